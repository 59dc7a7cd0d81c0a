"""Dynamic TS-LMI-LQR on the Apkarian-augmented model (paper Sec. 3.2; SPEC §6).

Model: the continuous LPV model of :mod:`tsmpc.models.dynamic`, augmented with the input filter
``ḟ = λ(u − f)`` and the yaw-rate integrator ``ζ̇ = ω_ref − ω`` → state
``[v, α, ω, F_f, δ_f, ζ]`` with a constant input matrix, discretised exactly (ZOH) at ``T_d``.
Gains act on deviations from the equilibrium, ``ũ = K(ϑ) x̃``, ``K(ϑ) = Σ μ_i(ϑ) K_i``.

Formulation (why it differs from a textbook vertex LMI)
-------------------------------------------------------
1. *Scaling.* States span F_f ~ 10³ N to α ~ 10⁻² rad and the weights span 10⁻³…10⁵; the LMI is
   posed on ``x = T_x x_s``, ``u = T_u u_s`` with diagonal ``T_x, T_u`` chosen so the scaled
   states and inputs are O(1), and Q, R normalised by their largest scaled entry (the LQR optimum
   is invariant to a common scale of Q and R).
2. *Guaranteed cost with a cost-bound variable.* Common ``Y = P⁻¹``; per-vertex ``W_i``; minimise
   ``trace X`` with ``[[X, I], [I, Y]] ⪰ 0`` (so ``X ⪰ P``): a bounded objective that keeps
   the solver away from the unbounded direction log det Y would take with these weights.
3. *Interpolated gains at grid points.* A(ϑ) is not affine in the premises (1/v, 1/v², sin δ,
   cos δ), so the 8 vertex LMIs alone do not certify the interpolated loop between vertices (a
   dense-grid check of the vertex-only design fails by ≈ 0.5 %). We therefore impose the LMI at an
   enriched (δ, v) grid with the *exact* model there and the *interpolated* variable
   ``W(ϑ) = Σ μ_i(ϑ) W_i`` — linear in the W_i, so the problem stays an SDP and its online gain is
   exactly ``K(ϑ) = W(ϑ) Y⁻¹ = Σ μ_i K_i``. α does not enter the matrices, so the α vertices share
   their gains.
4. *Certificates.* Afterwards, numpy recomputes (a) each imposed LMI, and (b) on a dense grid of ϑ
   (``grid_points`` per axis, default 15³) the spectral radius of the exact closed loop and the
   Lyapunov decrease ``A_clᵀ P A_cl − P ≺ 0`` (relative margin reported). A failing certificate
   raises :class:`CertificateError`.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import DynamicBox, DynamicLMISettings, VehicleParams
from tsmpc.errors import SolverError
from tsmpc.models.dynamic import Discretization, augment_apkarian, continuous_matrices, discretize
from tsmpc.models.polytope import SchedulingBox
from tsmpc.synthesis.certificates import Certificate, check, neg_def_margin

__all__ = ["DynamicDesign", "augmented_models", "design_dynamic", "per_vertex_dare_gains"]

#: Diagonal state / input scaling of the SDP: x = T_x x_s, u = T_u u_s (units: m/s, rad, rad/s,
#: N, rad, rad → O(1) at the operating envelope).
STATE_SCALE = np.array([1.0, 0.01, 0.1, 1000.0, 0.1, 0.1])
INPUT_SCALE = np.array([1000.0, 0.1])
LMI_EPS = 1e-8
#: Enriched (δ, v) grid where the LMI is imposed: v is graded towards low speed (1/v terms).
GRID_DELTA = 5
GRID_V = 9


@dataclass(frozen=True)
class DynamicDesign:
    """Gain-scheduled inner-loop design (vertex order of :class:`~tsmpc.models.dynamic.DynamicTS`).

    ``K[i]`` (2 × 6) maps the augmented deviation ``[ṽ, α̃, ω̃, F̃_f, δ̃_f, ζ]`` to the filter
    input deviation ``[F̃_xR, δ̃]`` in physical units (u = K x).
    """

    K: NDArray[np.float64]  #: (8, 2, 6)
    P: NDArray[np.float64]  #: (6, 6) common Lyapunov matrix, physical units
    Td: float
    bandwidth: float
    certificates: tuple[Certificate, ...]
    grid_max_rho: float  #: largest closed-loop spectral radius on the dense check grid
    grid_max_decrease: float  #: largest eigenvalue of P^{-1} A_clᵀ P A_cl on the grid (< 1 ⇔ decrease)
    solve_time_s: float
    status: str
    formulation: str = "guaranteed-cost LMI, common P, interpolated W on a (δ, v) grid, ZOH"
    inputs_hash: str = ""


def augmented_models(
    z: NDArray[np.float64], vehicle: VehicleParams, Td: float, bandwidth: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """ZOH-discretised augmented (A (..., 6, 6), B (..., 6, 2)) at premises z (..., 3) = (δ, v, α)."""
    z = np.asarray(z, float)
    Ac, Bc = continuous_matrices(z[..., 1], z[..., 0], vehicle)
    Aa, Ba = augment_apkarian(Ac, Bc, bandwidth)
    return discretize(Aa, np.broadcast_to(Ba, (*Aa.shape[:-2], 6, 2)), Td, Discretization.ZOH)


def _premise_box(box: DynamicBox) -> SchedulingBox:
    return SchedulingBox(
        ("delta", "v", "alpha"),
        (box.delta[0], box.v[0], box.alpha[0]),
        (box.delta[1], box.v[1], box.alpha[1]),
    )


def _lmi_grid(box: DynamicBox) -> NDArray[np.float64]:
    d = np.linspace(box.delta[0], box.delta[1], GRID_DELTA)
    # Uniform in 1/v: the model's nonlinearity is in 1/v and 1/v².
    v = 1.0 / np.linspace(1.0 / box.v[0], 1.0 / box.v[1], GRID_V)
    D, V = np.meshgrid(d, v, indexing="ij")
    return np.stack([D.ravel(), V.ravel(), np.full(D.size, box.alpha[0])], axis=-1)


def check_grid(box: DynamicBox, n: int) -> NDArray[np.float64]:
    """Dense certificate grid: n points per axis over (δ, v, α)."""
    axes = [np.linspace(lo, hi, n) for lo, hi in (box.delta, box.v, box.alpha)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def per_vertex_dare_gains(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float
) -> NDArray[np.float64]:
    """Per-vertex discrete LQR gains (u = K x) with the same weights: the comparison baseline."""
    import scipy.linalg

    A, B = augmented_models(_premise_box(box).vertices(), vehicle, Td, settings.filter_bandwidth)
    Q, R = np.diag(settings.Q), np.diag(settings.R)
    K = []
    for Ai, Bi in zip(A, B, strict=True):
        X = scipy.linalg.solve_discrete_are(Ai, Bi, Q, R)
        K.append(-np.linalg.solve(R + Bi.T @ X @ Bi, Bi.T @ X @ Ai))
    return np.array(K)


def design_dynamic(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float,
    inputs_hash: str = "",
) -> DynamicDesign:
    """Solve the dynamic TS-LMI-LQR with cvxpy + Clarabel and certify it (see module docstring).

    Raises :class:`SolverError` if the SDP fails and :class:`CertificateError` if a recomputed
    certificate does not hold.
    """
    import cvxpy as cp

    t0 = time.perf_counter()
    lam = settings.filter_bandwidth
    pb = _premise_box(box)
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Txi = np.diag(1.0 / STATE_SCALE)
    Q = Tx @ np.diag(settings.Q) @ Tx
    R = Tu @ np.diag(settings.R) @ Tu
    s = 1.0 / max(Q.max(), R.max())
    Qh, Rh = np.sqrt(Q * s), np.sqrt(R * s)

    zg = _lmi_grid(box)
    mu = pb.memberships(zg)  # (g, 8)
    A, B = augmented_models(zg, vehicle, Td, lam)
    As = Txi @ A @ Tx
    Bs = Txi @ B @ Tu

    n, m = 6, 2
    Y = cp.Variable((n, n), symmetric=True)
    X = cp.Variable((n, n), symmetric=True)
    # α does not enter the model: one W per (δ, v) corner, shared by the two α vertices.
    W = {(lo_d, lo_v): cp.Variable((m, n)) for lo_d in (False, True) for lo_v in (False, True)}
    Wv = [W[(bool(b[0]), bool(b[1]))] for b in pb.vertex_bits]
    Zn, Znm = np.zeros((n, n)), np.zeros((n, m))
    cons = [cp.bmat([[X, np.eye(n)], [np.eye(n), Y]]) >> 0]
    for g in range(zg.shape[0]):
        Wg = sum(float(mu[g, i]) * Wv[i] for i in range(len(Wv)) if mu[g, i] > 0.0)
        AY = As[g] @ Y + Bs[g] @ Wg
        M = cp.bmat([
            [Y, AY.T, (Qh @ Y).T, (Rh @ Wg).T],
            [AY, Y, Zn, Znm],
            [Qh @ Y, Zn, np.eye(n), Znm],
            [Rh @ Wg, Znm.T, Znm.T, np.eye(m)],
        ])
        cons.append(0.5 * (M + M.T) >> LMI_EPS * np.eye(3 * n + m))
    prob = cp.Problem(cp.Minimize(cp.trace(X)), cons)
    try:
        with warnings.catch_warnings():  # the status is reported; certificates decide
            warnings.simplefilter('ignore', UserWarning)
            prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:  # pragma: no cover - depends on the solver build
        raise SolverError(f"dynamic TS-LMI-LQR at Td={Td}: Clarabel failed ({exc})") from exc
    if Y.value is None or prob.status not in ("optimal", "optimal_inaccurate"):
        raise SolverError(f"dynamic TS-LMI-LQR at Td={Td}: Clarabel returned {prob.status!r}")

    Ys = 0.5 * (Y.value + Y.value.T)
    Ps = np.linalg.inv(Ys)
    Ks = np.array([w.value @ Ps for w in Wv])  # scaled gains, (8, 2, 6)
    K = Tu @ Ks @ Txi  # physical: u = T_u K_s T_x⁻¹ x
    P = Txi @ Ps @ Txi
    P = 0.5 * (P + P.T)

    certs: list[Certificate] = [Certificate("Y positive definite", neg_def_margin(-Ys))]
    Kg = np.tensordot(mu, Ks, axes=(1, 0))
    Acl = As + Bs @ Kg
    ric = np.swapaxes(Acl, -1, -2) @ Ps @ Acl - Ps + s * Q + np.swapaxes(Kg, -1, -2) @ (s * R) @ Kg
    lmi = Ys @ ric @ Ys
    certs += [Certificate(f"guaranteed cost at δ={zg[g, 0]:.3f}, v={zg[g, 1]:.2f}", neg_def_margin(lmi[g]))
              for g in range(zg.shape[0])]
    rho, dec, cg = certify_grid(K, P, box, vehicle, Td, lam, settings.grid_points)
    certs += cg
    check(certs, f"dynamic design (Td={Td})")
    return DynamicDesign(K=K, P=P, Td=float(Td), bandwidth=lam, certificates=tuple(certs),
                         grid_max_rho=rho, grid_max_decrease=dec,
                         solve_time_s=time.perf_counter() - t0, status=prob.status,
                         inputs_hash=inputs_hash)


def certify_grid(
    K: NDArray[np.float64], P: NDArray[np.float64], box: DynamicBox, vehicle: VehicleParams,
    Td: float, bandwidth: float, n: int,
) -> tuple[float, float, list[Certificate]]:
    """Dense-grid check of the interpolated closed loop with the exact (ZOH) model.

    Returns (max spectral radius, max eigenvalue of P⁻¹A_clᵀPA_cl, certificates). The Lyapunov
    decrease is measured relative to P (generalised eigenvalues), so the margin is scale-free.
    """
    pb = _premise_box(box)
    z = check_grid(box, n)
    A, B = augmented_models(z, vehicle, Td, bandwidth)
    Kg = np.tensordot(pb.memberships(z), K, axes=(1, 0))
    Acl = A + B @ Kg
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    # Generalised eigenvalues of (A_clᵀ P A_cl, P) via the Cholesky factor of P.
    Lc = np.linalg.cholesky(P)
    Li = np.linalg.inv(Lc)
    G = Li @ np.swapaxes(Acl, -1, -2) @ P @ Acl @ Li.T
    dec = float(np.max(np.linalg.eigvalsh(0.5 * (G + np.swapaxes(G, -1, -2)))))
    certs = [
        Certificate(f"grid {n}^3 spectral radius − 1", rho - 1.0),
        Certificate(f"grid {n}^3 Lyapunov decrease (λmax(P⁻¹A_clᵀPA_cl) − 1)", dec - 1.0),
    ]
    return rho, dec, certs
