"""The inner law as the published run ran it (the published run): a quirk of that run, not a recommendation
(``lqr.law = "as-run"``, the ``paper-as-run`` preset). Ours is :mod:`tsmpc.control.ts_lqr`.

Every T_d (the published run: 1 ms), with the Apkarian filter states ``F₁`` [N] and ``σ₁`` [rad]
(σ₁ in the *fed-back* coordinate δ + b, b = ``steering_bias_rad``), the yaw-rate integral ζ and
``F_app``, the clipped force the law produced at the previous step::

    ϑ = (σ₁ − b,  v + s,  α)                       scheduling (s = scheduling_speed_shift)
    μ = memberships(ϑ)                              not clipped when extrapolate_memberships
    K = Σ μ_i K_i                                   the scheduled gains
    A₅ = I + T_d A₅,c(σ₁ − b, v),  B₅ = T_d B₅,c    5-state plant + filter model (Euler)
    N̄ = [C (I − A₅ − B₅ K₁:₅)⁻¹ B₅]⁻¹              rebuilt every step; C picks v and ω
    u = N̄ [v_ref, ω_ref] + K [v, α, ω, F_app, σ₁, ζ]
    F₁ ← F₁ + T_d λ (u_F − F₁),   σ₁ ← σ₁ + T_d λ (u_δ − σ₁)      (Euler, λ = 10 rad/s)
    F_xR = sat(F₁ [+ M (v_ref − v)/τ] [+ F̂_fr]),   δ = sat(σ₁ − b)
    F_app = sat(F₁),   ζ ← ζ + T_d (ω_ref − ω)      (no anti-windup; no speed integral)

The 5-state model ``A₅,c = [[A(v, δ), B(v, δ)], [0, −λI]]``, ``B₅,c = [0; λI]`` (the paper's dynamic model) is
evaluated directly at the measured speed and the scheduled steering, neither shifted nor clipped
(the shift is a property of the gain scheduling, the published run); only a floor of
:data:`V_MODEL_FLOOR` guards its 1/v terms at standstill (the published run starts at 0.12 m/s).
That reading is also the one under which the published F₁(0) = μ_o M g is the model's steady force
at the start speed; scheduled like the gains (at v + 2 m/s), the model's rolling resistance would
be μ_o M g · v/(v + 2) ≈ 250 N at 0.12 m/s and the car would stall at the start. The Euler steady
state equals the continuous one, so N̄ equals the static reference gain of
:class:`~tsmpc.control.ts_lqr.TSLQR` at that model (tested).
The bias b enters as ``K(:, 5)·b`` in u: the design has no term to cancel it,
so the yaw-rate integrator winds it out — the start-up transient of the published run. The
compensation and speed-error feedback (off in that run) are added outside the filter, as in ours,
and do not enter ``F_app``. The plant receives the filter state *after* this step's update.

Without ``initial_filter_state`` the filter starts at the nominal steady state of the first
reference (F₁ = u_F,ss, σ₁ = δ_ss + b), like ours; with it, at the given (F₁(0), σ₁(0)).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import FrictionEstimate, LQRSettings, VehicleParams
from tsmpc.control.ts_lqr import InnerCommand
from tsmpc.errors import ConfigError
from tsmpc.models.dynamic import DynamicTS, continuous_matrices

__all__ = ["AsRunLQR", "as_run_memberships", "as_run_reference_gain"]

_C = np.array([[1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0]])  # outputs v and ω
#: Speed floor [m/s] of the 1/v terms of the model N̄ is computed on (a standstill guard).
V_MODEL_FLOOR = 0.1


def as_run_memberships(z: tuple[float, float, float], lower: NDArray[np.float64],
                       upper: NDArray[np.float64], bits: NDArray[np.bool_], *, extrapolate: bool
                       ) -> NDArray[np.float64]:
    """μ (2^r,) of z: the box memberships of :class:`~tsmpc.models.polytope.SchedulingBox`,
    without clipping z into the box when ``extrapolate`` (then some μ_i < 0, Σ μ_i = 1 still)."""
    zz = np.asarray(z, dtype=float)
    eta1 = (zz - lower) / (upper - lower)
    if not extrapolate:
        eta1 = np.clip(eta1, 0.0, 1.0)
    w = np.where(bits, eta1[None, :], 1.0 - eta1[None, :])
    return np.prod(w, axis=-1)


def as_run_reference_gain(A5: NDArray[np.float64], B5: NDArray[np.float64], K: NDArray[np.float64]
                          ) -> NDArray[np.float64]:
    """N̄ = [C (I − A₅ − B₅ K₁:₅)⁻¹ B₅]⁻¹ (2 × 2) of the discrete 5-state model (C: v and ω)."""
    X = np.linalg.solve(np.eye(5) - A5 - B5 @ K[:, :5], B5)
    return np.linalg.inv(_C @ X).astype(np.float64, copy=False)


class AsRunLQR:
    """The published run's inner law (module docstring); the interface of
    :class:`~tsmpc.control.ts_lqr.TSLQR` (``dt``, ``reset``, ``step``, ``applied_input``).

    Args:
        gains: (8, 2, 6) vertex gains (u = K x, physical units).
        model: dynamic TS model (premise box; vertex order).
        vehicle: vehicle parameters (the vertex models).
        settings: saturations and the as-run switches of :class:`~tsmpc.config.LQRSettings`.
        Td: sample time [s].
        bandwidth: Apkarian filter λ [rad/s].
    """

    def __init__(self, gains: NDArray[np.float64], model: DynamicTS, vehicle: VehicleParams,
                 settings: LQRSettings, Td: float, bandwidth: float = 10.0) -> None:
        self.K = np.asarray(gains, dtype=float)
        if self.K.shape != (model.n_vertices, 2, 6):
            raise ConfigError(f"AsRunLQR: gains must have shape ({model.n_vertices}, 2, 6), "
                              f"got {self.K.shape}")
        self.model = model
        self.vehicle = vehicle
        self.settings = settings
        self.Td = float(Td)
        self.bandwidth = float(bandwidth)
        box = model.premise_box
        self._lower = np.array(box.lower, dtype=float)
        self._upper = np.array(box.upper, dtype=float)
        self._bits = np.array(box.vertex_bits, dtype=bool)
        self.B5 = np.zeros((5, 2))
        self.B5[3, 0] = self.B5[4, 1] = self.Td * self.bandwidth
        f_lo, f_hi = settings.force_limits(vehicle)
        self._lo = (f_lo, -settings.delta_max)
        self._hi = (f_hi, settings.delta_max)
        self.reset()

    @property
    def dt(self) -> float:
        """Sample time T_d [s]."""
        return self.Td

    def reset(self) -> None:
        """Filter states to their start values at the next step, integrator cleared."""
        self._F1 = 0.0
        self._sigma = 0.0
        self._zeta = 0.0
        self._F_app = 0.0
        self._started = False
        self._applied = np.zeros(2)

    @property
    def state(self) -> tuple[float, float, float, float]:
        """(F₁ [N], σ₁ [rad], ζ [rad], F_app [N]): the law's state after the last step."""
        return self._F1, self._sigma, self._zeta, self._F_app

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """The last plant input [F_xR, δ]."""
        return self._applied.copy()

    def gains(self, z: tuple[float, float, float]) -> NDArray[np.float64]:
        """K (2, 6) = Σ μ_i(z) K_i at the scheduling point z = (δ, v, α) (already shifted)."""
        mu = as_run_memberships(z, self._lower, self._upper, self._bits,
                                extrapolate=self.settings.extrapolate_memberships)
        return np.tensordot(mu, self.K, axes=(0, 0))

    def model5(self, delta: float, v: float) -> NDArray[np.float64]:
        """Euler A₅ (5, 5) = I + T_d A₅,c of the plant + filter at (δ, max(v, V_MODEL_FLOOR))."""
        A, B = continuous_matrices(max(v, V_MODEL_FLOOR), delta, self.vehicle)
        Ac = np.zeros((5, 5))
        Ac[:3, :3], Ac[:3, 3:] = A, B
        Ac[3, 3] = Ac[4, 4] = -self.bandwidth
        return np.eye(5) + self.Td * Ac

    def _clip(self, i: int, value: float) -> float:
        return min(max(value, self._lo[i]), self._hi[i])

    def _start(self, v: float, al: float, r: NDArray[np.float64]) -> None:
        st = self.settings
        if st.initial_filter_state is not None:
            self._F1, self._sigma = (float(c) for c in st.initial_filter_state)
        else:  # bumpless: the nominal steady state of r at δ = 0
            K, A5 = self.gains((0.0, v + st.scheduling_speed_shift, al)), self.model5(0.0, v)
            Nbar = as_run_reference_gain(A5, self.B5, K)
            xss = np.linalg.solve(np.eye(5) - A5 - self.B5 @ K[:, :5], self.B5 @ (Nbar @ r))
            self._F1 = self._clip(0, float(xss[3]))
            self._sigma = self._clip(1, float(xss[4])) + st.steering_bias_rad
        self._F_app = self._clip(0, self._F1)
        self._zeta = 0.0
        self._started = True

    def step(self, estimate: Any, v_ref: float, omega_ref: float) -> InnerCommand:
        """One inner step from the state (``.x`` = [v, α, ω]: the true state in the published run)
        and the outer references; returns the plant input for the next T_d."""
        v, al, om = (float(c) for c in estimate.x)
        if not (math.isfinite(v) and math.isfinite(al) and math.isfinite(om)):
            return InnerCommand(float(self._applied[0]), float(self._applied[1]), True, 0.0)
        st = self.settings
        r = np.array([float(v_ref), float(omega_ref)])
        if not self._started:
            self._start(v, al, r)
        bias = st.steering_bias_rad
        delta_s = self._sigma - bias
        K, A5 = self.gains((delta_s, v + st.scheduling_speed_shift, al)), self.model5(delta_s, v)
        Nbar = as_run_reference_gain(A5, self.B5, K)
        x = np.array([v, al, om, self._F_app, self._sigma, self._zeta])
        u = Nbar @ r + K @ x
        a = self.Td * self.bandwidth
        self._F1 += a * (float(u[0]) - self._F1)
        self._sigma += a * (float(u[1]) - self._sigma)
        F_add = self.vehicle.mass * (v_ref - v) / st.speed_time_constant if st.speed_feedback else 0.0
        comp = 0.0
        if st.friction_compensation:
            F_hat = float(estimate.F_fr if st.friction_estimate == FrictionEstimate.WINDOW
                          else estimate.F_fr_raw)
            comp = F_hat if math.isfinite(F_hat) else 0.0
        out0, out1 = self._F1 + F_add + comp, self._sigma - bias
        o0, o1 = self._clip(0, out0), self._clip(1, out1)
        self._F_app = self._clip(0, self._F1)
        self._zeta += self.Td * (omega_ref - om)  # no anti-windup
        self._applied = np.array([o0, o1])
        return InnerCommand(o0, o1, o0 != out0 or o1 != out1, comp)
