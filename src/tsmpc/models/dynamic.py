"""Dynamic control-oriented model, its TS form and the Apkarian augmentation (paper eq.
"dynamic model"; the paper's dynamic model; the paper's LMI designs).

State ``x_d = [v, α, ω]``, input ``u_d = [F_xR, δ]``, disturbance ``F_fr = (μ(road) − μ_o) M g``.
Continuous LPV form ``ẋ = A(ϑ) x + B(ϑ) u + E F_fr`` derived from the plant model with
linear tyres and small body-slip angles (sin α ≈ α where it multiplies a force, cos α ≈ 1)::

    A11 = −μ_o g / v − ½ρC_dA_r v / M    A12 = C_x sin δ / M          A13 = C_x a sin δ / (M v)
    A21 = 0                              A22 = −C_x (1 + cos δ)/(M v) A23 = C_x (b − a cos δ)/(M v²) − 1
    A31 = 0                              A32 = C_x (b − a cos δ) / I  A33 = −C_x (a² cos δ + b²)/(I v)
    B11 = 1/M   B12 = −C_x sin δ / M     B21 = 0   B22 = C_x cos δ /(M v)   B31 = 0   B32 = C_x a cos δ / I
    E = [−1/M, 0, 0]ᵀ

``A11 v`` carries the nominal rolling resistance −μ_o g and the drag, so the model has no affine
term. The signs of A13 and B12 are those that follow from the plant (tested against it). The
paper's discrete model is Euler at ``T_d``: ``A_d = I + T_d A``, ``B_d = T_d B``, ``E_d = T_d E``.
:func:`discretize` also offers the exact zero-order-hold discretisation, which stays stable at low
speed where Euler does not (|1 + T_d A22| > 1 below v ≈ 0.37 m/s at T_d = 10 ms).

Scheduling ϑ = (δ, v, α) in the dynamic scheduling box; the matrices do not depend on α (it is a premise
of the paper's 8-vertex polytope all the same). Speeds below the box are clipped before the
matrices are evaluated (:meth:`DynamicTS.clip`), which is the documented low-speed behaviour.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import DynamicBox, VehicleParams
from tsmpc.errors import ConfigError
from tsmpc.models.polytope import SchedulingBox

__all__ = [
    "Discretization",
    "DynamicTS",
    "augment_apkarian",
    "continuous_matrices",
    "discretize",
    "disturbance_matrix",
    "equilibrium",
    "steady_states",
]


class Discretization(StrEnum):
    """Discretisation of a continuous LTI/LPV model at a sample time."""

    EULER = "euler"  #: the paper's: A_d = I + T A, B_d = T B
    ZOH = "zoh"  #: exact with inputs held: A_d = e^{AT}, B_d = ∫ e^{As} ds B


def continuous_matrices(
    v: ArrayLike, delta: ArrayLike, p: VehicleParams
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Continuous A (..., 3, 3) and B (..., 3, 2) at speed v > 0 and steering δ."""
    v, delta = np.broadcast_arrays(np.asarray(v, float), np.asarray(delta, float))
    sd, cd = np.sin(delta), np.cos(delta)
    # Linear tyres F_yF = C_f (δ − α − aω/v), F_yR = C_r (bω/v − α) in the single-track
    # equations, small slip (paper eq. "dynamic model"; C_f = C_r = C in the paper).
    M, I, Cf, Cr, a, b = p.mass, p.inertia, p.C_f, p.C_r, p.a, p.b
    A = np.zeros((*v.shape, 3, 3))
    B = np.zeros((*v.shape, 3, 2))
    A[..., 0, 0] = -p.mu_nominal * p.g / v - p.drag_factor * v / M
    A[..., 0, 1] = Cf * sd / M
    A[..., 0, 2] = Cf * a * sd / (M * v)
    A[..., 1, 1] = -(Cr + Cf * cd) / (M * v)
    A[..., 1, 2] = (Cr * b - Cf * a * cd) / (M * v**2) - 1.0
    A[..., 2, 1] = (Cr * b - Cf * a * cd) / I
    A[..., 2, 2] = -(Cf * a**2 * cd + Cr * b**2) / (I * v)
    B[..., 0, 0] = 1.0 / M
    B[..., 0, 1] = -Cf * sd / M
    B[..., 1, 1] = Cf * cd / (M * v)
    B[..., 2, 1] = Cf * a * cd / I
    return A, B


def disturbance_matrix(p: VehicleParams) -> NDArray[np.float64]:
    """Continuous E (3, 1) = [−1/M, 0, 0]ᵀ of the friction force F_fr."""
    return np.array([[-1.0 / p.mass], [0.0], [0.0]])


def discretize(
    A: ArrayLike, B: ArrayLike, T: float, method: Discretization = Discretization.EULER
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Discretise (A (..., n, n), B (..., n, m)) at sample time T; batched."""
    A = np.asarray(A, np.float64)
    B = np.asarray(B, np.float64)
    n, m = A.shape[-1], B.shape[-1]
    if method == Discretization.EULER:
        return np.eye(n) + T * A, T * B
    if method != Discretization.ZOH:
        raise ConfigError(f"unknown discretisation {method!r}; allowed: euler, zoh")
    big = np.zeros((*A.shape[:-2], n + m, n + m))
    big[..., :n, :n] = A * T
    big[..., :n, n:] = B * T
    E = np.asarray(scipy.linalg.expm(big), dtype=np.float64)  # (float64 already: no copy)
    return E[..., :n, :n], E[..., :n, n:]


def augment_apkarian(
    A: ArrayLike, B: ArrayLike, bandwidth: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Apkarian augmentation with a yaw-rate integrator (the paper's LMI designs), continuous time.

    Augmented state ``[v, α, ω, F_f, δ_f, ζ]``: the plant inputs become first-order filter
    states ``ḟ = λ(u − f)`` so the new input matrix is constant, and ``ζ̇ = ω_ref − ω`` (the
    reference enters as an exogenous signal, not through the returned matrices).

    Returns (A_a (..., 6, 6), B_a (6, 2)).
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    lam = float(bandwidth)
    Aa = np.zeros((*A.shape[:-2], 6, 6))
    Aa[..., :3, :3] = A
    Aa[..., :3, 3:5] = B
    Aa[..., 3, 3] = Aa[..., 4, 4] = -lam
    Aa[..., 5, 2] = -1.0
    Ba = np.zeros((6, 2))
    Ba[3, 0] = Ba[4, 1] = lam
    return Aa, Ba


class DynamicTS:
    """TS form of the dynamic model over ϑ = (δ, v, α): 8 vertex models at sample time Td.

    Args:
        box: scheduling box.
        params: vehicle parameters.
        Td: sample time [s].
        method: discretisation of the vertex and online models.
    """

    def __init__(
        self,
        box: DynamicBox,
        params: VehicleParams,
        Td: float,
        method: Discretization = Discretization.EULER,
    ) -> None:
        self.box = box
        self.params = params
        self.Td = float(Td)
        self.method = Discretization(method)
        self.premise_box = SchedulingBox(
            ("delta", "v", "alpha"),
            (box.delta[0], box.v[0], box.alpha[0]),
            (box.delta[1], box.v[1], box.alpha[1]),
        )
        z = self.premise_box.vertices()
        self.A_vertices, self.B_vertices = self.matrices(z)  # (8, 3, 3), (8, 3, 2)
        #: Euler E_d (3, 1) = [−T_d/M, 0, 0]ᵀ; see :meth:`disturbance` for ZOH.
        self.E = self.Td * disturbance_matrix(params)

    @property
    def n_vertices(self) -> int:
        """8."""
        return self.premise_box.n_vertices

    def clip(self, z: ArrayLike) -> tuple[NDArray[np.float64], int]:
        """Clip premises (..., 3) = (δ, v, α) into the box; returns (clipped, number out)."""
        return self.premise_box.clip(z)

    def memberships(self, z: ArrayLike) -> NDArray[np.float64]:
        """μ (..., 8) of premises z (..., 3) (clipped into the box)."""
        return self.premise_box.memberships(z)

    def matrices(self, z: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Discrete (A_d, B_d) evaluated directly at premises z (..., 3) clipped into the box."""
        zc = np.clip(np.asarray(z, float), self.premise_box.lower, self.premise_box.upper)
        Ac, Bc = continuous_matrices(zc[..., 1], zc[..., 0], self.params)
        return discretize(Ac, Bc, self.Td, self.method)

    def disturbance(self, z: ArrayLike) -> NDArray[np.float64]:
        """Discrete E_d (..., 3, 1) at premises z. The continuous E equals −B[:, :1] exactly
        (F_fr enters like a negative drive force), so E_d = −B_d[:, :1] for both methods."""
        return -self.matrices(z)[1][..., :, :1]

    def ts_matrices(self, z: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """TS interpolation (Σ μ_i A_i, Σ μ_i B_i) at premises z (..., 3)."""
        mu = self.memberships(z)
        pb = self.premise_box
        return pb.blend(mu, self.A_vertices), pb.blend(mu, self.B_vertices)


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


def steady_states(v: ArrayLike, omega: ArrayLike, p: VehicleParams,
                  iters: int = 4) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(α_eq, δ_eq) of :func:`equilibrium` at many (v, ω) points at once (the same fixed-point
    iteration, the 2×2 systems solved together): a reference's ≈ 1000 grid points in
    milliseconds instead of a third of a second (:func:`tsmpc.envelope.reference_ranges`)."""
    vv: NDArray[np.float64] = np.maximum(np.asarray(v, dtype=np.float64), 0.5)
    w: NDArray[np.float64] = np.asarray(omega, dtype=np.float64)
    sol: NDArray[np.float64] = np.stack([np.zeros_like(vv), (p.a + p.b) * w / vv], axis=-1)
    for _ in range(iters):  # sol = [α, δ] per point
        A, B = continuous_matrices(vv, sol[:, 1], p)
        m = np.stack([np.stack([A[:, 1, 1], B[:, 1, 1]], axis=-1),
                      np.stack([A[:, 2, 1], B[:, 2, 1]], axis=-1)], axis=-2)
        rhs = -np.stack([A[:, 1, 2], A[:, 2, 2]], axis=-1) * w[:, None]
        sol = np.asarray(np.linalg.solve(m, rhs[..., None])[..., 0], dtype=np.float64)
    return sol[:, 0].copy(), sol[:, 1].copy()
