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
        self._prepare()
        self.reset()

    def _prepare(self) -> None:
        """Per-step constants of :meth:`step` (plain floats; the vehicle is fixed at construction).

        The step is ~100 scalar operations; numpy's per-call overhead on 2- to 5-element arrays
        dominated it (≈ 110 µs per step in a hot loop, ≈ 10 µs on floats), hence plain floats and one
        small dot."""
        if self._bits.shape[1] != 3:
            raise ConfigError(f"AsRunLQR: the premise box must have 3 variables (δ, v, α), "
                              f"got {self._bits.shape[1]}")
        self._box = tuple((float(lo), float(hi) - float(lo)) for lo, hi in zip(self._lower, self._upper,
                                                                               strict=True))
        # μ_i = Π_j w_j with w_j = η_j (upper bound) or 1 − η_j: indices into (1−η₀, η₀, 1−η₁, …)
        self._mu_idx = tuple(tuple(2 * j + int(b) for j, b in enumerate(row)) for row in self._bits)
        self._K_flat = np.ascontiguousarray(self.K.reshape(self.K.shape[0], 12))
        p = self.vehicle
        self._veh = (p.mass, p.inertia, p.C_f, p.C_r, p.a, p.b, p.mu_nominal * p.g, p.drag_factor)

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
        self._applied = (0.0, 0.0)

    @property
    def state(self) -> tuple[float, float, float, float]:
        """(F₁ [N], σ₁ [rad], ζ [rad], F_app [N]): the law's state after the last step."""
        return self._F1, self._sigma, self._zeta, self._F_app

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """The last plant input [F_xR, δ]."""
        return np.array(self._applied)

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
        and the outer references; returns the plant input for the next T_d.

        The same computation as :meth:`gains`, :meth:`model5` and :func:`as_run_reference_gain`
        (tested to rounding), on plain floats with N̄ in closed form (:func:`_reference_gain`)."""
        v, al, om = np.asarray(estimate.x, dtype=float).tolist()
        if not (math.isfinite(v) and math.isfinite(al) and math.isfinite(om)):
            return InnerCommand(self._applied[0], self._applied[1], True, 0.0)
        st = self.settings
        v_ref, omega_ref = float(v_ref), float(omega_ref)
        if not self._started:
            self._start(v, al, np.array([v_ref, omega_ref]))
        bias = st.steering_bias_rad
        sigma = self._sigma
        delta_s = sigma - bias
        # memberships (as_run_memberships) and K = Σ μ_i K_i
        (lo0, w0), (lo1, w1), (lo2, w2) = self._box
        e0, e1, e2 = (delta_s - lo0) / w0, (v + st.scheduling_speed_shift - lo1) / w1, (al - lo2) / w2
        if not st.extrapolate_memberships:
            e0, e1, e2 = min(max(e0, 0.0), 1.0), min(max(e1, 0.0), 1.0), min(max(e2, 0.0), 1.0)
        eta = (1.0 - e0, e0, 1.0 - e1, e1, 1.0 - e2, e2)
        mu = [eta[i] * eta[j] * eta[k] for i, j, k in self._mu_idx]
        K = np.dot(mu, self._K_flat).tolist()  # K[0:6] the force row, K[6:12] the steering row
        a = self.Td * self.bandwidth
        n00, n01, n10, n11 = _reference_gain(self._veh, self.Td, self.bandwidth, delta_s,
                                             max(v, V_MODEL_FLOOR), K)
        F_app, zeta = self._F_app, self._zeta
        u0 = (n00 * v_ref + n01 * omega_ref) + (K[0] * v + K[1] * al + K[2] * om + K[3] * F_app
                                                + K[4] * sigma + K[5] * zeta)
        u1 = (n10 * v_ref + n11 * omega_ref) + (K[6] * v + K[7] * al + K[8] * om + K[9] * F_app
                                                + K[10] * sigma + K[11] * zeta)
        self._F1 += a * (u0 - self._F1)
        self._sigma += a * (u1 - self._sigma)
        F_add = self.vehicle.mass * (v_ref - v) / st.speed_time_constant if st.speed_feedback else 0.0
        comp = 0.0
        if st.friction_compensation:
            F_hat = float(estimate.F_fr if st.friction_estimate == FrictionEstimate.WINDOW
                          else estimate.F_fr_raw)
            comp = F_hat if math.isfinite(F_hat) else 0.0
        out0, out1 = self._F1 + F_add + comp, self._sigma - bias
        (f_lo, d_lo), (f_hi, d_hi) = self._lo, self._hi
        o0, o1 = min(max(out0, f_lo), f_hi), min(max(out1, d_lo), d_hi)
        self._F_app = min(max(self._F1, f_lo), f_hi)
        self._zeta += self.Td * (omega_ref - om)  # no anti-windup
        self._applied = (o0, o1)
        return InnerCommand(o0, o1, o0 != out0 or o1 != out1, comp)


def _reference_gain(veh: tuple[float, ...], Td: float, lam: float, delta: float, v: float,
                    K: list[float]) -> tuple[float, float, float, float]:
    """N̄ (row-major 2 × 2) of :func:`as_run_reference_gain` at the model of :meth:`AsRunLQR.model5`
    (v already floored) and the blended gains K (12 floats, row-major 2 × 6), in closed form.

    M = I − A₅ − B₅K₁:₅ is formed entry by entry as numpy forms it (the 1 − (1 + T_d a) of the
    diagonal included). With M = [[M₁₁, M₁₂], [M₂₁, M₂₂]] (3 + 2) and B₅ = [0; a I] (a = T_d λ),
    X = M⁻¹B₅ is X₂ = a S⁻¹, X₁ = −Y X₂ with Y = M₁₁⁻¹M₁₂ and S = M₂₂ − M₂₁Y, so
    N̄ = (C X)⁻¹ = −S Y_C⁻¹ / a, Y_C = Y's rows v and ω. The model's structure (A's first column and
    B's first column are zero below the v row) makes M₁₁ block upper triangular, Y's first column
    (Y₀₀, 0, 0) and Y_C upper triangular: a 2 × 2 solve and a few divisions."""
    M, I, Cf, Cr, a_, b_, mug, drag = veh
    sd, cd = math.sin(delta), math.cos(delta)
    # continuous_matrices, the same expressions
    A00 = -mug / v - drag * v / M
    A01 = Cf * sd / M
    A02 = Cf * a_ * sd / (M * v)
    A11 = -(Cr + Cf * cd) / (M * v)
    A12 = (Cr * b_ - Cf * a_ * cd) / (M * v**2) - 1.0
    A21 = (Cr * b_ - Cf * a_ * cd) / I
    A22 = -(Cf * a_**2 * cd + Cr * b_**2) / (I * v)
    # M₁₁ (its (1,0), (2,0) entries are 0) and M₁₂ = −T_d B (its (1,0), (2,0) entries are 0)
    m00, m01, m02 = 1.0 - (1.0 + Td * A00), -(Td * A01), -(Td * A02)
    m11, m12 = 1.0 - (1.0 + Td * A11), -(Td * A12)
    m21, m22 = -(Td * A21), 1.0 - (1.0 + Td * A22)
    p00, p01 = -(Td * (1.0 / M)), -(Td * (-Cf * sd / M))
    p11, p21 = -(Td * (Cf * cd / (M * v))), -(Td * (Cf * a_ * cd / I))
    # Y = M₁₁⁻¹ M₁₂: column 0 is (p00/m00, 0, 0); column 1 from the ω-α 2 × 2 block
    det = m11 * m22 - m12 * m21
    y1 = (p11 * m22 - m12 * p21) / det
    y2 = (m11 * p21 - m21 * p11) / det
    y0 = (p01 - m01 * y1 - m02 * y2) / m00
    Y00 = p00 / m00
    # S = M₂₂ − M₂₁ Y with M₂₁ = −a K[:, :3], M₂₂ = (1 − (1 − T_d λ)) I − a K[:, 3:5]
    a = Td * lam
    d = 1.0 - (1.0 + Td * -lam)
    s00 = (d - a * K[3]) + (a * K[0]) * Y00
    s01 = -(a * K[4]) + ((a * K[0]) * y0 + (a * K[1]) * y1 + (a * K[2]) * y2)
    s10 = -(a * K[9]) + (a * K[6]) * Y00
    s11 = (d - a * K[10]) + ((a * K[6]) * y0 + (a * K[7]) * y1 + (a * K[8]) * y2)
    # N̄ = −S [[1/Y00, −y0/(Y00 y2)], [0, 1/y2]] / a
    q0, q1 = s00 / Y00, s10 / Y00
    ay2 = a * y2
    return -q0 / a, -(s01 - q0 * y0) / ay2, -q1 / a, -(s11 - q1 * y0) / ay2
