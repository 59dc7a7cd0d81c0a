"""Why the paper's inner loop follows (or not) the speed profile: the speed mode of the TS-LQR
closed loop, per vertex of the dynamic design (README, "Why the paper's inner loop lags").

The dynamic model writes the constant rolling resistance ``μ_o M g`` as ``−(μ_o g / v)·v`` inside
``A11(ϑ)`` (the model has no affine term). At a frozen scheduling point that looks like a viscous
damping of ``μ_o M g / v`` N per m/s (≈ 335 N s/m at 10 m/s), which the real car does not have
(its resistance does not grow with v; only the drag does, ``2 d v``). So the speed mode depends on
where the reference feed-forward is scheduled:

* ``design`` — the LMI design model (LPV, frozen ϑ): what the design "believes";
* ``reference_scheduled`` — the feed-forward evaluated at the reference (the exact equilibrium
  ``u_eq(r) + K(x − x_eq(r))``): on the real resistance only the LQR's own speed gain acts;
* ``static_gain`` — the classical ``N̄(ϑ) r + K x`` with ϑ from the *measured* speed (the law of
  :class:`~tsmpc.control.ts_lqr.TSLQR`): ``∂(N̄(v̂) r)/∂v̂`` re-creates the design model's damping
  as a control action;
* ``with_speed_feedback`` — ``static_gain`` plus the speed-error feedback ``M (v_ref − v̂)/τ``.

Each is the time the linearised closed loop (plant with constant resistance, Apkarian filter,
integrator) takes to cover 63 % of a small v_ref step on a straight (δ = 0, where the speed
channel is the only one excited), with the vertex's own gain K_i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from tsmpc.config import VehicleParams
from tsmpc.models.dynamic import augment_apkarian, continuous_matrices

__all__ = ["SpeedMode", "speed_modes", "step_time_constant"]

LAWS = ("design", "reference_scheduled", "static_gain", "with_speed_feedback")


@dataclass(frozen=True)
class SpeedMode:
    """Speed-mode time constants [s] of one vertex (see the module docstring)."""

    vertex: int
    delta: float
    v: float
    alpha: float
    design: float
    reference_scheduled: float
    static_gain: float
    with_speed_feedback: float
    design_poles_tau: tuple[float, ...]  #: 1/|Re s| of every design closed-loop pole [s]


def _reference_gain(
    A5: NDArray[np.float64], B5: NDArray[np.float64], K: NDArray[np.float64]
) -> NDArray[np.float64]:
    X = np.linalg.solve(A5 + B5 @ K[:, :5], B5)
    return -np.linalg.inv(X[[0, 2], :]).astype(np.float64, copy=False)


def _nbar_r(
    v: float, v_ref: float, K: NDArray[np.float64], p: VehicleParams, lam: float
) -> NDArray[np.float64]:
    """N̄ scheduled at speed v (δ = 0) times r = (v_ref, 0)."""
    A, B = continuous_matrices(v, 0.0, p)
    Aa, Ba = augment_apkarian(A, B, lam)
    return _reference_gain(Aa[:5, :5], Ba[:5], K) @ np.array([v_ref, 0.0])


def step_time_constant(A: NDArray[np.float64], b: NDArray[np.float64], t_max: float = 60.0) -> float:
    """Time for v = x[0] of ``ẋ = A x + b`` (from x = 0) to reach 63 % of its final value [s]."""
    x_inf = -np.linalg.solve(A, b)
    dt = 0.005
    Phi = scipy.linalg.expm(A * dt)
    g = np.linalg.solve(A, (Phi - np.eye(A.shape[0])) @ b)  # exact ZOH of the constant input
    x = np.zeros(A.shape[0])
    target = 0.632 * x_inf[0]
    for k in range(1, round(t_max / dt) + 1):
        x = Phi @ x + g
        if (x[0] - target) * np.sign(target) >= 0.0:
            return k * dt
    return float("inf")


def speed_modes(
    K: NDArray[np.float64], vertices: NDArray[np.float64], vehicle: VehicleParams, bandwidth: float,
    speed_time_constant: float,
) -> list[SpeedMode]:
    """Speed-mode time constants of every vertex gain ``K[i]`` at the vertex speed (δ = 0)."""
    p = vehicle
    out = []
    for i, (delta_i, v0, alpha_i) in enumerate(np.asarray(vertices, float)):
        Ki = np.asarray(K[i], float)
        A, B = continuous_matrices(v0, 0.0, p)
        Aa, Ba = augment_apkarian(A, B, bandwidth)  # [v, α, ω, F_f, δ_f, ζ]
        lam_cl = np.linalg.eigvals(Aa + Ba @ Ki)
        poles_tau = tuple(sorted(float(1.0 / abs(s.real)) for s in lam_cl))
        r_col = Ba @ _reference_gain(Aa[:5, :5], Ba[:5], Ki)[:, 0]  # ∂ẋ/∂v_ref through N̄
        design = step_time_constant(Aa + Ba @ Ki, r_col)
        # Real resistance: ∂(−μ_o g − d v²/M)/∂v = −2 d v / M instead of A11(ϑ).
        At = Aa.copy()
        At[0, 0] = -2.0 * p.drag_factor * v0 / p.mass
        ref_sched = step_time_constant(At + Ba @ Ki, r_col)
        # N̄ scheduled at the measured speed: ∂(N̄(v̂) r)/∂v̂ at v̂ = v_ref = v0 (central difference).
        h = 1e-4 * v0
        dN = (_nbar_r(v0 + h, v0, Ki, p, bandwidth) - _nbar_r(v0 - h, v0, Ki, p, bandwidth)) / (2.0 * h)
        J = Ki.copy()
        J[:, 0] += dN
        static = step_time_constant(At + Ba @ J, r_col)
        Af = At + Ba @ J
        Af[0, 0] -= 1.0 / speed_time_constant  # M (v_ref − v)/τ enters v̇ directly
        r_fb = r_col.copy()
        r_fb[0] += 1.0 / speed_time_constant
        fb = step_time_constant(Af, r_fb)
        out.append(SpeedMode(i, float(delta_i), float(v0), float(alpha_i), design, ref_sched, static, fb,
                             poles_tau))
    return out
