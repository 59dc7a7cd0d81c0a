"""Dynamic TS-LMI-LQR on the Apkarian-augmented model (paper Sec. 3.2; the paper's LMI designs).

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
4. *A margin in the SDP.* The decrease condition is imposed with a relative margin t,
   ``A_clᵀ P A_cl − (1−t) P + s(Q + KᵀRK) ⪯ 0`` (``(1−t) Y`` in the Schur form's corner), t from
   the ladder of :mod:`tsmpc.synthesis.sdp` (1e-4 first): the recomputed certificates then hold
   by ≈ t, 100× the threshold, on any CPU and BLAS.
5. *Certificates.* Afterwards, numpy recomputes (a) the guaranteed-cost decrease at every LMI grid
   point relative to P (:func:`certify_dynamic`), and (b) on a dense grid of ϑ (``grid_points`` per
   axis, default 15³) the spectral radius of the exact closed loop and the Lyapunov decrease
   ``A_clᵀ P A_cl − P ≺ 0`` (relative margin reported). A failing certificate raises
   :class:`CertificateError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import DynamicBox, DynamicLMISettings, VehicleParams
from tsmpc.errors import SolverError
from tsmpc.models.dynamic import Discretization, augment_apkarian, continuous_matrices, discretize
from tsmpc.models.polytope import SchedulingBox
from tsmpc.synthesis.certificates import Certificate, definite_certificate, lmi_certificate
from tsmpc.synthesis.sdp import LADDER_FLOOR, Infeasible, SDPSolver, solve, solve_with_margin, values

if TYPE_CHECKING:  # cvxpy is imported where a design is solved
    from cvxpy.constraints.constraint import Constraint

__all__ = ["DynamicDesign", "augmented_models", "certify_dynamic", "certify_grid", "design_dynamic",
           "per_vertex_dare_gains"]

#: Diagonal state / input scaling of the SDP: x = T_x x_s, u = T_u u_s (units: m/s, rad, rad/s,
#: N, rad, rad → O(1) at the operating envelope).
STATE_SCALE = np.array([1.0, 0.01, 0.1, 1000.0, 0.1, 0.1])
INPUT_SCALE = np.array([1000.0, 0.1])
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
    margin_imposed: float = 0.0  #: relative margin t built into the SDP
    solver: str = "CLARABEL"


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


def _cost_scale(settings: DynamicLMISettings) -> float:
    """Common scale s of Q and R in the SDP (1 / the largest scaled weight); the LQR optimum is
    invariant to it, the guaranteed-cost matrix P is for the cost s·(xᵀQx + uᵀRu)."""
    Tx, Tu = STATE_SCALE, INPUT_SCALE
    return 1.0 / max(float(np.max(Tx**2 * np.asarray(settings.Q))),
                     float(np.max(Tu**2 * np.asarray(settings.R))))


def design_dynamic(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float,
    inputs_hash: str = "", *, solver: SDPSolver | str = SDPSolver.CLARABEL,
) -> DynamicDesign:
    """Solve the dynamic TS-LMI-LQR with cvxpy (Clarabel by default) and certify it (see the
    module docstring). Every LMI carries the relative margin of :mod:`tsmpc.synthesis.sdp`'s ladder.

    Raises :class:`SolverError` if the SDP fails or no margin is feasible (naming the LMI, the
    grid point that blocks and the options that would help) and
    :class:`~tsmpc.errors.CertificateError` if a recomputed certificate does not hold.
    """
    t0 = time.perf_counter()
    lam = settings.filter_bandwidth
    pb = _premise_box(box)
    s_solver = SDPSolver(str(solver).upper())
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Txi = np.diag(1.0 / STATE_SCALE)
    s = _cost_scale(settings)
    Qh = np.sqrt(Tx @ np.diag(settings.Q) @ Tx * s)
    Rh = np.sqrt(Tu @ np.diag(settings.R) @ Tu * s)

    zg = _lmi_grid(box)
    mu = pb.memberships(zg)  # (g, 8)
    A, B = augmented_models(zg, vehicle, Td, lam)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise SolverError(f"dynamic TS-LMI-LQR at Td={Td}: the model is not finite on the box "
                          "(check vehicle parameters and dynamic_box)")
    As = Txi @ A @ Tx
    Bs = Txi @ B @ Tu
    what = f"dynamic TS-LMI-LQR at Td={Td}"

    def attempt(t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        Ys, Ks, status = _guaranteed_cost_lmi(As, Bs, mu, pb, Qh, Rh, t, s_solver, what)
        Ps = np.linalg.inv(Ys)
        P = Txi @ Ps @ Txi
        return Tu @ Ks @ Txi, 0.5 * (P + P.T), status  # physical: u = T_u K_s T_x⁻¹ x

    def certify(res: tuple[NDArray[np.float64], NDArray[np.float64], str]) -> list[Certificate]:
        return certify_dynamic(res[0], res[1], box, vehicle, settings, Td)[2]

    try:
        (K, P, status), certs, t_imp = solve_with_margin(attempt, certify, f"dynamic design (Td={Td})")
    except Infeasible as exc:
        raise SolverError(
            f"{what}: no common Lyapunov matrix with a relative margin >= {LADDER_FLOOR:g} "
            f"({s_solver.value}: {exc.status}) over the box δ ∈ [{box.delta[0]:.3f}, "
            f"{box.delta[1]:.3f}] rad, v ∈ [{box.v[0]:g}, {box.v[1]:g}] m/s"
            f"{_blocking_point(As, Bs, mu, pb, Qh, Rh, zg, s_solver, what)}; narrow dynamic_box.v "
            "or dynamic_box.delta (plan the reference slower: tsmpc plan --v-max / --a-lat), or "
            "change dynamic_lmi.Q/R") from None
    rho, dec, _ = certify_grid(K, P, box, vehicle, Td, lam, settings.grid_points)
    return DynamicDesign(K=K, P=P, Td=float(Td), bandwidth=lam, certificates=tuple(certs),
                         grid_max_rho=rho, grid_max_decrease=dec,
                         solve_time_s=time.perf_counter() - t0, status=status,
                         inputs_hash=inputs_hash, margin_imposed=t_imp, solver=s_solver.value)


def _guaranteed_cost_lmi(
    As: NDArray[np.float64], Bs: NDArray[np.float64], mu: NDArray[np.float64], pb: SchedulingBox,
    Qh: NDArray[np.float64], Rh: NDArray[np.float64], t: float, solver: SDPSolver, what: str,
    points: NDArray[np.intp] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """min trace X, X ⪰ Y⁻¹, s.t. the guaranteed-cost LMI with relative margin t at the grid
    points (scaled coordinates) → (Y_s, K_s (8, 2, 6), status)."""
    import cvxpy as cp

    n, m = 6, 2
    Y = cp.Variable((n, n), symmetric=True)
    X = cp.Variable((n, n), symmetric=True)
    # α does not enter the model: one W per (δ, v) corner, shared by the two α vertices.
    W = {(lo_d, lo_v): cp.Variable((m, n)) for lo_d in (False, True) for lo_v in (False, True)}
    Wv = [W[(bool(b[0]), bool(b[1]))] for b in pb.vertex_bits]
    Zn, Znm = np.zeros((n, n)), np.zeros((n, m))
    cons: list[Constraint] = [cp.bmat([[X, np.eye(n)], [np.eye(n), Y]]) >> 0]
    for g in (range(As.shape[0]) if points is None else points):
        Wg = sum(float(mu[g, i]) * Wv[i] for i in range(len(Wv)) if mu[g, i] > 0.0)
        AY = As[g] @ Y + Bs[g] @ Wg
        M = cp.bmat([
            [(1.0 - t) * Y, AY.T, (Qh @ Y).T, (Rh @ Wg).T],
            [AY, Y, Zn, Znm],
            [Qh @ Y, Zn, np.eye(n), Znm],
            [Rh @ Wg, Znm.T, Znm.T, np.eye(m)],
        ])
        cons.append(0.5 * (M + M.T) >> 0)
    prob = cp.Problem(cp.Minimize(cp.trace(X)), cons)
    status = solve(prob, solver, what)
    Wvals = values(Wv)
    if Y.value is None or Wvals is None:
        raise Infeasible(status)
    Ys = 0.5 * (Y.value + Y.value.T)
    Ps = np.linalg.inv(Ys)
    return Ys, np.array([w @ Ps for w in Wvals]), status


def _blocking_point(
    As: NDArray[np.float64], Bs: NDArray[np.float64], mu: NDArray[np.float64], pb: SchedulingBox,
    Qh: NDArray[np.float64], Rh: NDArray[np.float64], zg: NDArray[np.float64], solver: SDPSolver,
    what: str,
) -> str:
    """Which grid point makes the SDP infeasible: the points are added from the centre of the box
    outwards until the problem at the ladder's floor margin has no solution (a diagnosis run only
    when the design failed)."""
    centre = 0.5 * (pb.lower + pb.upper)
    span = pb.upper - pb.lower
    order = np.argsort(np.max(np.abs(zg - centre) / span, axis=1), kind="stable")
    for n in range(1, order.size + 1):
        try:
            _guaranteed_cost_lmi(As, Bs, mu, pb, Qh, Rh, LADDER_FLOOR, solver, what, order[:n])
        except (Infeasible, SolverError):
            g = int(order[n - 1])
            return (f"; infeasible once the grid point δ = {zg[g, 0]:.3f} rad, v = {zg[g, 1]:.2f} "
                    "m/s is added (guaranteed-cost LMI)")
    return ""


def certify_dynamic(
    K: NDArray[np.float64], P: NDArray[np.float64], box: DynamicBox, vehicle: VehicleParams,
    settings: DynamicLMISettings, Td: float,
) -> tuple[float, float, list[Certificate]]:
    """Every certificate of a dynamic design, recomputed with numpy from (K, P) in physical units:

    * P positive definite (in the scaled states, where its condition number means something);
    * the guaranteed-cost decrease ``A_clᵀ P A_cl − P + s(Q + KᵀRK) ≺ 0`` relative to P at every
      point of the LMI grid (exact ZOH model, interpolated gain; absolute margin in the scaled
      states);
    * on the dense grid: spectral radius and Lyapunov decrease (:func:`certify_grid`).

    Returns (max spectral radius, max Lyapunov ratio, certificates)."""
    Tx = np.diag(STATE_SCALE)
    certs = [definite_certificate("P positive definite (scaled states)", Tx @ P @ Tx)]
    zg = _lmi_grid(box)
    A, B = augmented_models(zg, vehicle, Td, settings.filter_bandwidth)
    Kg = np.tensordot(_premise_box(box).memberships(zg), K, axes=(1, 0))
    Acl = A + B @ Kg
    s = _cost_scale(settings)
    Q, R = s * np.diag(settings.Q), s * np.diag(settings.R)
    ric = np.swapaxes(Acl, -1, -2) @ P @ Acl - P + Q + np.swapaxes(Kg, -1, -2) @ R @ Kg
    # Absolute margins in the SDP's scaled states (physical P mixes N and rad: its entries span
    # 1e-6…1e3); the relative margins are the same in either.
    ric_s, P_s = Tx @ ric @ Tx, Tx @ P @ Tx
    certs += [lmi_certificate(f"guaranteed cost at δ={zg[g, 0]:.3f}, v={zg[g, 1]:.2f}", ric_s[g], P_s)
              for g in range(zg.shape[0])]
    rho, dec, cg = certify_grid(K, P, box, vehicle, Td, settings.filter_bandwidth,
                                settings.grid_points)
    return rho, dec, certs + cg


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
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl)))) if np.all(np.isfinite(Acl)) else np.inf
    # Generalised eigenvalues of (A_clᵀ P A_cl, P) via the Cholesky factor of P, in the scaled
    # states (the same eigenvalues, a far better conditioned P).
    Tx, Txi = np.diag(STATE_SCALE), np.diag(1.0 / STATE_SCALE)
    Ps, Acls = Tx @ P @ Tx, Txi @ Acl @ Tx
    try:
        Li = np.linalg.inv(np.linalg.cholesky(0.5 * (Ps + Ps.T)))
        G = Li @ np.swapaxes(Acls, -1, -2) @ Ps @ Acls @ Li.T
        dec = float(np.max(np.linalg.eigvalsh(0.5 * (G + np.swapaxes(G, -1, -2)))))
    except np.linalg.LinAlgError:
        dec = np.inf
    certs = [
        Certificate(f"grid {n}^3 spectral radius − 1", rho - 1.0, rho - 1.0),
        Certificate(f"grid {n}^3 Lyapunov decrease (λmax(P⁻¹A_clᵀPA_cl) − 1)", dec - 1.0, dec - 1.0),
    ]
    return rho, dec, certs
