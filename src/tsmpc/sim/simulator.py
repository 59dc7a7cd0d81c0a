"""Multi-rate closed-loop simulation of the cascade (SPEC §1, §10).

Outer kinematic MPC every T_c, inner MHE-UIO + TS-LQR every T_d, plant RK4 every h, with exactly
T_c/T_d inner steps per outer step and T_d/h plant steps per inner step (integer counters, no
accumulated floating-point time, so nothing drifts). The blocks only compute; this module times
them, feeds them and logs everything into a :class:`~tsmpc.sim.log.RunLog`.

A run is reproducible from ``cfg.seed``: the sensor noise is the only random draw.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, SchedulingMode, TyreParams, VehicleParams, replace
from tsmpc.errors import NonFiniteError
from tsmpc.models.dynamic import DynamicTS
from tsmpc.models.kinematic import KinematicTS, pose_to_errors
from tsmpc.planning.reference import Reference
from tsmpc.scenarios import FrictionProfile, SensorNoise, paper_friction_profile
from tsmpc.sim.log import RunLog
from tsmpc.vehicle.plant import Plant

__all__ = ["Method", "Scenario", "SensorFault", "build_outer_controller", "simulate", "tracked_steps"]

ProgressFn = Callable[[int, int], None]


class SensorFault(Protocol):
    """Corrupts measurements: called every T_d with the time and the noisy measurement
    ``[X, Y, θ, v, ω]``; returns what the sensors deliver (may hold values or return NaN)."""

    def __call__(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]: ...


class Method(StrEnum):
    """Outer-loop method of a run."""

    FZN = "FZN"
    REF = "REF"
    ITER = "ITER"
    NL = "NL"

    @classmethod
    def parse(cls, text: str) -> Method:
        """Case-insensitive parse; the error lists the allowed values."""
        try:
            return cls(text.strip().upper())
        except ValueError:
            allowed = ", ".join(m.value.lower() for m in cls)
            raise ValueError(f"unknown method {text!r}; allowed: {allowed}") from None


@dataclass(frozen=True)
class Scenario:
    """What a run tracks and in which conditions.

    Attributes:
        name: label used in outputs.
        reference: reference sampled at T_c, including the N-step look-ahead at its end.
        friction: μ(road) as a function of time and travelled distance.
        initial_error: (lateral offset [m], heading offset [rad]) of the start pose.
        plant_vehicle, plant_tyre: plant-only parameters (model mismatch); None = the config's.
        sensor_fault: measurement corruption (dropouts, NaN bursts); None = healthy sensors.
        divergence_bound_m: end the run as diverged when |e_y| exceeds it (e.g. a track's
            half-width); None = ``cfg.divergence_bound_m``.
        meta: free-form facts written to metrics.json (source file, window, ...).
    """

    name: str
    reference: Reference
    friction: FrictionProfile = field(default_factory=paper_friction_profile)
    initial_error: tuple[float, float] = (0.0, 0.0)
    plant_vehicle: VehicleParams | None = None
    plant_tyre: TyreParams | None = None
    sensor_fault: SensorFault | None = None
    divergence_bound_m: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)


def build_outer_controller(cfg: Config, method: Method, P: np.ndarray, S: np.ndarray) -> Any:
    """The outer MPC of ``method`` with the terminal ingredients (P, S) of the kinematic design."""
    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    if method == Method.NL:
        from tsmpc.control.nl_mpc import NLMPC

        return NLMPC(cfg.mpc, model, P, S)
    from tsmpc.control.ts_mpc import TSMPC

    return TSMPC(cfg.mpc, model, P, S, mode=SchedulingMode(method.value.lower()))


def tracked_steps(ref: Reference, N: int) -> int:
    """Outer steps a run tracks: a closed lap to its end (its look-ahead wraps into the next lap,
    see :meth:`Reference.window`); an open reference keeps its last N samples as look-ahead."""
    return len(ref) if ref.closed else len(ref) - N


def _oracle_estimate(x: np.ndarray) -> Any:
    from tsmpc.estimation.mhe_uio import Estimate, EstimatorStatus

    return Estimate(x=x[3:6].copy(), F_fr=0.0, F_fr_raw=0.0, status=EstimatorStatus.OK,
                    solve_time_s=0.0)


def simulate(
    cfg: Config,
    method: Method | str,
    scenario: Scenario,
    *,
    oracle: bool = False,
    kinematic_design: Any = None,
    dynamic_design: Any = None,
    progress: ProgressFn | None = None,
    max_steps: int | None = None,
) -> RunLog:
    """Run the closed loop of ``method`` on ``scenario`` and return its log.

    Args:
        cfg: configuration (rates, vehicle, controllers, noise, seed).
        method: outer-loop method (FZN, REF, ITER, NL).
        scenario: reference, friction profile, initial error.
        oracle: ablation: the inner controller gets the true state and no friction compensation.
        kinematic_design, dynamic_design: LMI designs; loaded from the design cache if None.
        progress: called as ``progress(k, K)`` after each outer step.
        max_steps: stop after this many outer steps (shortened runs).

    A non-finite plant state ends the run early; the log then holds the steps done and
    ``termination`` says why. Controller and estimator failures are counted, never raised.
    """
    from tsmpc.control.slip_aware import outer_loop_errors
    from tsmpc.control.ts_lqr import TSLQR
    from tsmpc.estimation.mhe_uio import MHEUIO
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    method = Method.parse(method) if isinstance(method, str) else method
    if oracle:
        cfg = replace(cfg, lqr=replace(cfg.lqr, oracle=True, friction_compensation=False))
    kd = kinematic_design or load_or_design_kinematic(cfg)
    dd = dynamic_design or load_or_design_dynamic(cfg)
    rates, N = cfg.rates, cfg.mpc.N
    n_in, n_pl = rates.inner_per_outer, rates.plant_per_inner
    Tc, Td = rates.Tc, rates.Td
    ref = scenario.reference
    if abs(ref.dt - Tc) > 1e-9:
        ref = ref.resample(Tc)
    K = tracked_steps(ref, N)
    if K < 1:
        raise ValueError(f"reference has {len(ref)} samples: needs more than N = {N} for look-ahead")
    if max_steps is not None:
        K = min(K, int(max_steps))

    mpc = build_outer_controller(cfg, method, kd.P, kd.S)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    mhe_model = dyn
    lqr = TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth)
    plant = Plant(scenario.plant_vehicle or cfg.vehicle, scenario.plant_tyre or cfg.tyre, rates.h)
    fault = scenario.sensor_fault
    # A run leaving the road is a result (diverged), not a number: the track's half-width when
    # the scenario knows it, else the configured default.
    bound = scenario.divergence_bound_m or cfg.divergence_bound_m
    noise = SensorNoise(cfg.noise, cfg.seed)
    friction = scenario.friction
    p = cfg.vehicle
    # The disturbance the UIO should see: the plant's resistance minus the model's nominal one.
    mg = plant.vehicle.mass * plant.vehicle.g

    # Start pose on the reference, optionally offset laterally and in heading.
    th0 = float(ref.theta[0])
    lat, dth = scenario.initial_error
    x = np.array([ref.x[0] - lat * np.sin(th0), ref.y[0] + lat * np.cos(th0), th0 + dth,
                  max(float(ref.v[0]), 0.0), 0.0, float(ref.omega[0])])
    mhe = MHEUIO(cfg.mhe, mhe_model, p, Td, x0=x[3:6].copy())

    M = K * n_in
    t_outer = np.arange(K) * Tc + float(ref.t[0])
    refs = np.stack([ref.x[:K], ref.y[:K], ref.theta[:K], ref.v[:K], ref.omega[:K]], axis=1)
    state_outer = np.zeros((K, 6))
    errors = np.zeros((K, 3))
    errors_meas = np.zeros((K, 3))
    u_c = np.zeros((K, 2))
    x_pred = np.zeros((K, N + 1, 3))
    mpc_time = np.zeros(K)
    mpc_status = np.empty(K, dtype="<U16")
    mpc_it = np.zeros(K, dtype=np.int64)
    mpc_qpit = np.zeros(K, dtype=np.int64)
    mpc_clip = np.zeros(K, dtype=np.int64)
    t_inner = np.arange(M) * Td + float(ref.t[0])
    state = np.zeros((M, 6))
    est = np.zeros((M, 3))
    meas = np.zeros((M, 2))
    f_hat = np.zeros(M)
    f_raw = np.zeros(M)
    f_true = np.zeros(M)
    mu_log = np.zeros(M)
    cmd_log = np.zeros((M, 2))
    sat = np.zeros(M, dtype=bool)
    mhe_time = np.zeros(M)
    lqr_time = np.zeros(M)
    mhe_status = np.empty(M, dtype="<U16")

    clock = time.perf_counter
    u_prev = np.array([x[3], x[5]])
    u_applied = np.zeros(2)
    s_travel = 0.0
    pose_meas = x[:3].copy()
    n_pose_rejected = 0
    termination = "completed"
    done = K
    slip_aware, tangent, alpha_hat = cfg.mpc.slip_aware, cfg.mpc.tangent_heading, 0.0
    t_start = clock()
    m = 0
    def measure(t: float) -> NDArray[np.float64]:
        y5 = np.array([x[0], x[1], x[2], x[3], x[5]]) + noise.sample()
        return fault(t, y5) if fault is not None else y5

    for k in range(K):
        y0 = measure(k * Tc)  # the pose part feeds the MPC this step
        state_outer[k] = x
        errors[k] = pose_to_errors(x[0], x[1], x[2], refs[k, 0], refs[k, 1], refs[k, 2])
        if np.all(np.isfinite(y0[:3])):
            pose_meas = y0[:3]
        else:  # keep the last good pose; the MPC never sees NaN
            n_pose_rejected += 1
        e_meas = pose_to_errors(pose_meas[0], pose_meas[1], pose_meas[2],
                                refs[k, 0], refs[k, 1], refs[k, 2])
        errors_meas[k] = e_meas
        if bound is not None and abs(errors[k, 1]) > bound:
            termination = (f"diverged: |e_y| = {abs(errors[k, 1]):.2f} m > {bound:g} m "
                           f"at t = {k * Tc:.1f} s")
            done = k + 1
            break
        window = ref.window(k, N + 1)
        if slip_aware or tangent:  # beyond the paper (tsmpc.control.slip_aware)
            e_meas = outer_loop_errors(pose_meas, refs[k, :3], alpha_hat if slip_aware else 0.0,
                                       float(window.omega[1]) * Tc if tangent else 0.0)
        t0 = clock()
        res = mpc.step(e_meas, u_prev, window)
        mpc_time[k] = clock() - t0
        u_prev = np.asarray(res.u, dtype=float)
        u_c[k] = u_prev
        xp = np.asarray(res.x_pred)
        x_pred[k, : xp.shape[0]] = xp[: N + 1]
        mpc_status[k] = str(res.status)
        mpc_it[k] = res.iterations
        mpc_qpit[k] = res.qp_iterations
        mpc_clip[k] = res.n_clipped
        v_ref, w_ref = float(u_prev[0]), float(u_prev[1])
        try:
            for j in range(n_in):
                t = (k * n_in + j) * Td
                yj = y0 if j == 0 else measure(t)
                mu = float(friction.mu(t, s_travel))
                y = yj[3:5]
                t1 = clock()
                e = mhe.step(y, u_applied)
                t2 = clock()
                cmd = lqr.step(_oracle_estimate(x) if oracle else e, v_ref, w_ref)
                t3 = clock()
                u_applied = np.array([cmd.F_xR, cmd.delta])
                state[m], est[m], meas[m] = x, e.x, y
                f_hat[m], f_raw[m] = e.F_fr, e.F_fr_raw
                f_true[m] = (mu - p.mu_nominal) * mg
                mu_log[m], cmd_log[m], sat[m] = mu, u_applied, cmd.saturated
                mhe_time[m], lqr_time[m], mhe_status[m] = t2 - t1, t3 - t2, str(e.status)
                m += 1
                alpha_hat = float(e.x[1])
                x = plant.step(x, u_applied, mu, n_pl)
                s_travel += max(x[3], 0.0) * Td
        except NonFiniteError as err:
            termination = f"plant diverged at t = {k * Tc:.2f} s: {err}"
            done = k + 1
            break
        if progress is not None:
            progress(k + 1, K)
    wall = clock() - t_start

    events = {
        "mpc_soft": int(np.count_nonzero(mpc_status[:done] == "soft")),
        "mpc_fallback": int(np.count_nonzero(mpc_status[:done] == "fallback")),
        "mpc_scheduling_clipped": int(mpc_clip[:done].sum()),
        "mhe_rejected": int(np.count_nonzero(mhe_status[:m] == "rejected")),
        "mhe_failed": int(np.count_nonzero(mhe_status[:m] == "failed")),
        "inner_saturated": int(np.count_nonzero(sat[:m])),
        "pose_rejected": n_pose_rejected,
    }
    return RunLog(
        method=method.value, scenario=scenario.name, Tc=Tc, Td=Td,
        t_outer=t_outer[:done], ref=refs[:done], state_outer=state_outer[:done],
        errors=errors[:done], errors_measured=errors_meas[:done], u_c=u_c[:done],
        x_pred=x_pred[:done], mpc_time_s=mpc_time[:done], mpc_status=mpc_status[:done],
        mpc_iterations=mpc_it[:done], mpc_qp_iterations=mpc_qpit[:done],
        mpc_clipped=mpc_clip[:done],
        t_inner=t_inner[:m], state=state[:m], estimate=est[:m], measurement=meas[:m],
        F_fr_hat=f_hat[:m], F_fr_raw=f_raw[:m], F_fr_true=f_true[:m], mu_road=mu_log[:m],
        command=cmd_log[:m], saturated=sat[:m], mhe_time_s=mhe_time[:m],
        lqr_time_s=lqr_time[:m], mhe_status=mhe_status[:m],
        wall_s=wall, termination=termination, events=events,
        meta={"oracle": oracle, "seed": cfg.seed, **scenario.meta},
    )
