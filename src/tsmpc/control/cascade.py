"""The guidance system as one runtime object: outer MPC + MHE-UIO + TS-LQR (paper Fig. 1).

A vehicle stack calls :meth:`Cascade.step` every T_d with the latest sensor sample and applies the
returned :class:`Command` until the next call. Inside, the outer kinematic MPC (TS-MPC or NL-MPC)
runs every T_c/T_d calls on the measured pose, and the MHE-UIO and the TS-LQR run every call::

    cascade = Cascade(cfg, Method.REF, reference)
    while driving:
        cmd = cascade.step(t, Measurement(pose=(X, Y, θ), v=v, omega=ω))
        vehicle.apply(cmd.F_xR, cmd.delta)

``step`` never raises: a NaN or stale sample is rejected (the pose holds its last good value, the
MHE predicts), MPC and MHE failures fall back inside the blocks; an exception escaping a block
falls back at this level (MPC: the shifted previous plan; MHE: the last estimate, status FAILED),
and anything else holds the previous command. Every such event is counted in
:attr:`Cascade.events` (``step_errors`` for exceptions, :attr:`Cascade.last_error` says which).

Garbage that is finite is rejected too (issue 24), each kind under its own counter:

* ``time_rejected``: a call time that is not finite, goes backwards or repeats, or jumps ahead by
  more than ``max_time_jump_s``; the cascade's own clock (previous time + T_d) is used instead;
* ``stamp_rejected``: a sample stamped in the future (beyond the call time + T_d) or with a
  non-finite stamp (stale samples: ``stale_rejected``);
* ``speed_rejected``: a speed or yaw rate no vehicle this config drives can have (negative beyond
  the noise, far above every speed bound of the config);
* ``pose_jump_rejected``: a pose further from the dead-reckoned pose than the car can have
  drifted since the last accepted one (1 m + 2 m per second without a pose), or a heading off by
  more than 0.3 rad + 0.5 rad/s.

Between accepted poses the pose is dead-reckoned from the estimate (v̂, α̂, ω̂), so the MPC of a
call without a usable pose sees where the car most likely is, not where it was.

The cascade does no logging (blocks do not log): each :class:`Command` carries what a logger needs (the
estimate, the MPC result when the MPC ran at that call, the block timings).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc._records import quick_init
from tsmpc.config import Config, InnerLaw, Method, MHEForm
from tsmpc.control._back import (
    CM_ALPHA,
    CM_CALLS,
    CM_D,
    CM_F,
    CM_HASLAST,
    CM_LOW,
    CM_SAT,
    BackParams,
    BackState,
    back_start,
    cascade_back,
    cascade_command,
    command_state,
)
from tsmpc.control._clock import (
    CC_BLIND,
    CC_RECOVER,
    CC_STALE,
    CC_STAMP,
    CC_TIME,
    CK_BLIND,
    CK_CATCHUP,
    CK_REANCHOR,
    CK_TLAST,
    ClockParams,
    cascade_clock,
    cascade_sample,
    clock_state,
    pack_clock,
)
from tsmpc.control._front import (
    FrontParams,
    FrontState,
    OuterParams,
    OuterState,
    cascade_front,
    cascade_outer,
)
from tsmpc.control._mid import AfterState, cascade_after_plan
from tsmpc.control.fusion_block import (
    FB_OFF,
    FB_SENT,
    FusionParams,
    fusion_state,
    speed_load,
)
from tsmpc.control.gates import (
    GC_JUMP,
    GC_NAN,
    GC_REINIT,
    GC_REPEATED,
    GC_SPEED,
    PO_T,
    GateBlockParams,
    GateParams,
    blind_stop,
    gate_state,
)
from tsmpc.control.governor import GovernorParams, GripParams, governed_window
from tsmpc.control.inner_block import (
    EST_FAILED,
    EST_OK,
    EST_REJECTED,
    EST_WARMUP,
    IC_FAILED,
    IC_FSTEPS,
    IC_REJECTED,
    IC_SATURATED,
    InnerBlockParams,
    block_delta_mass,
    compensated_force,
    count_step,
    start_state,
)
from tsmpc.control.mhe_block import N_EO, mhe_inputs
from tsmpc.control.offset_free import OffsetParams
from tsmpc.control.outer_block import (
    MPC_FALLBACK,
    MPC_OPTIMAL,
    MPC_SOFT,
    OB_RATE,
    OB_TOFF,
    OC_CLIPPED,
    OC_FALLBACK,
    OC_GACT,
    OC_GSTEPS,
    OC_POSE_REJ,
    OC_SOFT,
    GovernBlockParams,
    OuterBlockParams,
    RefArrays,
    governed_sample,
    outer_state,
    pack_govern,
    pack_outer,
    scratch_size,
)
from tsmpc.control.slip_aware import BASELINE
from tsmpc.control.stiffness_block import MP_B, N_SA, PRM_B, SA_A, SA_B, SA_CF, SA_CR, SA_HAS, SA_I
from tsmpc.control.ts_lqr import LQR_NUMPY, TSLQR, InnerParams
from tsmpc.control.ts_mpc import MPCResult, MPCStatus, shifted_plan
from tsmpc.estimation.friction_step import FrictionStep, FrictionStepParams
from tsmpc.estimation.fusion import MassParams, speed_offset
from tsmpc.estimation.mhe_uio import Estimate, EstimatorStatus
from tsmpc.planning.reference import Reference

if TYPE_CHECKING:
    from tsmpc.control.paper_as_run import AsRunLQR
    from tsmpc.estimation.mhe_uio import MHEUIO

__all__ = ["EVENT_NAMES", "Cascade", "Command", "Measurement", "Method", "build_outer_controller"]

#: Counters of :attr:`Cascade.events` (also the ``events`` of a run's metrics).
EVENT_NAMES: tuple[str, ...] = (
    "mpc_soft",  # the MPC solved the softened problem
    "mpc_fallback",  # the MPC returned its shifted previous plan
    "mpc_scheduling_clipped",  # scheduling values clipped into the kinematic box (summed)
    "mhe_rejected",  # MHE samples rejected (NaN or stale speed/yaw rate)
    "mhe_failed",  # MHE solver failures (model prediction used)
    "inner_saturated",  # TS-LQR steps with an active saturation
    "pose_rejected",  # MPC steps that used the last good pose (NaN or stale pose)
    "time_rejected",  # calls whose time went backwards, repeated, jumped or was not finite
    "stamp_rejected",  # samples stamped in the future or with a non-finite stamp
    "speed_rejected",  # samples with an impossible speed or yaw rate (negative, absurd)
    "pose_jump_rejected",  # poses further than the car can have moved since the last good one
    "pose_nan",  # calls whose (fresh) pose was not finite
    "pose_reinit",  # poses taken after a run of consistent jump rejections (recovery)
    "blind_steps",  # calls in the blind stop (no speed / yaw-rate sample for recovery.blind_after_s)
    "recoveries",  # returns from the blind stop (the reference re-anchored at the car)
)


@dataclass(frozen=True)
class Measurement:
    """One sensor sample delivered to :meth:`Cascade.step`.

    Attributes:
        pose: (X [m], Y [m], θ [rad]) global pose of the CoG.
        v: speed of the CoG [m/s].
        omega: yaw rate [rad/s].
        steering: front steering actually applied over the last T_d [rad], if the platform
            measures it (an actuator with lag); the MHE then uses it instead of the command.
        force: rear drive force actually applied over the last T_d [N], if measured.
        stamp: time the sample was taken [s] (same clock as ``t`` of ``step``); a sample older
            than the cascade's ``max_age_s`` is rejected as stale. None = fresh.
        state: ground-truth [v, α, ω] (simulation only: the *oracle* ablation). When given, the
            TS-LQR uses it instead of the MHE's estimate and gets no friction compensation —
            or, with ``lqr.true_state_feedback`` (the published run's quirk), the compensation
            as configured.
    """

    pose: tuple[float, float, float]
    v: float
    omega: float
    steering: float | None = None
    force: float | None = None
    stamp: float | None = None
    state: NDArray[np.float64] | None = None

    @classmethod
    def from_array(cls, y: ArrayLike, **kwargs: Any) -> Measurement:
        """From ``[X, Y, θ, v, ω]`` (the simulator's sensor vector)."""
        a = np.asarray(y, dtype=float).reshape(5)
        return cls((float(a[0]), float(a[1]), float(a[2])), float(a[3]), float(a[4]), **kwargs)


@quick_init
@dataclass(frozen=True)
class Command:
    """The plant input for the next T_d and what produced it.

    Attributes:
        F_xR: rear drive force [N] (after feed-forward, friction compensation, saturation).
        delta: front steering sent to the servo [rad]: the inner loop's, less the estimated
            steering offset in force (``fusion.steering_offset``), within the steering limits.
        saturated: an inner-loop saturation was active.
        v_ref: the outer loop's speed reference in force [m/s].
        omega_ref: the outer loop's yaw-rate reference in force [rad/s].
        estimate: the MHE-UIO's estimate at this call.
        plan: the MPC result when the MPC ran at this call, else None.
        errors_measured: the errors [e_x, e_y, e_θ] the MPC saw (None when it did not run).
        mpc_time_s: wall time of the MPC at this call (0 when it did not run) [s].
        mhe_time_s: wall time of the MHE-UIO at this call [s].
        lqr_time_s: wall time of the TS-LQR at this call [s].
        held: True when an unexpected error made the cascade hold its previous command.
    """

    F_xR: float
    delta: float
    saturated: bool
    v_ref: float
    omega_ref: float
    estimate: Estimate
    plan: MPCResult | None = None
    errors_measured: NDArray[np.float64] | None = None
    mpc_time_s: float = 0.0
    mhe_time_s: float = 0.0
    lqr_time_s: float = 0.0
    held: bool = False

    @property
    def u(self) -> NDArray[np.float64]:
        """[F_xR, δ] as an array (the plant input)."""
        return np.array([self.F_xR, self.delta])


def build_outer_controller(
    cfg: Config, method: Method, P: np.ndarray, S: np.ndarray, K: np.ndarray | None = None
) -> Any:
    """The outer MPC of ``method`` with the terminal ingredients (P, S) of the kinematic design;
    a baseline (pure pursuit, Stanley, LQR, LTV: :mod:`tsmpc.control.baselines`) for the others
    (``K``: the design's vertex gains, needed by the kinematic LQR)."""
    from tsmpc.models.kinematic import KinematicTS

    if not method.is_ts_mpc and method != Method.NL:
        from tsmpc.control.baselines import build_baseline

        return build_baseline(cfg, method, P, S, K)
    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    if method == Method.NL:
        from tsmpc.control.nl_mpc import NLMPC

        return NLMPC(cfg.mpc, model, P, S)
    from tsmpc.control.ts_mpc import TSMPC

    return TSMPC(cfg.mpc, model, P, S, mode=method)


class Cascade:
    """Outer MPC (every T_c) + MHE-UIO and TS-LQR (every T_d), called every T_d.

    Args:
        cfg: configuration (rates, vehicle, MPC, MHE, LQR settings).
        method: outer-loop method (FZN, REF, ITER: TS-MPC scheduling; NL: NL-MPC; PURE_PURSUIT,
            STANLEY, LQR, LTV: the baselines of :mod:`tsmpc.control.baselines`).
        reference: the reference to track; resampled to T_c if needed. Call ``step`` with
            ``t`` = time since the reference's first sample: the MPC tracks sample ``t / T_c``.
        kinematic_design: kinematic LMI design; loaded from the design cache if None.
        dynamic_design: dynamic LMI design; loaded from the design cache if None.
        x0: initial state [X, Y, θ, v, α, ω] (MHE start, first MPC input, pose fallback);
            None = taken from the first measurement (α = 0).
        max_age_s: a measurement whose ``stamp`` is older than this is rejected [s]
            (default: T_c).
        max_time_jump_s: a call time more than this after the previous one is rejected (the
            cascade's own clock is used) [s] (default: T_c).
    """

    lqr: TSLQR | AsRunLQR  #: the inner loop (cfg.lqr.law)
    mhe: MHEUIO  #: the estimator (MHEUIO or its paper form PaperUIOMHE, cfg.mhe.form)
    _mhe_arrays: tuple[Any, ...]  #: the MHE block's leading arguments (the estimator's arrays)

    def __init__(
        self, cfg: Config, method: Method | str, reference: Reference, *,
        kinematic_design: Any = None, dynamic_design: Any = None,
        x0: ArrayLike | None = None, max_age_s: float | None = None,
        max_time_jump_s: float | None = None,
    ) -> None:
        from tsmpc.control.ts_lqr import TSLQR
        from tsmpc.estimation.mhe_uio import MHEUIO
        from tsmpc.models.dynamic import DynamicTS
        from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

        self.cfg = cfg
        self.method = Method.parse(method) if isinstance(method, str) else method
        rates = cfg.rates
        self.Tc, self.Td = rates.Tc, rates.Td
        self.n_inner = rates.inner_per_outer
        ref = reference if abs(reference.dt - self.Tc) <= 1e-9 else reference.resample(self.Tc)
        self.reference = ref
        # the path's tangent at each sample, from the geometry (any sample period; slip_aware.py)
        self._theta_tangent = ref.tangent_heading()
        # the reference's v_d, ω_d (the course fusion's lateral acceleration v_d ω_d, every call)
        self._ref_v: list[float] = ref.v.tolist()
        self._ref_w: list[float] = ref.omega.tolist()
        # what the MPC's steps see: the planner's samples (paper) or each T_c step's averages
        self._mpc_reference = ref.step_averages() if cfg.mpc.step_average_reference else ref
        kd = kinematic_design or load_or_design_kinematic(cfg)
        dd = dynamic_design or load_or_design_dynamic(cfg)
        self.mpc = build_outer_controller(cfg, self.method, kd.P, kd.S, K=kd.K)
        dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, self.Td)
        if cfg.lqr.law == InnerLaw.AS_RUN:  # the published run's law: a quirk
            from tsmpc.control.paper_as_run import AsRunLQR

            self.lqr = AsRunLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, self.Td,
                                bandwidth=cfg.dynamic_lmi.filter_bandwidth)
        else:
            self.lqr = TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, self.Td,
                             bandwidth=cfg.dynamic_lmi.filter_bandwidth)
        if cfg.mhe.form == MHEForm.UIO:  # the paper's UIO form (numpy path)
            from tsmpc.estimation.mhe_paper_uio import PaperUIOMHE

            self.mhe = PaperUIOMHE(cfg.mhe, dyn, cfg.vehicle, self.Td)
        else:
            self.mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, self.Td)
        self.max_age_s = self.Tc if max_age_s is None else float(max_age_s)
        self.max_time_jump_s = self.Tc if max_time_jump_s is None else float(max_time_jump_s)
        self._slip_sigma = float(cfg.noise.position * cfg.noise.scale)  # the slip gate's (slip_aware.py)
        # Plausible measurements (issue 24): beyond every speed / yaw-rate bound of the config,
        # with room for the sensor noise.
        nz = cfg.noise
        v_bound = max(cfg.mpc.u_max[0], cfg.dynamic_box.v[1], cfg.kinematic_box.v_d[1])
        w_bound = max(abs(cfg.mpc.u_min[1]), cfg.mpc.u_max[1], *map(abs, cfg.kinematic_box.omega))
        self._v_range = (-max(1.0, 5.0 * nz.v * nz.scale), 2.0 * v_bound + 5.0 + 5.0 * nz.v * nz.scale)
        self._w_limit = max(4.0, 2.0 * w_bound) + 5.0 * nz.omega * nz.scale
        self._pose_noise = 5.0 * nz.position * nz.scale
        self._heading_noise = 5.0 * nz.theta * nz.scale
        self._gates = GateParams(self._v_range[0], self._v_range[1], self._w_limit, self._pose_noise,
                                 self._heading_noise, self.Td)
        # beyond the paper: blind stop and recovery (gates.py)
        self._recovery = cfg.recovery if cfg.recovery.enabled else None
        self._force_limits = cfg.lqr.force_limits(cfg.vehicle)
        # the gate block (gates.py): the bounds, the jump-run re-initialisation, the repeat guard
        rp = cfg.recovery.pose_reinit_s
        self._gate_p = GateBlockParams(self._gates, self._recovery is not None, float(rp),
                                       bool(cfg.fusion.reject_repeated_samples))
        # recovery.yaw_rate_bound: the kinematic bicycle's tightest path curvature tan(δ_max)/L [1/m]
        rc = cfg.recovery
        self._curvature_max = (math.tan(cfg.lqr.delta_max) / cfg.vehicle.wheelbase
                               if rc.enabled and rc.yaw_rate_bound else None)
        # the cascade's time (_clock.py): the clock, the stamp's age, the blind clock, the time base
        self._clock_p = ClockParams(
            float(self.Td), float(self.Tc), float(self.max_time_jump_s), float(self.max_age_s),
            self._recovery is not None, float(rc.blind_after_s), int(self.n_inner),
            cfg.rates.inner_steps_per_outer is not None, self._curvature_max is not None,
            0.0 if self._curvature_max is None else float(self._curvature_max))
        from tsmpc.estimation.fusion import Fusion

        self._fusion = Fusion(cfg)  # beyond the paper: cfg.fusion's switches (issue 21)
        # the fusion block's record (fusion_block.py): the parts the config selects (the step has
        # no feature switch), the steering limits of the servo
        self._fb_p = FusionParams(bool(cfg.fusion.gyro_bias), self._fusion.any_course,
                                  bool(cfg.fusion.steering_offset), bool(cfg.fusion.course_slip),
                                  -cfg.lqr.delta_max, cfg.lqr.delta_max,
                                  self._fusion.gyro.params, self._fusion.course.params)
        self._build_inner_block(cfg)
        self._build_mhe_block()
        #: the speed governor's block record (issue 36; None: off)
        self.governor: GovernBlockParams | None = _build_governor(cfg) if cfg.governor.enabled else None
        self._build_outer_block(cfg)
        self._build_back(cfg)
        self.road_mu = math.nan  # governor.grip_source = "oracle": the true μ(road), set by the simulator
        self.reset(x0)

    # -------------------------------------------------------------------------- state
    @property
    def dt(self) -> float:
        """Call period T_d [s] (the runtime protocol's name)."""
        return self.Td

    def reset(self, x0: ArrayLike | None = None) -> None:
        """Start over (blocks cleared, counters zeroed) from state ``x0`` (6,) or, if None, from
        the first measurement."""
        self._x0 = None if x0 is None else np.asarray(x0, dtype=float).reshape(6).copy()
        self.mhe.reset(None if self._x0 is None else self._x0[3:6].copy())
        self.lqr.reset()
        self._gate_poses = np.zeros((BASELINE + 1, 3))  # the slip gate's MPC poses (slip_aware.py)
        fu = self._fusion
        fu.reset(None if self._x0 is None else self._x0[:3])
        # the fusion block's state (fusion_block.py: its vector, the course fusion's ring and open
        # interval), the stiffnesses given (stiffness_block.SA_*), the command record (_back.CM_*)
        self._fb, self._ivs, self._cur = fusion_state(fu.gyro.state, fu.steer, 0.0, 0.0, fu.course.state,
                                                      fu.course.cur)
        self._cmd = command_state()
        self._ib_state, self._ib_ring, self._ib_count = start_state(self.cfg.mhe.N)
        sa: NDArray[np.float64] | None = getattr(self, "_sa", None)
        if sa is not None and sa[SA_HAS]:  # back to the config's lateral model
            veh = self.cfg.vehicle
            for b in (self.mhe, self.lqr):
                setter = getattr(b, "set_cornering_stiffness", None)
                if setter is not None:
                    setter(veh.C_f, veh.C_r, veh.inertia, veh.a, veh.b)
        self._sa = np.zeros(N_SA)  # the stiffness block's record of those given (stiffness_block.py)
        self.mpc.reset()
        # the gate block's pose record (gates.PO_*): the accepted or dead-reckoned pose, the time of
        # the last accepted pose
        self._pose = None if self._x0 is None else np.array([*self._x0[:3].tolist(), 0.0])
        # the outer block's state (held pose, slip gate count, offset estimate, reference time
        # offset, governor) and its counters (outer_block.py)
        self._ob, self._oc = outer_state(None if self._x0 is None else self._x0[:3])
        self._pose_fresh = False
        # the MPC's previous input [v, ω] (the TS-LQR's references until the next MPC step; set by
        # the first call's start without x0)
        self._up = np.zeros(2) if self._x0 is None else np.array([self._x0[3], self._x0[5]])
        # the cascade's time (_clock.py: the last call's time, the recovery's blind clock, the
        # blind stop, the re-anchoring due and the catch-up after it) and its counters
        self._ck, self._cc = clock_state()
        self._gs, self._gate_count = gate_state()  # the gate block's state and counters
        # the phases' states (_front.FrontState, _back.BackState: the blocks' vectors above; None
        # until the pose record exists)
        self._front_s = None if self._pose is None else FrontState(
            self._gs, self._gate_count, self._pose, self._fb, self._ivs, self._cur, self._cmd, self._ck,
            self._cc)
        self._outer_s = None if self._pose is None else OuterState(
            self._fb, self._ivs, self._sa, self._stiff_mp, self._stiff_prm, self._ob, self._oc,
            self._gate_poses, self._pose, self._cmd, self._ck, self._up)
        self._back_s = None if self._pose is None else BackState(
            self._pose, self._fb, self._cur, self._sa, self._cmd, getattr(self.lqr, "_s", self._cmd[:0]),
            self._ib_state, self._ib_ring, self._ib_count)
        self._last: Command | None = None
        self._plan: MPCResult | None = None
        self._events = dict.fromkeys(EVENT_NAMES, 0)
        self._events["stale_rejected"] = 0
        self._events["step_errors"] = 0
        self._events["repeated_rejected"] = 0  # fusion.reject_repeated_samples (issue 21)
        self._events["friction_steps"] = 0  # lqr.friction_step: steps of the friction detected
        # (mhe_rejected, mhe_failed, inner_saturated and friction_steps: the inner block's counters)
        if self.governor is not None:  # the speed governor (governor.py): its actions
            self._events["governor_actions"] = self._events["governor_steps"] = 0
        self.last_error: str | None = None

    @property
    def events(self) -> dict[str, int]:
        """Event counters since the last reset (see :data:`EVENT_NAMES`; plus ``stale_rejected``,
        samples rejected for their age, ``step_errors``, unexpected errors caught,
        ``repeated_rejected``, stalled samples, and ``friction_steps``, steps of the friction force
        declared by ``lqr.friction_step``)."""
        ev, c, g = dict(self._events), self._ib_count.tolist(), self._gate_count.tolist()
        k = self._cc.tolist()  # the cascade's time's (_clock.py)
        ev["time_rejected"], ev["stamp_rejected"], ev["stale_rejected"] = k[CC_TIME], k[CC_STAMP], k[CC_STALE]
        ev["blind_steps"], ev["recoveries"] = k[CC_BLIND], k[CC_RECOVER]
        ev["speed_rejected"], ev["repeated_rejected"], ev["pose_nan"] = g[GC_SPEED], g[GC_REPEATED], g[GC_NAN]
        ev["pose_reinit"], ev["pose_jump_rejected"] = g[GC_REINIT], g[GC_JUMP]
        ev["mhe_rejected"], ev["mhe_failed"] = c[IC_REJECTED], c[IC_FAILED]
        ev["inner_saturated"], ev["friction_steps"] = c[IC_SATURATED], c[IC_FSTEPS]
        o = self._oc.tolist()  # the outer block's
        ev["pose_rejected"], ev["mpc_soft"], ev["mpc_fallback"] = o[OC_POSE_REJ], o[OC_SOFT], o[OC_FALLBACK]
        ev["mpc_scheduling_clipped"] = o[OC_CLIPPED]
        if self.governor is not None:
            ev["governor_actions"], ev["governor_steps"] = o[OC_GACT], o[OC_GSTEPS]
        return ev

    @property
    def _blind_since(self) -> float | None:
        """recovery: when the blind stop began (None: not blind; the clock's state, _clock.CK_BLIND)."""
        b = float(self._ck[CK_BLIND])
        return None if math.isnan(b) else b

    @property
    def _blind(self) -> bool:
        """In the blind stop (recovery)."""
        return not math.isnan(self._ck[CK_BLIND])

    @property
    def _reanchor(self) -> bool:
        """recovery: the reference is re-anchored at the car at the next MPC step with a pose."""
        return bool(self._ck[CK_REANCHOR] != 0.0)

    @property
    def _catch_up(self) -> bool:
        """recovery: after a re-anchoring, the reference time advances at the car's speed."""
        return bool(self._ck[CK_CATCHUP] != 0.0)

    @property
    def _calls(self) -> int:
        """Calls made since the reset (the command record's)."""
        return int(self._cmd[CM_CALLS])

    @property
    def _u_applied(self) -> tuple[float, float]:
        """[F_xR, δ] the plant got over the last T_d (δ: the wheels' intended angle, sent + the
        steering offset: what the MHE's model sees)."""
        c = self._cmd
        return float(c[CM_F]), float(c[CM_D])

    @property
    def _low_applied(self) -> float:
        """lqr.low_speed_resistance's part of the applied force."""
        return float(self._cmd[CM_LOW])

    @property
    def _steer_offset(self) -> float:
        """fusion.steering_offset: the offset estimate the last command took off."""
        return float(self._fb[FB_OFF])

    @property
    def _steer_sent(self) -> float:
        """The angle last sent to the servo."""
        return float(self._fb[FB_SENT])

    @property
    def last_plan(self) -> MPCResult | None:
        """The last MPC result (predicted errors, planned inputs), None before the first."""
        return self._plan

    @property
    def last_estimate(self) -> Estimate | None:
        """The last MHE-UIO estimate, None before the first call."""
        return None if self._last is None else self._last.estimate

    @property
    def last_command(self) -> Command | None:
        """The last command returned."""
        return self._last

    # --------------------------------------------------------------------------- step
    def step(self, t: float, measurement: Measurement) -> Command:
        """One call every T_d: the command to apply until the next call. Never raises."""
        calls = self._calls
        try:
            cmd = self._step(self._clock(t), measurement)  # (its last phase keeps the command record)
        except Exception as err:  # the contract: a guidance step never raises
            self._caught(err)
            cmd = self._hold()
            c = self._cmd  # the held command in the command record
            c[CM_CALLS], c[CM_HASLAST] = calls + 1, 1.0
            c[CM_ALPHA], c[CM_SAT] = float(cmd.estimate.x[1]), 1.0 if cmd.saturated else 0.0
        self._last = cmd
        return cmd

    def _caught(self, err: Exception) -> None:
        self._events["step_errors"] += 1
        self.last_error = f"{type(err).__name__}: {err}"

    def _hold(self) -> Command:
        """The previous command again (a zero command before the first)."""
        last = self._last
        if last is None:
            est = Estimate(np.zeros(3), 0.0, 0.0, EstimatorStatus.FAILED, 0.0)
            return Command(0.0, 0.0, False, 0.0, 0.0, est, held=True)
        return Command(last.F_xR, last.delta, last.saturated, last.v_ref, last.omega_ref,
                       last.estimate, held=True)

    def _clock(self, t: Any) -> float:
        """The call's time (_clock.cascade_clock, one compiled call; as Python with TSMPC_NO_JIT):
        ``t`` when it follows the previous call (later by at most ``max_time_jump_s``), else the
        cascade's own clock, previous + T_d (``time_rejected``)."""
        try:
            tt = float(t)
        except (TypeError, ValueError):
            tt = math.nan
        call = self._clock_call
        if call is not None:
            return float(call[0](call[1], self._ck, self._cc, tt))
        return float(cascade_clock(self._clock_p, self._ck, self._cc, tt))

    def _stiffness_given(self) -> None:
        """fusion.stiffness_estimate: the stiffness block (stiffness_block.py, in the outer phase:
        _front.cascade_outer) gave the fitted lateral model (C_f, C_r, I_z, a, b: any moved by over
        1 %; the slip fit's gain κ restarted when it replaced a given one) to the MHE's and the
        TS-LQR's parameter arrays: the Python models around those arrays and the steering-offset
        fit's balance follow."""
        model = [float(self._sa[i]) for i in (SA_CF, SA_CR, SA_I, SA_A, SA_B)]
        for b in (self.mhe, self.lqr):
            follow = getattr(b, "model_stiffness", None) or getattr(b, "set_cornering_stiffness", None)
            if follow is not None:
                follow(*model)
        self._fusion.set_stiffness(*model)  # the steering-offset fit's balance too

    def _step(self, t: float, m: Measurement) -> Command:
        """One call: the block diagram of paper Fig. 1 (gates → outer MPC every T_c/T_d calls →
        MHE-UIO → friction compensation → TS-LQR), each block a method below; the fusion's blocks
        (gyro bias, course fusion, steering offset) around them."""
        pX, pY, pth = m.pose
        X, Y, th = float(pX), float(pY), float(pth)
        v, om = float(m.v), float(m.omega)
        if self._x0 is None:
            self._start_from(t, X, Y, th, v, om)
        # the gates, the MPC's turn, the fusion block before the MPC: ω less its bias from here on
        fresh, speeds_ok, pose_ok, mpc_step, om = self._front(t, m, X, Y, th, v, om)
        ok = fresh and speeds_ok
        plan, e_meas, t_mpc = (self._outer(t, X, Y, v, om, ok, pose_ok) if mpc_step
                               else (None, None, 0.0))
        up = self._up  # the MPC's previous input: the TS-LQR's references
        v_ref, w_ref = float(up[0]), float(up[1])
        t1 = time.perf_counter()
        est, u_model = self._estimate(m, v, om, ok, t1)
        t2 = time.perf_counter()
        F, delta, sat = self._back(m, est, u_model, ok, pose_ok, th, v, v_ref, w_ref)
        t3 = time.perf_counter()
        return Command(F, delta, sat, v_ref, w_ref, est, plan, e_meas, t_mpc, t2 - t1, t3 - t2)

    def _back(self, m: Measurement, est: Estimate, u_model: tuple[float, float], ok: bool, pose_ok: bool,
              th: float, v: float, v_ref: float, w_ref: float) -> tuple[float, float, bool]:
        """The phase after the MHE (_back.cascade_back: one compiled call on the default path): the
        dead reckoning, the fusion block after the MHE, the inner block (friction step, mass terms,
        TS-LQR, events), the servo and the command record — (F_xR, the angle sent, saturated). The
        numpy law (no compiled law, or N̄ singular), the oracle, the published run's law, the blind
        stop and a replaced ``lqr.step`` decide the inner loop in Python between the phase's parts."""
        v_hat, a_hat, w_hat = est.x.tolist()
        lqr, code = self._ib_lqr, STATUS_CODE[est.status]
        d_m, F_m = float(u_model[1]), float(u_model[0])
        if (m.state is not None or self._blind or lqr is None or "step" in lqr.__dict__
                or type(lqr).step is not _TSLQR_STEP):  # (a replaced step: the Python path calls it)
            self._back_start(ok, pose_ok, th, v, v_hat, a_hat, w_hat, code, d_m, F_m)
            F, d, sat, low = self._inner_other(m, est, v_hat, v_ref, w_ref, code)
            return F, self._command(F, d, sat, low, a_hat), sat
        args = (ok, pose_ok, th, v, v_hat, a_hat, w_hat, float(est.F_fr), float(est.F_fr_raw), code, d_m, F_m,
                v_ref, w_ref)
        call = self._back_call
        if call is not None:
            F, d, sat, st, comp, low = call[0](*call[1:], *self._back_s, *args)  # type: ignore[misc]
        else:  # TSMPC_NO_JIT, or a TS-LQR without its compiled law: the phase as Python
            law = lqr._law if lqr._kern is not None else None
            F, d, sat, st, comp, low = cascade_back(self._back_p, law, self._back_s, *args)  # type: ignore[arg-type]
        if st != LQR_NUMPY:
            return F, d, bool(sat)
        c = lqr._numpy_step(v_hat, a_hat, w_hat, v_ref, w_ref, comp, low)  # the numpy law decides
        count_step(self._ib_count, code, bool(c.saturated))
        sat = bool(c.saturated)
        return c.F_xR, self._command(c.F_xR, c.delta, sat, c.F_low_speed, a_hat), sat

    def _back_start(self, ok: bool, pose_ok: bool, th: float, v: float, v_hat: float, a_hat: float,
                    w_hat: float, code: int, d_m: float, F_m: float) -> None:
        """The phase's part before the inner block (_back.back_start): dead reckoning, fusion."""
        blind = self._blind
        call = self._start_call
        if call is not None:
            call[0](call[1], self._pose, self._fb, self._cur, self._sa, self._cmd, ok, pose_ok, th, v, v_hat,
                    a_hat, w_hat, code, d_m, F_m, blind)
        else:
            back_start(self._back_p, self._back_s, ok, pose_ok, th, v, v_hat, a_hat, w_hat, code, d_m, F_m,  # type: ignore[arg-type]
                       blind)

    def _command(self, F: float, delta: float, sat: bool, low: float, alpha: float) -> float:
        """The phase's part after the inner loop (_back.cascade_command): the angle sent (the
        wheels' angle less the steering offset in force, within the steering limits), the
        command record."""
        call = self._command_call
        if call is not None:
            return float(call[0](call[1], self._fb, self._sa, self._cmd, F, delta, sat, low, alpha))
        return cascade_command(self._back_p, self._back_s, F, delta, sat, low, alpha)  # type: ignore[arg-type]

    def _start_from(self, t: float, X: float, Y: float, th: float, v: float, om: float) -> None:
        """Start from the first measurement (its garbage made harmless)."""
        x0 = np.nan_to_num(np.array([X, Y, th, v, 0.0, om]), posinf=0.0, neginf=0.0)
        x0[3] = min(max(x0[3], 0.0), self._v_range[1])
        x0[5] = min(max(x0[5], -self._w_limit), self._w_limit)
        t_last = self._ck[CK_TLAST]  # (the clock's: this call's time)
        self.reset(x0)
        self._ck[CK_TLAST] = t_last
        self._pose[PO_T] = t  # type: ignore[index]

    def _front(self, t: float, m: Measurement, X: float, Y: float, th: float, v: float,
               om: float) -> tuple[bool, bool, bool, bool, float]:
        """The phase before the outer loop (_front.cascade_front: one compiled call on the default
        path; as Python with TSMPC_NO_JIT): the sample's stamp and the recovery's watch, the sample
        gates, the MPC's turn and the fusion block before the MPC and the MHE — (fresh, speeds
        plausible, pose accepted, the MPC runs, ω less the gyro's bias). The pose, every call:
        accepted when fresh, finite and where the car can be; else the dead-reckoned pose stands
        (advanced at the end of the call) for the plausibility gate. The yaw-rate bias fit takes
        the raw ω against the accepted pose's heading, the course fusion closes its interval at an
        accepted pose. A stamp that is no number is refused (``stamp_rejected``), then fails the
        call."""
        has_stamp, stamp = m.stamp is not None, -math.inf  # (a new stamp is a new sample)
        if has_stamp:
            try:
                stamp = float(m.stamp)  # type: ignore[arg-type]
            except (TypeError, ValueError):  # refused (and watched), then the call's error
                if cascade_sample(self._clock_p, self._gates, self._ck, self._cc, self._gs, t, True, math.nan,
                                  v, om)[1]:
                    self.lqr.reset()
                raise
        call, s = self._front_call, self._front_s
        if call is not None:
            out = call[0](call[1], call[2], call[3], call[4], *s, t, has_stamp, X, Y, th, v, om,  # type: ignore[misc]
                          stamp, self._t_offset, call[5], call[6])
        else:
            out = cascade_front(self._front_p, s, t, has_stamp, X, Y, th, v, om, stamp,  # type: ignore[arg-type]
                                self._t_offset, self._ref_v, self._ref_w)
        if out[5]:  # the blind stop ended: the TS-LQR's filter did not run while blind
            self.lqr.reset()
        return out[0], out[1], out[2], out[3], out[4]

    def _outer(self, t: float, X: float, Y: float, v: float, om: float, ok: bool,
               pose_ok: bool) -> tuple[MPCResult, NDArray[np.float64], float]:
        """An MPC step: (the plan, the errors it saw, its wall time). The phase before the solve
        (_front.cascade_outer: the recovery's restart, the reference sample, the errors and the
        window) and the one after it (_mid.cascade_after_plan: the plan's input kept, the plan's
        events, the governor)."""
        e_meas, window = self._outer_block(t, X, Y, v, om, pose_ok)
        u_prev = self._up.copy()  # (the plan may keep what it is given)
        t0 = time.perf_counter()
        try:
            plan = self.mpc.step(e_meas, u_prev, window)
        except Exception as err:  # a solver bug must not stop the car: shifted plan
            self._caught(err)
            plan = shifted_plan(self._plan, e_meas, u_prev, self.cfg.mpc.N, t0, 0, 0, 0)
        t_mpc = time.perf_counter() - t0
        self._plan = plan
        self._after_plan(t, plan, ok, v)
        return plan, e_meas, t_mpc

    def _outer_block(self, t: float, X: float, Y: float, v: float, om: float,
                     pose_ok: bool) -> tuple[NDArray[np.float64], Any]:
        """The MPC step before the solve (_front.cascade_outer, one compiled call; as Python with
        TSMPC_NO_JIT): the recovery's restart (re-anchored at the sample's pose: the MPC and the
        last plan forgotten) and the reference sample k, the stiffness block
        (fusion.stiffness_estimate; the Python models follow when it gave), the errors the MPC sees
        of the pose against reference sample ``k`` (or the governed time's) and its window (v_d,
        ω_d; a baseline's: the reference's window)."""
        xp = None if self._plan is None else self._plan.x_pred
        has_pred = xp is not None and len(xp) >= 2
        last = self._last
        n = self.cfg.mpc.N + 1
        e, wv, ww = np.empty(3), np.empty(n), np.empty(n)
        v_hat = float(last.estimate.x[0]) if last is not None else math.nan
        args = (t, pose_ok, X, Y, v, om, v_hat, has_pred, float(xp[1][1]) if has_pred else 0.0,  # type: ignore[index]
                e, wv, ww, self._ob_buf)
        call, s = self._outer_call, self._outer_s
        if call is not None:
            k, restarted, give, governed = call[0](call[1], call[2], call[3], call[4], self._refs, *s, *args)  # type: ignore[misc]
        else:  # TSMPC_NO_JIT: the phase as Python
            k, restarted, give, governed = cascade_outer(self._outer_p, self._ref_rec, s, *args)  # type: ignore[arg-type]
        if restarted:  # re-anchored: the MPC starts afresh
            self.mpc.reset()
            self._plan = None
        if give:
            self._stiffness_given()
        if not self._window_only:  # a baseline reads the whole reference window
            tau, rate = t - self._t_offset, float(self._ob[OB_RATE])
            return e, (governed_window(self._mpc_reference, tau, rate, n) if governed
                       else self._mpc_reference.window(int(k), n))
        return e, _Window(wv, ww)

    def _after_plan(self, t: float, plan: MPCResult, ok: bool, v: float) -> None:
        """The plan's bookkeeping (_mid.cascade_after_plan, one compiled call; as Python with
        TSMPC_NO_JIT): the plan's first input kept as the MPC's previous input (within what the car
        can turn at the measured speed ``v``, ``ok``: the gates took it, during a restart), the
        outer block after the solve (outer_block.outer_after: the plan's events and the governor's
        rate for the next step from the last estimate's grip) on the command record."""
        last, gov = self._last, self.governor
        est = last.estimate if last is not None else None
        dm = block_delta_mass(self._ib, self._ib_state) if gov is not None and gov.mass_estimate else 0.0
        code, v_hat, F_fr = ((STATUS_CODE[est.status], float(est.x[0]), float(est.F_fr)) if est is not None
                             else (0, math.nan, math.nan))
        u = plan.u
        args = (float(u[0]), float(u[1]), ok, v, _MPC_STATUS_CODE[plan.status], int(plan.n_clipped), t, code,
                v_hat, F_fr, self.road_mu, dm, self._ob_buf)
        call = self._after_call
        if call is not None:
            call[0](call[1], call[2], call[3], self._refs, self._ob, self._oc, self._cmd, self._ck, self._up,
                    *args)
        else:  # TSMPC_NO_JIT: the phase as Python
            state = AfterState(self._ob, self._oc, self._cmd, self._ck, self._up)
            cascade_after_plan(self._ob_p, self._gov_p, self._clock_p, self._ref_rec, state, *args)

    def _build_outer_block(self, cfg: Config) -> None:
        """The outer block's records (outer_block.py), the reference it reads, its scratch and its
        compiled calls (kernels/blocks.py)."""
        ref, mref, mc = self.reference, self._mpc_reference, cfg.mpc
        dt = ref.dt
        turn = ref.theta[-1] - ref.theta[0] + ref.omega[0] * dt  # a closed lap's (Reference.window)
        turn = 2 * np.pi * np.round(turn / (2 * np.pi))
        off = mc.offset_free_s > 0  # beyond the paper: the offset-free outer loop (offset_free.py)
        self._ob_p = OuterBlockParams(
            bool(mc.slip_aware), bool(mc.tangent_heading), bool(cfg.fusion.course_slip),
            bool(cfg.fusion.predict_pose), self._slip_sigma, off,
            OffsetParams(float(self.Tc) / float(mc.offset_free_s) if off else 0.0, float(self.Tc)),
            self.governor is not None, float(self.Tc), int(mc.N), float(dt), bool(ref.closed), float(turn),
            float(mref.dt), bool(mref.closed))
        self._gov_p = self.governor if self.governor is not None else _build_governor(cfg)
        if len(mref) != len(ref):  # (step averages keep the samples)
            raise ValueError("the MPC's reference must have the reference's samples")
        self._refs = np.ascontiguousarray(np.vstack([ref.x, ref.y, ref.theta, ref.v, ref.omega,
                                                     self._theta_tangent, mref.v, mref.omega]), dtype=float)
        self._ref_rec = RefArrays(*self._refs)
        self._ob_buf = np.zeros(scratch_size(int(mc.N), self._gov_p.preview))
        # the TS-MPC reads the window's v and ω only; a baseline the whole reference window
        self._window_only = self.method.is_ts_mpc
        from tsmpc import kernels

        kern = kernels.load("blocks")
        self._after_call: Any = None
        self._clock_call: Any = None
        if kern is not None:
            ckp = pack_clock(self._clock_p)
            self._after_call = (kern.after_plan_call, pack_outer(self._ob_p), pack_govern(self._gov_p), ckp)
            self._clock_call = (kern.clock_call, ckp)

    # ------------------------------------------------------------------ speed governor (issue 36)
    @property
    def governed(self) -> bool:
        """True once the speed governor has slowed the reference (its time τ is then fractional)."""
        return self.governor is not None and bool(self._oc[OC_GACT] > 0 or self._ob[OB_RATE] < 1.0)

    @property
    def plan_delay(self) -> float:
        """How far behind the plan's timing the reference is sampled [s]: t − τ, what the speed
        governor's slow-downs (and the recovery's re-anchoring) have added up to. The tracking
        errors are measured against the reference at τ, so this is the time a governed run lost,
        which its RMSEs do not show."""
        return float(self._t_offset)

    @property
    def _t_offset(self) -> float:
        """The reference time offset t − τ [s] (the outer block's slot: the governor and the
        recovery's re-anchoring move it)."""
        return float(self._ob[OB_TOFF])

    @_t_offset.setter
    def _t_offset(self, value: float) -> None:
        self._ob[OB_TOFF] = value

    def reference_row(self, t: float) -> NDArray[np.float64]:
        """[x_d, y_d, θ_d, v_d, ω_d] the cascade tracks at time ``t``: the reference at the governed
        time (interpolated; v_d and ω_d times the governed rate) — the plan's sample when ungoverned."""
        r = float(self._ob[OB_RATE]) if self.governor is not None else 1.0
        return np.array(governed_sample(self._ob_p, self._ref_rec, t - self._t_offset, r, self._ob_buf))

    def _estimate(self, m: Measurement, v: float, om: float, speeds_ok: bool,
                  t1: float) -> tuple[Estimate, tuple[float, float]]:
        """The MHE phase (_mid.cascade_estimate around mhe_block.py: one compiled call on the default
        path): the MHE-UIO's step on the measured speeds (NaN when the gates refused them) and the
        input the plant received — (the estimate, that input as the MHE's model sees it). Without
        the compiled kernel (or a replaced ``mhe.step``) the same inputs (_mhe_inputs) go to the
        estimator's own step."""
        f, s, mhe = m.force, m.steering, self.mhe
        hf, hs = f is not None, s is not None
        F, S = (0.0 if f is None else float(f)), (0.0 if s is None else float(s))
        try:
            call = self._mhe_call
            if call is not None and "step" not in mhe.__dict__:
                arrays = self._mhe_arrays
                if arrays[1] is not mhe._Y:  # (the estimator's reset makes a new window)
                    arrays = self._mhe_arrays = (mhe.vehicle.mass, mhe._Y, mhe._W, mhe._U, mhe._XS, mhe._Ab,
                                                 mhe._Bb, mhe._Xb, mhe._mp, mhe._ms, mhe._mi, mhe._uk,
                                                 self._est_buf)
                st, F_raw, n, ok, u0, u1 = call(*arrays, self._fb, self._cmd, self._course_speed, speeds_ok,
                                                v, hf, F, hs, S)
                return mhe.estimate(st, F_raw, n, ok, t1), (u0, u1)
            y0, y1, u0, u1 = self._mhe_inputs(speeds_ok, v, om, hf, F, hs, S)
            return mhe.step((y0, y1), (u0, u1)), (u0, u1)
        except Exception as err:  # e.g. a LinAlgError: keep the last estimate, flagged FAILED
            self._caught(err)
            last = self.last_estimate
            x_hat = last.x.copy() if last is not None else np.array([v, 0.0, om])
            est = Estimate(x_hat, last.F_fr if last is not None else 0.0, 0.0,
                           EstimatorStatus.FAILED, time.perf_counter() - t1)
            y0, y1, u0, u1 = self._mhe_inputs(speeds_ok, v, om, hf, F, hs, S)
            return est, (u0, u1)

    def _mhe_inputs(self, speeds_ok: bool, v: float, om: float, hf: bool, F: float, hs: bool,
                    S: float) -> tuple[float, float, float, float]:
        """The MHE block's inputs (mhe_block.mhe_inputs) in Python, as _mid.cascade_estimate gives
        them: the sample less the course fit's speed offset, the input applied or measured."""
        fb = self._fb
        off = speed_offset(speed_load(fb), v) if self._course_speed else 0.0
        Fa, da = self._u_applied
        return mhe_inputs(speeds_ok, v, om, off, Fa, da, hf, F, hs, S, self._steer_offset, self._low_applied)

    def _build_mhe_block(self) -> None:
        """The MHE phase's compiled call (kernels/blocks.py estimate_call: _mid.cascade_estimate) when
        the estimator runs the compiled window kernel with its model in it (Euler) and its step is
        MHEUIO's own."""
        from tsmpc import kernels
        from tsmpc.estimation.mhe_uio import MHEUIO

        mhe, kern = self.mhe, kernels.load("blocks")
        self._est_buf = np.zeros(N_EO)
        # the stiffness block's parameter arrays: the MHE's and the TS-LQR law's (scratch where a
        # block has none: its model_stiffness / set_cornering_stiffness holds its stiffnesses)
        mp, law = getattr(mhe, "_mp", None), getattr(self.lqr, "_law", None)
        self._stiff_mp = mp if isinstance(mp, np.ndarray) else np.zeros(MP_B + 1)
        self._stiff_prm = law.prm if law is not None else np.zeros(PRM_B + 1)
        self._mhe_arrays = (None, None)  # the call's leading arguments (made at the first)
        self._mhe_call: Any = None
        if (kern is not None and mhe._kern is not None and mhe._kargs[-1] and type(mhe).step is MHEUIO.step
                and type(mhe).step_values is MHEUIO.step_values):
            self._mhe_call = kern.estimate_call

    def _build_inner_block(self, cfg: Config) -> None:
        """The inner block's records (inner_block.py: lqr.friction_step's detector, beyond the paper;
        fusion.mass_estimate's inertia terms; the TS-LQR) and its compiled call when the TS-LQR has
        its compiled law; the gate block's compiled call (kernels/blocks.py)."""
        N, lq = cfg.mhe.N, cfg.lqr
        fs = (FrictionStep(N, lq.friction_step_threshold).params if lq.friction_step  # (validates)
              else FrictionStepParams(N, 1.0))
        inner = getattr(self.lqr, "_inner", None)  # the TS-LQR's (the as-run law has none)
        self._ib = InnerBlockParams(
            bool(lq.friction_step), fs, bool(cfg.fusion.mass_estimate),
            MassParams(float(cfg.vehicle.mass), self.Td, int(N), float(lq.speed_time_constant),
                       bool(lq.speed_feedback)),
            inner if isinstance(inner, InnerParams) else InnerParams(False, False, False, 1.0, 0.0))
        # the TS-LQR whose step is the block's (the as-run law's is its own)
        self._ib_lqr: TSLQR | None = self.lqr if isinstance(inner, InnerParams) else None  # type: ignore[assignment]

    def _build_back(self, cfg: Config) -> None:
        """The phase after the MHE's record (_back.BackParams) and the compiled calls of it, of its
        parts and of the fusion block before the MHE (kernels/blocks.py)."""
        from tsmpc import kernels

        self._back_p = BackParams(self._gates, self._fb_p, self._fusion.steer_p, self._ib)
        self._front_p = FrontParams(self._gate_p, self._fb_p, self.n_inner, self._clock_p)
        fu = self._fusion
        stiff = bool(fu.any_course and cfg.fusion.stiffness_estimate)  # (with the course fits only)
        self._outer_p = OuterParams(stiff, fu.course.params, self._ob_p, self._clock_p)
        self._course_speed = bool(cfg.fusion.course_speed)
        kern = kernels.load("blocks")
        self._back_call: Any = None
        self._start_call: Any = None
        self._command_call: Any = None
        self._front_call: Any = None
        self._outer_call: Any = None
        if kern is None:
            return
        lqr, law = self._ib_lqr, getattr(self.lqr, "_law", None)
        pk = kern.pack_back(self._back_p, law)
        self._start_call, self._command_call = (kern.start_call, pk), (kern.command_call, pk)
        ckp = pack_clock(self._clock_p)
        self._front_call = (kern.front_call, kern.pack_gates(self._gate_p), pk, ckp, self.n_inner,
                            self._refs[3], self._refs[4])  # (the reference's v_d, ω_d)
        self._outer_call = (kern.outer_phase_call, pk, pack_outer(self._ob_p), ckp, stiff)
        if lqr is not None and law is not None and lqr._kern is not None:
            self._back_call = (kern.back_call, pk, law.Kv, law.zlo, law.zhi, law.bits, law.prm)

    def _inner_other(self, m: Measurement, est: Estimate, v_hat: float, v_ref: float, w_ref: float,
                     code: int) -> tuple[float, float, bool, float]:
        """The configurations the compiled block does not express: the friction the block
        compensates (inner_block.compensated_force: the mass terms on the MHE's estimate only),
        then the law on the oracle's true state, the published run's law, or the blind stop."""
        F_c, F_r = compensated_force(self._ib, self._ib_state, self._ib_ring, self._ib_count, v_hat,
                                     float(est.F_fr), float(est.F_fr_raw), code == EST_OK, v_ref,
                                     m.state is None)
        if m.state is None:
            inner = est if (F_c == est.F_fr and F_r == est.F_fr_raw) else Estimate(
                est.x, F_c, F_r, est.status, est.solve_time_s)
        elif self.cfg.lqr.true_state_feedback:  # the published run: true state, F̂ as configured
            inner = Estimate(np.asarray(m.state, dtype=float).reshape(3).copy(), F_c, est.F_fr_raw,
                             est.status, est.solve_time_s)
        else:
            inner = _oracle_estimate(m.state)
        if not self._blind:
            out = self.lqr.step(inner, v_ref, w_ref)
            F, delta, sat, low = out.F_xR, out.delta, bool(out.saturated), out.F_low_speed
        else:
            rc = self._recovery  # recovery: blind, the minimal-risk stop (gates.py)
            assert rc is not None
            F, delta = blind_stop(float(est.x[0]), float(self._u_applied[1]), self.cfg.vehicle.mass,
                                  rc.stop_decel, *self._force_limits)
            self._cc[CC_BLIND] += 1
            sat, low = False, 0.0
        count_step(self._ib_count, code, sat)
        return F, delta, sat, low


def _build_governor(cfg: Config) -> GovernBlockParams:
    """The speed governor's block record of ``cfg.governor`` for the config's vehicle (governor.py,
    outer_block.py)."""
    g, veh, Tc = cfg.governor, cfg.vehicle, cfg.rates.Tc
    params = GovernorParams(
        margin=g.margin, rate_down=g.rate_down, rate_up=g.rate_up, rate_min=g.rate_min,
        mu_plan=cfg.tyre.mu_tyre, deadband=g.deadband,
        traction_factor=veh.wheelbase / veh.a / g.traction_margin,
        drag_per_kg=veh.drag_factor / veh.mass, g=veh.g, Tc=Tc,
        grip_alpha=min(Tc / g.grip_time_constant_s, 1.0))
    # the MPC's horizon, and the samples a slow-down from 1 to rate_min takes at rate_down
    preview = cfg.mpc.N + math.ceil((1.0 - g.rate_min) / (g.rate_down * Tc))
    # the grip model is the road the run declares, the plan check's (experiment.check_plan_limits):
    # read from the road's resistance when the tyres' grip follows the road (the config's tyre or
    # the scenario's), else tyre-only (governor.py)
    tyre, plant = cfg.tyre, cfg.scenario.plant
    follows = tyre.scale_grip_with_road or plant.grip_scales_with_road
    grip = GripParams(
        oracle=g.grip_source == "oracle", mu_nominal=veh.mu_nominal, mu_dry=tyre.mu_dry,
        mu_tyre=tyre.mu_tyre, grip_per_road=tyre.mu_tyre / tyre.mu_dry if follows else 0.0,
        deadband=g.deadband, g=veh.g, mass=veh.mass, rear_share=veh.a / veh.wheelbase,
        force_max=cfg.lqr.force_limits(veh)[1])
    return GovernBlockParams(params, grip, preview, float(cfg.dynamic_box.v[0]),
                             bool(cfg.fusion.mass_estimate))


class _Window:
    """The MPC's window as the TS-MPC reads it: v_d, ω_d (N + 1 each), the outer block's."""

    __slots__ = ("omega", "v")

    def __init__(self, v: NDArray[np.float64], omega: NDArray[np.float64]) -> None:
        self.v, self.omega = v, omega


#: TSLQR.step as defined (Cascade._back calls the block in its place unless it was replaced)
_TSLQR_STEP = TSLQR.step

#: The plan's status as the outer block's code (outer_block.MPC_*)
_MPC_STATUS_CODE = {MPCStatus.OPTIMAL: MPC_OPTIMAL, MPCStatus.SOFT: MPC_SOFT,
                    MPCStatus.FALLBACK: MPC_FALLBACK}

#: The estimator's status as the blocks' code (inner_block.EST_*, the run engine's MHE codes)
STATUS_CODE = {EstimatorStatus.OK: EST_OK, EstimatorStatus.REJECTED: EST_REJECTED,
             EstimatorStatus.FAILED: EST_FAILED, EstimatorStatus.WARMUP: EST_WARMUP}


def _oracle_estimate(state: ArrayLike) -> Estimate:
    """The true [v, α, ω] as an estimate, without friction compensation (F̂ = 0)."""
    x = np.asarray(state, dtype=float).reshape(3).copy()
    return Estimate(x=x, F_fr=0.0, F_fr_raw=0.0, status=EstimatorStatus.OK, solve_time_s=0.0)
