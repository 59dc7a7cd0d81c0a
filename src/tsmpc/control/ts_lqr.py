"""Inner loop: gain-scheduled TS-LQR on the Apkarian-augmented model with friction compensation
(paper Sec. 3.2, Sec. 4; the paper's LMI designs; the paper's inner loop).

Law, every T_d, with ϑ = (δ_f, v̂, α̂) clipped into the box and r = [v_ref, ω_ref]::

    K(ϑ) = Σ μ_i(ϑ) K_i                                 (the LMI design, 2 × 6)
    N̄(ϑ) = [C (I − A − B K₅)⁻¹ B]⁻¹                     (static reference gain, C = rows v, ω)
    x = [v̂, α̂, ω̂, F_f, δ_f, ζ]
    u_f = N̄(ϑ) r + K(ϑ) x                              (reference feed-forward + state feedback)
    f⁺ = e^{−λT_d} f + (1 − e^{−λT_d}) u_f     (the Apkarian input filter, the plant input)
    ζ⁺ = ζ + T_d (ω_ref − ω̂)                   (yaw-rate integral; frozen while saturated)
    F_xR = F_f + F̂_fr [+ M (v_ref − v̂)/τ],   δ = δ_f      (then saturations)

N̄ is the classical static reference gain of the plant + filter loop (A, B the 5-state augmented
model at ϑ without the integrator, K₅ = K without its ζ column): on the nominal model a constant r
is tracked with zero steady-state error *and* ζ = 0 at the steady state, so the integrator only
removes what the model misses (tyre nonlinearity) and the compensation F̂_fr removes the unknown
road resistance. The steady state of ``x⁺ = A_d x + B_d u`` is that of ``ẋ = A x + B u`` for
Euler and ZOH alike, so N̄ is computed from the continuous matrices: N̄ = −[C (A + B K₅)⁻¹ B]⁻¹.

The bracketed term is the switch ``speed_feedback`` of :class:`~tsmpc.config.LQRSettings`:
``M (v_ref − v̂)/τ`` (τ = ``speed_time_constant``) is proportional *feedback* on the speed error,
beyond the paper; it makes v follow the outer loop's command within ≈ τ where the paper's loop
takes seconds (README, "Why the paper's inner loop lags"). ``friction_estimate`` chooses the
compensated F̂_fr: the MHE's window fit (default) or the paper's one-step UIO formula.

Anti-windup: the filter states are clamped to the saturation limits and ζ stops integrating
while an input saturates.

``low_speed_resistance`` (beyond the paper): the model's road resistance, written ``(μ_o g / v) v``
in the linear-parameter-varying form, is evaluated at the speed clipped into the box, so below the
box's floor v_min (2 m/s) it shrinks to ``μ_o M g v / v_min``: the law under-drives a launch by up to
μ_o M g and the MHE reads the missing resistance as friction (F̂ twice the true one at 1 m/s). The
switch adds the missing part ``μ_o M g (1 − v̂ / v_min)`` (:meth:`TSLQR.low_speed_residual`) to the
force, outside the filter like the compensation, and the cascade removes it from the force the MHE
sees, so the model's resistance is μ_o M g at every speed.

The law as the published run ran it (the published run; ``lqr.law = "as-run"``, a quirk of that run) is
:mod:`tsmpc.control.paper_as_run`.

One definition (issue 34): the step's glue around the compiled law — the hold on a non-finite
estimate, the compensated estimate (:func:`compensated_friction`), the low-speed residual
(:func:`low_speed_force`) and the call of :func:`tsmpc.kernels.lqr.lqr_step` — is the ``@jitable``
block :func:`inner_step` over the records :class:`InnerParams` and :class:`LQRLaw`. :meth:`TSLQR.step`
calls it as Python; the run engine (``tsmpc.kernels.engine.run``) and the batch compile it. Its
status (:data:`LQR_OK`, :data:`LQR_HELD`, :data:`LQR_NUMPY`) says who decided the step: when the
compiled law is absent or finds N̄ singular, the numpy step of :class:`TSLQR` decides (the engine
hands that step to its caller, which runs it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc._records import StateField, quick_init
from tsmpc.config import FrictionEstimate, LQRSettings, VehicleParams
from tsmpc.control.stiffness_block import PRM_A, PRM_B, PRM_CF, PRM_CR, PRM_I, give_model
from tsmpc.errors import ConfigError
from tsmpc.kernels.jit import _numba_ready, jitable
from tsmpc.models.dynamic import DynamicTS, continuous_matrices, equilibrium, steady_states

lqr_step: Any = None  # no compiled law: inner_step leaves every step to the numpy law (law=None)
if _numba_ready():  # the compiled law, called by inner_step (compiled into the engine with it)
    from tsmpc.kernels.lqr import lqr_step

__all__ = ["LQR_HELD", "LQR_NUMPY", "LQR_OK", "N_LAW", "TSLQR", "InnerCommand", "InnerParams", "InnerStep",
           "LQRLaw", "compensated_friction", "equilibrium", "inner_step", "low_speed_force", "pack_law",
           "steady_states", "unpack_law"]


@quick_init
@dataclass(frozen=True)
class InnerCommand:
    """Plant input for the next T_d: rear force [N] and steering [rad] (after saturation)."""

    F_xR: float
    delta: float
    saturated: bool
    F_comp: float  #: the friction compensation included in F_xR [N]
    #: the model's road resistance below the box's speed floor included in F_xR [N]
    #: (``low_speed_resistance``; the MHE must see F_xR minus this, see :meth:`TSLQR.low_speed_residual`)
    F_low_speed: float = 0.0


#: Statuses of :func:`inner_step`: who decided the step.
LQR_OK = 0  #: the compiled law
LQR_HELD = 1  #: nobody: the estimate is not finite, the last input is held (reported saturated)
LQR_NUMPY = 2  #: the numpy step of :class:`TSLQR` must (no compiled law, or it found N̄ singular)


class InnerParams(NamedTuple):
    """The step's switches and constants around the law (:class:`~tsmpc.config.LQRSettings`, the
    vehicle and the dynamic box).

    Attributes:
        compensation: add the friction estimate F̂_fr to the force (``friction_compensation``).
        raw_estimate: compensate the paper's one-step UIO formula instead of the MHE's window fit
            (``friction_estimate = "uio"``).
        low_speed: add the low-speed residual (``low_speed_resistance``).
        v_min: the dynamic box's speed floor [m/s].
        resistance: the model's road resistance μ_o g M [N] (drag apart).
    """

    compensation: bool
    raw_estimate: bool
    low_speed: bool
    v_min: float
    resistance: float


class LQRLaw(NamedTuple):
    """The compiled law's parameters (:func:`tsmpc.kernels.lqr.lqr_step`'s, in its order).

    Attributes:
        Kv: (n_v, 2, 6) vertex gains K_i.
        zlo: (3,) lower corner of the premise box (δ, v, α).
        zhi: (3,) upper corner of the premise box.
        bits: (n_v, 3) vertex bits of the box (True: the upper side).
        prm: (8,) [M, I, C_f, C_r, a, b, μ_o g, drag factor] of N̄'s model (C_f, C_r follow the
            stiffness fit: written in place).
        lam: Apkarian filter bandwidth λ [rad/s].
        afilt: the filter's e^{−λ T_d}.
        Td: sample time [s].
        F_min: lower force limit [N].
        F_max: upper force limit [N].
        d_min: lower steering limit [rad].
        d_max: upper steering limit [rad].
        speed_feedback: the speed-error feedback M (v_ref − v̂)/τ (``speed_feedback``).
        tau: its time constant τ [s].
    """

    Kv: NDArray[np.float64]
    zlo: NDArray[np.float64]
    zhi: NDArray[np.float64]
    bits: NDArray[np.bool_]
    prm: NDArray[np.float64]
    lam: float
    afilt: float
    Td: float
    F_min: float
    F_max: float
    d_min: float
    d_max: float
    speed_feedback: bool
    tau: float


#: Length of :func:`pack_law`'s vector: LQRLaw's scalars (lam … tau, in its order).
N_LAW = 9


def pack_law(law: LQRLaw) -> NDArray[np.float64]:
    """The law's scalars as the float vector :func:`unpack_law` reads (its arrays are passed as
    they are: ``prm`` is written in place by the stiffness fit; compiled callers rebuild it: the
    cascade's compiled calls, the run engine's parameter slots)."""
    return np.array([law.lam, law.afilt, law.Td, law.F_min, law.F_max, law.d_min, law.d_max,
                     law.speed_feedback, law.tau], dtype=np.float64)


@jitable
def unpack_law(a: NDArray[np.float64], Kv: NDArray[np.float64], zlo: NDArray[np.float64],
               zhi: NDArray[np.float64], bits: NDArray[np.bool_], prm: NDArray[np.float64]) -> LQRLaw:
    """The law of :func:`pack_law`'s vector and the law's arrays."""
    return LQRLaw(Kv, zlo, zhi, bits, prm, a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7] != 0.0, a[8])


class InnerStep(NamedTuple):
    """What :func:`inner_step` decided.

    Attributes:
        F_xR: rear force for the next T_d [N] (after saturation; 0 with :data:`LQR_NUMPY`).
        delta: steering [rad] (after saturation; 0 with :data:`LQR_NUMPY`).
        saturated: an input saturated (True when held).
        F_comp: the friction compensation in F_xR [N].
        F_low_speed: the low-speed residual in F_xR [N].
        status: :data:`LQR_OK`, :data:`LQR_HELD` or :data:`LQR_NUMPY`.
    """

    F_xR: float
    delta: float
    saturated: bool
    F_comp: float
    F_low_speed: float
    status: int


@jitable
def compensated_friction(p: InnerParams, F_window: float, F_raw: float) -> float:
    """F̂_fr the force compensates (paper Sec. 4: F_xR = F_f + F̂_fr): the window fit or the one-step
    UIO formula as configured; 0 without compensation or for a non-finite estimate."""
    if not p.compensation:
        return 0.0
    F_hat = F_raw if p.raw_estimate else F_window
    return F_hat if math.isfinite(F_hat) else 0.0


@jitable
def low_speed_force(p: InnerParams, v: float) -> float:
    """The model's road resistance the clipped premise leaves out at speed ``v`` [N] (beyond the
    paper): μ_o M g (1 − max(v, 0) / v_min) below the box's speed floor, 0 above it and with the
    switch off."""
    if not p.low_speed or not v < p.v_min:
        return 0.0
    return p.resistance * (1.0 - max(v, 0.0) / p.v_min)


@jitable
def inner_step(p: InnerParams, law: LQRLaw | None, s: NDArray[np.float64], v: float, alpha: float,
               omega: float, F_window: float, F_raw: float, v_ref: float, w_ref: float) -> InnerStep:
    """One T_d of the TS-LQR around its law, from the estimate (v̂, α̂, ω̂), the friction estimates
    (window fit, one-step UIO) and the outer loop's references (v_ref, ω_ref).

    A non-finite estimate holds the last input (``s[4:6]``) and changes nothing. Else the law —
    the compiled :func:`~tsmpc.kernels.lqr.lqr_step` on the controller state ``s`` (updated in
    place) with the compensation and the low-speed residual added outside the filter — decides,
    unless ``law`` is None or N̄ is singular (:data:`LQR_NUMPY`: ``s`` unchanged, the terms are
    returned for the numpy step)."""
    if not (math.isfinite(v) and math.isfinite(alpha) and math.isfinite(omega)):
        return InnerStep(float(s[4]), float(s[5]), True, 0.0, 0.0, LQR_HELD)
    comp = compensated_friction(p, F_window, F_raw)
    low = low_speed_force(p, v)
    if law is None:
        return InnerStep(0.0, 0.0, False, comp, low, LQR_NUMPY)
    F, d, sat, ok = lqr_step(s, v, alpha, omega, comp + low, v_ref, w_ref, law.Kv, law.zlo, law.zhi, law.bits,
                             law.prm, law.lam, law.afilt, law.Td, law.F_min, law.F_max, law.d_min, law.d_max,
                             law.speed_feedback, law.tau)
    if not ok:  # singular reference gain: the numpy step decides (and may raise)
        return InnerStep(0.0, 0.0, False, comp, low, LQR_NUMPY)
    return InnerStep(F, d, sat, comp, low, LQR_OK)


#: TSLQR._kernel_agrees's answers in this process, by the law's inputs
_AGREES: dict[tuple[Any, ...], bool] = {}


class TSLQR:
    """Gain-scheduled LQR with Apkarian filter, yaw-rate integrator and friction compensation.

    Args:
        gains: (8, 2, 6) vertex gains of the dynamic design (u = K x, physical units).
        model: dynamic TS model (its premise box and memberships schedule the gains).
        vehicle: vehicle parameters (equilibrium).
        settings: saturations, compensation switch.
        Td: sample time [s].
        bandwidth: Apkarian filter λ [rad/s] (must match the design).
        jit: run :meth:`step` as one compiled call (:mod:`tsmpc.kernels.lqr`, the same law); None =
            unless ``TSMPC_NO_JIT`` is set; False = numpy only (the tests' oracle).
    """

    def __init__(
        self, gains: NDArray[np.float64], model: DynamicTS, vehicle: VehicleParams, settings: LQRSettings,
        Td: float, bandwidth: float = 10.0, jit: bool | None = None,
    ) -> None:
        self.K = np.asarray(gains, dtype=float)
        if self.K.shape != (model.n_vertices, 2, 6):
            raise ConfigError(f"TSLQR: gains must have shape ({model.n_vertices}, 2, 6), got {self.K.shape}")
        self.model = model
        self.vehicle = vehicle
        self.settings = settings
        self.Td = float(Td)
        self.bandwidth = float(bandwidth)
        self._a = math.exp(-bandwidth * self.Td)
        f_lo, f_hi = settings.force_limits(vehicle)
        self._lo = np.array([f_lo, -settings.delta_max])
        self._hi = np.array([f_hi, settings.delta_max])
        # The step runs every T_d on 2-vectors: plain floats beat numpy's per-call cost, so the
        # premise box and vertex bits are unpacked once here.
        box = model.premise_box
        self._zlo = tuple(float(v) for v in box.lower)
        self._zhi = tuple(float(v) for v in box.upper)
        self._bits = tuple(tuple(bool(b) for b in row) for row in box.vertex_bits)
        # Controller state [f_F, f_δ, ζ, started, applied_F, applied_δ], shared by both paths.
        self._s = np.zeros(6)
        p = vehicle
        # The step's glue (inner_step): the inner block's record carries it (the cascade's
        # compiled calls and the run engine read it packed: inner_block.pack_inner_block).
        self._inner = InnerParams(
            compensation=bool(settings.friction_compensation),
            raw_estimate=settings.friction_estimate != FrictionEstimate.WINDOW,
            low_speed=bool(settings.low_speed_resistance), v_min=self._zlo[1],
            resistance=p.mu_nominal * p.g * p.mass)
        self._kern = None
        self._law: LQRLaw | None = None
        if jit is None or jit:
            from tsmpc import kernels

            self._kern = kernels.load("lqr")
        if self._kern is not None:
            try:
                self._law = LQRLaw(
                    Kv=np.ascontiguousarray(self.K), zlo=np.array(self._zlo), zhi=np.array(self._zhi),
                    bits=np.array(self._bits, dtype=np.bool_),
                    prm=np.array([p.mass, p.inertia, getattr(p, "C_f", p.cornering_stiffness),
                                  getattr(p, "C_r", p.cornering_stiffness), p.a, p.b, p.mu_nominal * p.g,
                                  p.drag_factor], dtype=float),
                    lam=self.bandwidth, afilt=self._a, Td=self.Td, F_min=float(self._lo[0]),
                    F_max=float(self._hi[0]), d_min=float(self._lo[1]), d_max=float(self._hi[1]),
                    speed_feedback=bool(settings.speed_feedback), tau=float(settings.speed_time_constant))
            except (AttributeError, TypeError):  # parameters the kernel does not know: numpy
                self._kern = None
        if self._kern is not None:
            # (once per law in a process: a batch builds one cascade per run)
            key = (self.K.tobytes(), self.K.shape, repr(model.box), repr(model.params), model.Td,
                   str(getattr(model, "method", "")), repr(vehicle), repr(settings), self.Td, self.bandwidth)
            agrees = _AGREES.get(key)
            if agrees is None:
                agrees = _AGREES[key] = self._kernel_agrees()
            if not agrees:
                self._kern = None  # the law changed on the numpy side only: numpy it is
        self.reset()

    def _kernel_agrees(self) -> bool:
        """The compiled step reproduces the numpy step on a short probe sequence (guards against a
        law edited on one side only)."""
        from types import SimpleNamespace

        kern, out = self._kern, []
        for use in (None, kern):
            self._kern = use
            self.reset()
            for k in range(3):
                est = SimpleNamespace(x=(9.0 + k, 0.01, 0.1), F_fr=120.0, F_fr_raw=90.0)
                c = self._step(est, 10.0, 0.12)  # not step(): callers may wrap it
                out.append((c.F_xR, c.delta, c.saturated))
        self._kern = kern
        self.reset()
        a, b = np.array(out[:3], dtype=float), np.array(out[3:], dtype=float)
        return bool(np.allclose(a, b, rtol=1e-9, atol=1e-12))

    @property
    def dt(self) -> float:
        """Sample time T_d [s] (the runtime protocol's name)."""
        return self.Td

    def set_cornering_stiffness(self, C_f: float, C_r: float, inertia: float | None = None,
                                a: float | None = None, b: float | None = None) -> None:
        """Use axle stiffnesses C_f, C_r [N/rad] (and, given, the yaw inertia and the CoG's distances
        a, b) in the reference gain N̄ (the model of the feed-forward) from the next step on (an
        online estimate, ``fusion.stiffness_estimate``); the LMI gains K_i and the controller state
        are kept."""
        self.model_stiffness(C_f, C_r, inertia, a, b)
        if self._law is not None:  # [M, I, C_f, C_r, a, b, μ_o g, d], read by every kernel step
            v = self.vehicle
            give_model(self._law.prm, PRM_I, PRM_CF, PRM_CR, PRM_A, PRM_B, float(C_f), float(C_r),
                       float(v.inertia), float(v.a), float(v.b))

    def model_stiffness(self, C_f: float, C_r: float, inertia: float | None = None, a: float | None = None,
                        b: float | None = None) -> None:
        """The lateral model of the numpy law (its vehicle): C_f, C_r and, given, I_z, a, b; the
        compiled law's ``prm`` left as it is: the cascade's stiffness block
        (control/stiffness_block.py) writes it."""
        self.vehicle = self.vehicle.with_lateral_model(C_f, C_r, inertia, a, b)

    def reset(self) -> None:
        """Filter states at rest, integrator cleared."""
        self._s[:] = 0.0

    # The controller state as named views of the state vector (the numpy step's variables).
    _f: StateField = StateField("_s", slice(0, 2))
    _zeta: StateField = StateField("_s", 2, float)
    _started: StateField = StateField("_s", 3, bool)
    _applied: StateField = StateField("_s", slice(4, 6))

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """The last plant input [F_xR, δ] (what the MHE must see)."""
        return self._applied.copy()

    def reference_gain(self, delta: float, v: float, K: NDArray[np.float64]) -> NDArray[np.float64]:
        """Static reference gain N̄ (2 × 2) at ϑ = (δ, v) for the blended gain K (2 × 6).

        N̄ = −[C (A + B K₅)⁻¹ B]⁻¹ on the continuous plant + filter model (5 states; equal to the
        discrete [C (I − A_d − B_d K₅)⁻¹ B_d]⁻¹ for Euler and ZOH): with u = N̄ r + K x the
        steady state of the nominal loop has C x = r and ζ = 0 (the paper's inner loop)."""
        Aa, Ba = self._plant_filter(delta, v)
        X = np.linalg.solve(Aa + Ba @ K[:, :5], Ba)  # (A + B K₅)⁻¹ B
        return -np.linalg.inv(X[[0, 2], :]).astype(np.float64, copy=False)

    def _plant_filter(self, delta: float, v: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Continuous plant + Apkarian filter (5 × 5, 5 × 2) at (δ, v) clipped into the box."""
        delta = min(max(delta, self._zlo[0]), self._zhi[0])
        v = min(max(v, self._zlo[1]), self._zhi[1])
        A, B = continuous_matrices(v, delta, self.vehicle)
        Aa = np.zeros((5, 5))
        Aa[:3, :3], Aa[:3, 3:] = A, B
        Aa[3, 3] = Aa[4, 4] = -self.bandwidth
        Ba = np.zeros((5, 2))
        Ba[3, 0] = Ba[4, 1] = self.bandwidth
        return Aa, Ba

    def step(self, estimate: Any, v_ref: float, omega_ref: float) -> InnerCommand:
        """One inner step from the estimate (``.x`` = [v̂, α̂, ω̂], ``.F_fr``, ``.F_fr_raw``) and
        the outer-loop references; returns the plant input for the next T_d."""
        return self._step(estimate, v_ref, omega_ref)

    def low_speed_residual(self, v: float) -> float:
        """The model's road resistance the clipped premise leaves out at speed ``v`` [N]:
        μ_o M g (1 − v / v_min) below the box's speed floor v_min, 0 above it and with
        ``low_speed_resistance`` off (:func:`low_speed_force`)."""
        return low_speed_force(self._inner, v)

    def _step(self, estimate: Any, v_ref: float, omega_ref: float) -> InnerCommand:
        v, al, om = np.asarray(estimate.x, dtype=float).reshape(3).tolist()
        # the block decides (the compiled law inside it), or hands the step to the numpy law below
        out = inner_step(self._inner, self._law if self._kern is not None else None, self._s, v, al, om,
                         float(estimate.F_fr), float(estimate.F_fr_raw), float(v_ref), float(omega_ref))
        if out.status != LQR_NUMPY:
            return InnerCommand(out.F_xR, out.delta, out.saturated, out.F_comp, out.F_low_speed)
        return self._numpy_step(v, al, om, float(v_ref), float(omega_ref), out.F_comp, out.F_low_speed)

    def _numpy_step(self, v: float, al: float, om: float, v_ref: float, omega_ref: float, comp: float,
                    low: float) -> InnerCommand:
        """The law in numpy (no compiled law, or it found N̄ singular): the tests' oracle."""
        st = self.settings
        Fmin, dmin = float(self._lo[0]), float(self._lo[1])
        Fmax, dmax = float(self._hi[0]), float(self._hi[1])
        r = np.array([v_ref, omega_ref])
        if not self._started:  # bumpless start: filter at the steady-state input of r, ζ = 0
            K0 = np.tensordot(np.asarray(self._memberships(0.0, v, al)), self.K, axes=(0, 0))
            u_ss = self._steady_input(0.0, v, K0, r)
            self._f = np.array([min(max(u_ss[0], Fmin), Fmax), min(max(u_ss[1], dmin), dmax)])
            self._started = True
        f0, f1 = float(self._f[0]), float(self._f[1])
        # K(ϑ) = Σ μ_i(ϑ) K_i, ϑ = (δ_f, v̂, α̂).
        mu = self._memberships(f1, v, al)
        K = np.tensordot(np.asarray(mu), self.K, axes=(0, 0))
        Nbar = self.reference_gain(f1, v, K)
        x = np.array([v, al, om, f0, f1, self._zeta])
        u = Nbar @ r + K @ x
        u0, u1 = min(max(float(u[0]), Fmin), Fmax), min(max(float(u[1]), dmin), dmax)
        # Force terms outside the filter: the plant receives the filter state (held over T_d).
        F_add = 0.0
        if st.speed_feedback:  # feedback on the speed error (beyond the paper)
            F_add = self.vehicle.mass * (v_ref - v) / st.speed_time_constant
        out0 = f0 + F_add + comp + low
        o0, o1 = min(max(out0, Fmin), Fmax), min(max(f1, dmin), dmax)
        saturated = o0 != out0 or o1 != f1
        a = self._a
        self._f = np.array([min(max(a * f0 + (1.0 - a) * u0, Fmin), Fmax),
                            min(max(a * f1 + (1.0 - a) * u1, dmin), dmax)])
        if not saturated:
            self._zeta += self.Td * (omega_ref - om)
        self._applied = np.array([o0, o1])
        return InnerCommand(o0, o1, saturated, comp, low)

    def _steady_input(self, delta: float, v: float, K: NDArray[np.float64], r: NDArray[np.float64]
                      ) -> NDArray[np.float64]:
        """Filter input at the nominal steady state of reference r (u = N̄ r + K₅ x_ss)."""
        Nbar = self.reference_gain(delta, v, K)
        Aa, Ba = self._plant_filter(delta, v)
        xss = -np.linalg.solve(Aa + Ba @ K[:, :5], Ba @ (Nbar @ r))
        return xss[3:5].astype(np.float64, copy=False)

    def _memberships(self, *z: float) -> list[float]:
        """μ_i(ϑ) of the dynamic box (same as ``SchedulingBox.memberships``, on floats)."""
        eta = [min(max((zj - lo) / (hi - lo), 0.0), 1.0)
               for zj, lo, hi in zip(z, self._zlo, self._zhi, strict=True)]
        out = []
        for bits in self._bits:
            m = 1.0
            for b, e in zip(bits, eta, strict=True):
                m *= e if b else 1.0 - e
            out.append(m)
        return out
