"""Inner loop: gain-scheduled TS-LQR on the Apkarian-augmented model with friction compensation
(paper Sec. 3.2, Sec. 4; SPEC §6, §8).

Law, every T_d, with ϑ = (δ_f, v̂, α̂) clipped into the box::

    (α_eq, F_eq, δ_eq) = equilibrium of the nominal model at (v_ref, ω_ref)      (feed-forward)
    F_ff = M (a_ref + (v_ref − v̂)/τ)             (planned acceleration + speed feed-forward)
    x̃ = [v̂ − v_ref, α̂ − α_eq, ω̂ − ω_ref, F_f − F_eq, δ_f − δ_eq, ζ]
    u_f = [F_eq, δ_eq] + K(ϑ) x̃,     K(ϑ) = Σ μ_i(ϑ) K_i
    f⁺ = e^{−λT_d} f + (1 − e^{−λT_d}) u_f     (the Apkarian input filter, the plant input)
    ζ⁺ = ζ + T_d (ω_ref − ω̂)                   (yaw-rate integral; frozen while saturated)
    F_xR = F_f + F_ff + F̂_fr,   δ = δ_f         (feed-forward, friction compensation, saturations)

At a constant reference on the nominal model the equilibrium makes x̃ = 0 a fixed point, so v and
ω are tracked without steady-state error; the integrator removes what the model misses (tyre
nonlinearity) in ω, and the compensation F̂_fr removes the unknown road resistance in v.
Anti-windup: the filter states are clamped to the saturation limits and ζ stops integrating
while an input saturates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import LQRSettings, VehicleParams
from tsmpc.models.dynamic import DynamicTS, continuous_matrices

__all__ = ["TSLQR", "InnerCommand", "equilibrium"]


@dataclass(frozen=True)
class InnerCommand:
    """Plant input for the next T_d: rear force [N] and steering [rad] (after saturation)."""

    F_xR: float
    delta: float
    saturated: bool
    F_comp: float  #: the friction compensation included in F_xR [N]


def equilibrium(v: float, omega: float, p: VehicleParams, iters: int = 4) -> tuple[float, float, float]:
    """(α_eq, F_eq, δ_eq) with ẋ = A(v, δ)x + B(v, δ)u = 0 at x = (v, α, ω) (nominal model, no F_fr).

    The α̇ and ω̇ rows are linear in (α, δ) for fixed matrix entries; the δ inside sin/cos is
    updated by fixed-point iteration (it converges in a few steps: the dependence is weak).
    """
    v = max(v, 0.5)
    delta = (p.a + p.b) * omega / v  # kinematic guess
    alpha = 0.0
    for _ in range(iters):
        A, B = continuous_matrices(v, delta, p)
        # rows 2–3: [A22 B22; A32 B32] [α; δ] = −[A23; A33] ω
        m = np.array([[A[1, 1], B[1, 1]], [A[2, 1], B[2, 1]]])
        rhs = -np.array([A[1, 2], A[2, 2]]) * omega
        alpha, delta = np.linalg.solve(m, rhs)
    A, B = continuous_matrices(v, delta, p)
    F = -(A[0, 0] * v + A[0, 1] * alpha + A[0, 2] * omega + B[0, 1] * delta) / B[0, 0]
    return float(alpha), float(F), float(delta)


class TSLQR:
    """Gain-scheduled LQR with Apkarian filter, yaw-rate integrator and friction compensation.

    Args:
        gains: (8, 2, 6) vertex gains of the dynamic design (u = K x, physical units).
        model: dynamic TS model (its premise box and memberships schedule the gains).
        vehicle: vehicle parameters (equilibrium).
        settings: saturations, compensation switch.
        Td: sample time [s].
        bandwidth: Apkarian filter λ [rad/s] (must match the design).
    """

    def __init__(
        self, gains: NDArray[np.float64], model: DynamicTS, vehicle: VehicleParams, settings: LQRSettings,
        Td: float, bandwidth: float = 10.0,
    ) -> None:
        self.K = np.asarray(gains, dtype=float)
        if self.K.shape != (model.n_vertices, 2, 6):
            raise ValueError(f"TSLQR: gains must have shape ({model.n_vertices}, 2, 6), got {self.K.shape}")
        self.model = model
        self.vehicle = vehicle
        self.settings = settings
        self.Td = float(Td)
        self._a = math.exp(-bandwidth * self.Td)
        self._lo = np.array([settings.force_min, -settings.delta_max])
        self._hi = np.array([settings.force_max, settings.delta_max])
        # The step runs every millisecond on 2-vectors: plain floats beat numpy's per-call cost,
        # so the premise box, vertex bits and gains are unpacked once here.
        box = model.premise_box
        self._zlo = tuple(float(v) for v in box.lower)
        self._zhi = tuple(float(v) for v in box.upper)
        self._bits = tuple(tuple(bool(b) for b in row) for row in box.vertex_bits)
        self._K2 = self.K.reshape(-1, 6).copy()  # row 2i+j = gain row j of vertex i
        self.reset()

    def reset(self) -> None:
        """Filter states at rest, integrator cleared."""
        self._f = np.zeros(2)
        self._zeta = 0.0
        self._applied = np.zeros(2)
        self._eq_key: tuple[float, float] | None = None
        self._eq = (0.0, 0.0, 0.0)
        self._started = False

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """The last plant input [F_xR, δ] (what the MHE must see)."""
        return self._applied.copy()

    def step(self, estimate: Any, v_ref: float, omega_ref: float, a_ref: float = 0.0) -> InnerCommand:
        """One inner step from the estimate (``.x`` = [v̂, α̂, ω̂], ``.F_fr``) and the outer-loop
        references; returns the plant input for the next T_d.

        ``a_ref`` [m/s²] is the planned acceleration of the outer loop (its next move minus the
        current one over T_c): the force feed-forward ``M a_ref`` is added to the equilibrium
        force, so speed ramps do not have to be tracked by feedback alone (the paper's weights
        penalise filter-state deviations hard, which makes pure feedback slow in v)."""
        v, al, om = (float(c) for c in estimate.x)
        if not (math.isfinite(v) and math.isfinite(al) and math.isfinite(om)):
            # Never command from a corrupted estimate: hold the last input.
            return InnerCommand(float(self._applied[0]), float(self._applied[1]), True, 0.0)
        key = (round(v_ref, 9), round(omega_ref, 9))
        if key != self._eq_key:  # the references change every T_c only
            self._eq = equilibrium(v_ref, omega_ref, self.vehicle)
            self._eq_key = key
        a_eq, F_eq, d_eq = self._eq
        Fmin, dmin = float(self._lo[0]), float(self._lo[1])
        Fmax, dmax = float(self._hi[0]), float(self._hi[1])
        # Speed feed-forward: the outer loop's model assumes v follows v_ref within T_c, but the
        # paper's weights (filter-state deviations cost 0.1/N²) make the LQR's own speed loop slow
        # (≈ 9 s); the planned acceleration plus a first-order approach to v_ref (time constant
        # τ, well below the 0.1 s filter) supplies the force the cascade expects.
        a_ff = (a_ref if math.isfinite(a_ref) else 0.0) + (v_ref - v) / self.settings.speed_time_constant
        F_ff = self.vehicle.mass * a_ff  # applied directly: the filter is the LQR's, not the feed-forward's
        if not self._started:  # bumpless start: the filter begins at the equilibrium input
            self._f = np.array([min(max(F_eq, Fmin), Fmax), min(max(d_eq, dmin), dmax)])
            self._started = True
        f0, f1 = float(self._f[0]), float(self._f[1])
        xt = np.array([v - v_ref, al - a_eq, om - omega_ref, f0 - F_eq, f1 - d_eq, self._zeta])
        # K(ϑ) x̃ = Σ μ_i(ϑ) K_i x̃: all vertex products in one (16, 6) @ (6,) product, then blended.
        Kx = (self._K2 @ xt).tolist()
        u0, u1 = F_eq, d_eq
        for i, m in enumerate(self._memberships(f1, v, al)):
            u0 += m * Kx[2 * i]
            u1 += m * Kx[2 * i + 1]
        u0, u1 = min(max(u0, Fmin), Fmax), min(max(u1, dmin), dmax)
        # The plant receives the filter state (held over T_d); the filter then moves toward u_f.
        comp = 0.0
        if self.settings.friction_compensation:
            F_hat = float(estimate.F_fr)
            comp = F_hat if math.isfinite(F_hat) else 0.0
        out0 = f0 + F_ff + comp
        o0, o1 = min(max(out0, Fmin), Fmax), min(max(f1, dmin), dmax)
        saturated = o0 != out0 or o1 != f1
        a = self._a
        self._f = np.array([min(max(a * f0 + (1.0 - a) * u0, Fmin), Fmax),
                            min(max(a * f1 + (1.0 - a) * u1, dmin), dmax)])
        if not saturated:
            self._zeta += self.Td * (omega_ref - om)
        self._applied = np.array([o0, o1])
        return InnerCommand(o0, o1, saturated, comp)

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
