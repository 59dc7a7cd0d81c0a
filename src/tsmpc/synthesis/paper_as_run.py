"""The dynamic TS-LMI-LQR as the published run solved it (the published run): a quirk of that run, not a
recommendation (``dynamic_lmi.formulation = "feasibility-euler"``, the ``paper-as-run`` preset).

Problem. The Apkarian-augmented model ``[v, α, ω, F_f, δ_f, ζ]`` of :mod:`tsmpc.models.dynamic`
discretised by **Euler** at ``T_d`` (the published run: 1 ms) at the **8 vertices** of the box
(δ, v, α) only, one common ``Y = P⁻¹`` and one ``W_i`` per vertex, the paper's LQR-LMI at each
vertex (the Schur form of ``(A_i + B K_i)ᵀ P (A_i + B K_i) − P + Q + K_iᵀ R K_i ≺ 0``,
``K_i = W_i Y⁻¹``, as in :mod:`tsmpc.synthesis.kinematic`) and **no objective**: a feasibility
problem. It has no unique answer and the published gains are unknown; which point is
kept is its own switch (``dynamic_lmi.feasible_point``):

* ``"analytic-center"`` (the ``paper-as-run`` preset): the analytic centre of the 8 vertex LMIs and
  Y ≻ 0 (:mod:`tsmpc.synthesis.analytic_center`, Newton on the log-det barrier from Clarabel's
  answer). It is what an interior-point solver converges to on a problem without objective, and it
  is the same whatever units or scaling the LMIs are posed in (a change of variables adds a
  constant to the barrier; the normalisation of Q and R below scales Y and the Schur complements
  alike) — so it is also the centre of the problem as a MATLAB user would pose it, in physical
  units, where Clarabel itself returns an inaccurate answer that fails the certificates
  (:func:`solve_unscaled`, documented in docs/paper.md).
* ``"solver"``: Clarabel's answer in the scaled coordinates — where the solver stopped, which
  depends on that scaling.

The gains decide the two places where the preset misses Table 5 (docs/paper.md, "What the gains
decide"): the steering row's δ_f / ζ ratio sets the start-up transient, and the force row's speed
gain sets the headroom on the fastest stretch.

What is *not* certified, by construction of the published design: the interpolated loop between
the vertices (the model is not affine in the premises, the paper's LMI designs) and, with the as-run law's
unclipped memberships, anything outside the box. :func:`grid_report` measures the former on a
dense grid (Euler model) and reports it; it does not reject the design. The numerical conditioning
uses the state and input scaling of :mod:`tsmpc.synthesis.dynamic` (reused by import).

Certificates (numpy, recomputed from the stored K and P, also on every cache load): P ≻ 0 and the
Riccati inequality at each vertex relative to P — what the SDP imposed, with the relative margin of
:mod:`tsmpc.synthesis.sdp` built into the LMIs (still no objective) so that the certificates hold
on any machine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import DynamicBox, DynamicLMISettings, FeasiblePoint, VehicleParams
from tsmpc.errors import SolverError
from tsmpc.models.dynamic import Discretization, augment_apkarian, continuous_matrices, discretize
from tsmpc.models.polytope import SchedulingBox
from tsmpc.synthesis.analytic_center import AffineLMI, analytic_center
from tsmpc.synthesis.certificates import Certificate, check, definite_certificate, lmi_certificate
from tsmpc.synthesis.dynamic import INPUT_SCALE, STATE_SCALE, check_grid
from tsmpc.synthesis.sdp import LADDER_FLOOR, Infeasible, SDPSolver, solve, solve_with_margin, values

if TYPE_CHECKING:  # cvxpy is imported where a design is solved
    from cvxpy.constraints.constraint import Constraint

__all__ = [
    "FeasibilityDesign",
    "certify_vertices",
    "design_feasibility",
    "grid_report",
    "solve_unscaled",
    "vertex_lmis",
    "vertex_models",
]


#: Margins tried for the published run's design: the smallest that certifies on any machine
#: first (the published LMI was only marginally feasible: a larger margin moves its gains).
AS_RUN_LADDER = (LADDER_FLOOR,)

#: Ways of posing the same feasibility SDP to Clarabel, tried in order when the previous one ends
#: in a numerical failure (not infeasibility): the published LMI is so marginal that whether
#: Clarabel's default path converges depends on the CPU (seen: an AMD Zen 5 fails where Intel
#: machines succeed, μ 0.5 at 1 ms). The redundant ``Y ⪰ 0`` and Clarabel without equilibration
#: converge there; the analytic centre kept by the ``paper-as-run`` preset is the same whichever
#: variant found the first feasible point. (y_constraint, Clarabel options, label)
CLARABEL_VARIANTS: tuple[tuple[bool, dict[str, object], str], ...] = (
    (False, {}, ""),
    (True, {}, " (with Y ⪰ 0)"),
    (False, {"equilibrate_enable": False}, " (no equilibration)"),
)


_FORMULATION = ("feasibility LMI (no objective), common P, 8 vertices, Euler (the published run's; "
                "a quirk, not a recommendation)")


@dataclass(frozen=True)
class FeasibilityDesign:
    """The published run's dynamic design (vertex order of
    :class:`~tsmpc.models.dynamic.DynamicTS`); the fields of
    :class:`~tsmpc.synthesis.dynamic.DynamicDesign`, so ``tsmpc design`` prints either.

    ``K[i]`` (2 × 6) maps ``[v, α, ω, F_f, δ_f, ζ]`` to the filter input ``[F_xR, δ]`` (u = K x,
    physical units)."""

    K: NDArray[np.float64]  #: (8, 2, 6)
    P: NDArray[np.float64]  #: (6, 6) common Lyapunov matrix, physical units
    Td: float
    bandwidth: float
    certificates: tuple[Certificate, ...]  #: P ≻ 0 and the 8 vertex LMIs, recomputed
    grid_max_rho: float  #: informational: largest spectral radius of the interpolated loop on the grid
    grid_max_decrease: float  #: informational: largest λ(P⁻¹A_clᵀPA_cl) on the grid (< 1: decrease)
    solve_time_s: float
    status: str
    formulation: str = _FORMULATION
    inputs_hash: str = ""
    margin_imposed: float = 0.0  #: relative margin t of the vertex LMIs (sdp.solve_with_margin)
    solver: str = "CLARABEL"
    feasible_point: str = FeasiblePoint.SOLVER.value  #: which point of the solution set was kept
    center_iterations: int = 0  #: Newton steps from Clarabel's answer to the analytic centre


def _premise_box(box: DynamicBox) -> SchedulingBox:
    return SchedulingBox(("delta", "v", "alpha"), (box.delta[0], box.v[0], box.alpha[0]),
                         (box.delta[1], box.v[1], box.alpha[1]))


def vertex_models(
    box: DynamicBox, vehicle: VehicleParams, Td: float, bandwidth: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Euler-discretised augmented (A (8, 6, 6), B (8, 6, 2)) at the 8 vertices of ``box``."""
    return _euler_augmented(_premise_box(box).vertices(), vehicle, Td, bandwidth)


def _euler_augmented(z: NDArray[np.float64], vehicle: VehicleParams, Td: float, bandwidth: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    z = np.asarray(z, float)
    Ac, Bc = continuous_matrices(z[..., 1], z[..., 0], vehicle)
    Aa, Ba = augment_apkarian(Ac, Bc, bandwidth)
    return discretize(Aa, np.broadcast_to(Ba, (*Aa.shape[:-2], 6, 2)), Td, Discretization.EULER)


def _scaled_weights(settings: DynamicLMISettings) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Q, R) in the scaled coordinates, normalised by their largest entry (feasibility of the
    Riccati inequality is invariant to a common scale of Q and R: P scales with them)."""
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Q = Tx @ np.diag(settings.Q) @ Tx
    R = Tu @ np.diag(settings.R) @ Tu
    s = 1.0 / max(Q.max(), R.max())
    return Q * s, R * s


def _scaled_problem(A: NDArray[np.float64], B: NDArray[np.float64], settings: DynamicLMISettings,
                    state_scale: NDArray[np.float64], input_scale: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.float64]]:
    """(A_s, B_s, Q^½, R^½) in the coordinates x = T_x x_s, u = T_u u_s, Q and R normalised."""
    Tx, Tu = np.diag(state_scale), np.diag(input_scale)
    Txi = np.diag(1.0 / state_scale)
    Q = Tx @ np.diag(settings.Q) @ Tx
    R = Tu @ np.diag(settings.R) @ Tu
    s = 1.0 / max(Q.max(), R.max())
    return Txi @ A @ Tx, Txi @ B @ Tu, np.sqrt(Q * s), np.sqrt(R * s)


def _solve_clarabel(As: NDArray[np.float64], Bs: NDArray[np.float64], Qh: NDArray[np.float64],
                    Rh: NDArray[np.float64], t: float, what: str, *, y_constraint: bool = False,
                    options: dict[str, object] | None = None,
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """The paper's vertex LMIs with the certificates' relative margin t ((1 − t) Y in the corner,
    see tsmpc.synthesis.sdp), no objective: (Y (6, 6), W (8, 2, 6), status) in the given
    coordinates; ``y_constraint`` adds Y ⪰ 0 as a constraint of its own (implied by the vertex
    LMIs). Raises :class:`Infeasible`."""
    import cvxpy as cp

    n, m = As.shape[-1], Bs.shape[-1]
    Y = cp.Variable((n, n), symmetric=True)
    W = [cp.Variable((m, n)) for _ in range(As.shape[0])]
    Zn, Znm = np.zeros((n, n)), np.zeros((n, m))
    cons: list[Constraint] = [Y >> 0] if y_constraint else []
    for i in range(As.shape[0]):
        AY = As[i] @ Y + Bs[i] @ W[i]
        M = cp.bmat([
            [(1.0 - t) * Y, AY.T, (Qh @ Y).T, (Rh @ W[i]).T],
            [AY, Y, Zn, Znm],
            [Qh @ Y, Zn, np.eye(n), Znm],
            [Rh @ W[i], Znm.T, Znm.T, np.eye(m)],
        ])
        cons.append(0.5 * (M + M.T) >> 0)
    status = solve(cp.Problem(cp.Minimize(0), cons), SDPSolver.CLARABEL, what, options)
    Wv = values(W)
    if Y.value is None or Wv is None:
        raise Infeasible(status)
    return 0.5 * (Y.value + Y.value.T), np.array(Wv), status


def _physical(Ys: NDArray[np.float64], Ws: NDArray[np.float64], state_scale: NDArray[np.float64],
              input_scale: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(K (8, 2, 6), P (6, 6)) in physical units from the scaled (Y, W): K_i = W_i Y⁻¹, P = Y⁻¹."""
    Ps = np.linalg.inv(Ys)
    Txi = np.diag(1.0 / state_scale)
    K = np.diag(input_scale) @ (Ws @ Ps) @ Txi
    P = Txi @ Ps @ Txi
    return K, 0.5 * (P + P.T)


def vertex_lmis(As: NDArray[np.float64], Bs: NDArray[np.float64], Qh: NDArray[np.float64],
                Rh: NDArray[np.float64], t: float) -> list[AffineLMI]:
    """The published LMIs as affine functions of x = [upper triangle of Y (21), W (8 · 2 · 6)]:
    Y ≻ 0 and, per vertex, the Schur form with the relative margin t (as solved by Clarabel)."""
    nv, n, m = As.shape[0], As.shape[-1], Bs.shape[-1]
    iu = np.triu_indices(n)
    ny, nw = iu[0].size, m * n
    nx = ny + nv * nw
    d = 3 * n + m
    basis_Y = np.zeros((ny, n, n))
    basis_Y[np.arange(ny), iu[0], iu[1]] = 1.0
    basis_Y[np.arange(ny), iu[1], iu[0]] = 1.0
    lmis = [AffineLMI(np.zeros((n, n)), np.concatenate([basis_Y, np.zeros((nv * nw, n, n))]))]
    F0 = np.zeros((d, d))
    F0[2 * n:, 2 * n:] = np.eye(n + m)
    for i in range(nv):
        F = np.zeros((nx, d, d))
        for j, Yj in enumerate(basis_Y):  # Y enters the corner, the diagonal, A Y and Q^½ Y
            AY, QY = As[i] @ Yj, Qh @ Yj
            F[j, :n, :n] = (1.0 - t) * Yj
            F[j, n:2 * n, n:2 * n] = Yj
            F[j, n:2 * n, :n], F[j, :n, n:2 * n] = AY, AY.T
            F[j, 2 * n:3 * n, :n], F[j, :n, 2 * n:3 * n] = QY, QY.T
        for a in range(m):  # W_i enters B W and R^½ W
            for b in range(n):
                j = ny + i * nw + a * n + b
                Wj = np.zeros((m, n))
                Wj[a, b] = 1.0
                BW, RW = Bs[i] @ Wj, Rh @ Wj
                F[j, n:2 * n, :n], F[j, :n, n:2 * n] = BW, BW.T
                F[j, 3 * n:, :n], F[j, :n, 3 * n:] = RW, RW.T
        lmis.append(AffineLMI(F0, F))
    return lmis


def _center(As: NDArray[np.float64], Bs: NDArray[np.float64], Qh: NDArray[np.float64],
            Rh: NDArray[np.float64], t: float, Ys: NDArray[np.float64], Ws: NDArray[np.float64]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The analytic centre of :func:`vertex_lmis` from the strictly feasible (Ys, Ws)."""
    n = Ys.shape[0]
    iu = np.triu_indices(n)
    res = analytic_center(vertex_lmis(As, Bs, Qh, Rh, t), np.concatenate([Ys[iu], Ws.reshape(-1)]))
    Y = np.zeros((n, n))
    Y[iu] = res.x[:iu[0].size]
    Y = Y + np.triu(Y, 1).T
    return Y, res.x[iu[0].size:].reshape(Ws.shape), res.iterations


def design_feasibility(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float,
    inputs_hash: str = "",
) -> FeasibilityDesign:
    """Solve the published run's feasibility LMI with cvxpy + Clarabel (and, with
    ``settings.feasible_point = "analytic-center"``, move to the LMIs' analytic centre), and
    certify its vertices.

    Raises :class:`SolverError` when Clarabel finds no feasible point or Newton does not converge
    and :class:`~tsmpc.errors.CertificateError` when a recomputed vertex certificate fails.
    """
    t0 = time.perf_counter()
    lam = settings.filter_bandwidth
    A, B = vertex_models(box, vehicle, Td, lam)
    As, Bs, Qh, Rh = _scaled_problem(A, B, settings, STATE_SCALE, INPUT_SCALE)
    what = f"feasibility TS-LMI-LQR at Td={Td}"

    def attempt(t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        failure: Infeasible | None = None
        for y_constraint, options, label in CLARABEL_VARIANTS:
            try:
                Ys, Ws, status = _solve_clarabel(As, Bs, Qh, Rh, t, what, y_constraint=y_constraint,
                                                 options=options)
            except Infeasible as exc:
                if "failed" not in exc.status:  # a status (infeasible, …), not a numerical failure
                    raise
                failure = failure or exc
                continue
            K, P = _physical(Ys, Ws, STATE_SCALE, INPUT_SCALE)
            return K, P, status + label
        assert failure is not None
        raise failure

    try:
        (K, P, status), certs, t_imp = solve_with_margin(
            attempt, lambda r: certify_vertices(A, B, settings, r[0], r[1]),
            f"feasibility dynamic design (Td={Td})", ladder=AS_RUN_LADDER)
    except Infeasible as exc:
        raise SolverError(f"{what}: Clarabel returned {exc.status!r} (the published run's LMI is "
                          "only marginally feasible)") from None
    iterations = 0
    if settings.feasible_point == FeasiblePoint.ANALYTIC_CENTER:
        Tx, Tui = np.diag(STATE_SCALE), np.diag(1.0 / INPUT_SCALE)
        Ys = np.linalg.inv(Tx @ P @ Tx)  # Clarabel's answer in the scaled coordinates
        Ws = (Tui @ K @ Tx) @ Ys
        Yc, Wc, iterations = _center(As, Bs, Qh, Rh, t_imp, 0.5 * (Ys + Ys.T), Ws)
        K, P = _physical(Yc, Wc, STATE_SCALE, INPUT_SCALE)
        certs = certify_vertices(A, B, settings, K, P)
        check(certs, f"feasibility dynamic design, analytic centre (Td={Td})")
    rho, dec = grid_report(K, P, box, vehicle, Td, lam, settings.grid_points)
    return FeasibilityDesign(K=K, P=P, Td=float(Td), bandwidth=lam, certificates=tuple(certs),
                             grid_max_rho=rho, grid_max_decrease=dec,
                             solve_time_s=time.perf_counter() - t0, status=status,
                             inputs_hash=inputs_hash, margin_imposed=t_imp,
                             feasible_point=FeasiblePoint(settings.feasible_point).value,
                             center_iterations=iterations,
                             formulation=_FORMULATION + f"; point kept: {settings.feasible_point}")


def solve_unscaled(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float,
    margin: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], str, list[Certificate]]:
    """The published LMI posed as a MATLAB user would: physical units, no scaling, the paper's Q
    and R as given, Y ⪰ 0 and the 8 vertex LMIs, no margin (``margin`` > 0 imposes the relative
    margin of the designs). Clarabel's answer and its recomputed certificates, *not* checked (a
    study of what the published solver may have returned; never used by a run). Returns (K, P, status,
    certificates). Raises :class:`SolverError` when Clarabel returns nothing."""
    A, B = vertex_models(box, vehicle, Td, settings.filter_bandwidth)
    ones_x, ones_u = np.ones(A.shape[-1]), np.ones(B.shape[-1])
    Qh, Rh = np.sqrt(np.diag(settings.Q)), np.sqrt(np.diag(settings.R))
    what = f"feasibility TS-LMI-LQR in physical units at Td={Td}"
    try:
        Ys, Ws, status = _solve_clarabel(A, B, Qh, Rh, margin, what, y_constraint=True)
    except Infeasible as exc:
        raise SolverError(f"{what}: Clarabel returned {exc.status!r}") from None
    K, P = _physical(Ys, Ws, ones_x, ones_u)
    return K, P, status, certify_vertices(A, B, settings, K, P)


def certify_vertices(
    A: NDArray[np.float64], B: NDArray[np.float64], settings: DynamicLMISettings,
    K: NDArray[np.float64], P: NDArray[np.float64],
) -> list[Certificate]:
    """Recompute with numpy what the SDP imposed: P ≻ 0 and, at every vertex i,
    ``Y [(A_i + B_i K_i)ᵀ P (A_i + B_i K_i) − P + Q + K_iᵀ R K_i] Y ≺ 0`` (Y = P⁻¹), in the
    scaled coordinates of the solve; relative margins with respect to P (scale-free)."""
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Txi, Tui = np.diag(1.0 / STATE_SCALE), np.diag(1.0 / INPUT_SCALE)
    Qs, Rs = _scaled_weights(settings)
    Ps = Tx @ P @ Tx
    Ps = 0.5 * (Ps + Ps.T)
    certs = [definite_certificate("P positive definite (scaled states)", Ps)]
    if not certs[0].holds:
        return certs
    As, Bs = Txi @ A @ Tx, Txi @ B @ Tu
    Ks = Tui @ K @ Tx
    for i in range(A.shape[0]):
        Acl = As[i] + Bs[i] @ Ks[i]
        ric = Acl.T @ Ps @ Acl - Ps + Qs + Ks[i].T @ Rs @ Ks[i]
        certs.append(lmi_certificate(f"LQR decrease, vertex {i}", ric, Ps))
    return certs


def grid_report(
    K: NDArray[np.float64], P: NDArray[np.float64], box: DynamicBox, vehicle: VehicleParams,
    Td: float, bandwidth: float, n: int,
) -> tuple[float, float]:
    """Informational dense-grid check of the interpolated loop (Euler model, memberships inside
    the box): (max spectral radius, max generalised eigenvalue of (A_clᵀPA_cl, P)). Values ≥ 1
    mean the vertex-only design does not certify the loop there — a property of the published
    design, reported, not raised."""
    pb = _premise_box(box)
    z = check_grid(box, n)
    A, B = _euler_augmented(z, vehicle, Td, bandwidth)
    Kg = np.tensordot(pb.memberships(z), K, axes=(1, 0))
    Acl = A + B @ Kg
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    Li = np.linalg.inv(np.linalg.cholesky(P))
    G = Li @ np.swapaxes(Acl, -1, -2) @ P @ Acl @ Li.T
    dec = float(np.max(np.linalg.eigvalsh(0.5 * (G + np.swapaxes(G, -1, -2)))))
    return rho, dec
