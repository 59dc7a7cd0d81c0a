"""Kinematic LQR-LMI and terminal set (paper eqs. "Feasibility-LMI" and
"terminal_set_computation"; the paper's LMI designs).

LQR-LMI: common ``Y ≻ 0``, per-vertex ``W_i``; for every vertex i of the TS error model::

    [ (1−t) Y        (A_i Y + B W_i)ᵀ   (Q½ Y)ᵀ   (R½ W_i)ᵀ ]
    [ A_i Y + B W_i   Y                  0          0       ]  ⪰ 0
    [ Q½ Y            0                  I          0       ]
    [ R½ W_i          0                  0          I       ]

which is the Schur form of ``(A_i+BK_i)ᵀP(A_i+BK_i) − (1−t)P + Q + K_iᵀRK_i ⪯ 0`` with
``P = Y⁻¹``, ``K_i = W_i Y⁻¹``: the LQR decrease condition with a *relative margin* t — the
certificate recomputed with numpy then holds by t relative to P, far above any solver tolerance
(see :mod:`tsmpc.synthesis.sdp`; t = 0 is the paper's LMI). B is constant, so the closed loop with
``K(ρ) = Σμ_i K_i`` is the same convex combination and the vertex LMIs cover the whole box.
Objective: maximise log det Y (the paper states none; this one reproduces the published S best);
then, with Y backed off by 1 %, the gains nearest to the log-det optimum's that satisfy the LMI
with margin t (an accurate conic problem: the log-det solve alone can end a hair outside the
feasible set, see :func:`_lqr_lmi`).

Terminal set: maximise trace Z subject to ``(A_i+BK_i) Z (A_i+BK_i)ᵀ ⪯ (1−t) Z`` (invariance) and
``K_i Z K_iᵀ ⪯ (1−t) diag(ū²)`` (inputs) for every vertex; ``S = Z⁻¹``, χ = {x : xᵀSx ≤ 1}.

Scaling: e_x, e_y, e_θ have comparable magnitudes here (Y's eigenvalues span 1e-3…3e-2), so the
SDPs are posed in physical units; the margins are relative, hence scale-free.

Symmetry: mirroring (e_y, e_θ, ω) → −(e_y, e_θ, ω) maps the vertex set onto itself, so averaging any
feasible (Y, Z) with its mirror image is feasible and not worse (log det is concave, trace linear).
Hence an optimum with ``Y₁₂ = Y₁₃ = Z₁₂ = Z₁₃ = 0`` exists and we impose that structure: it gives
the paper's S structure exactly instead of up to solver noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import KinematicBox, KinematicLMISettings
from tsmpc.errors import SolverError
from tsmpc.models.kinematic import KinematicTS
from tsmpc.synthesis.certificates import (
    Certificate,
    consistency_certificate,
    definite_certificate,
    lmi_certificate,
)
from tsmpc.synthesis.sdp import (
    LADDER_DOWN,
    LADDER_UP,
    Infeasible,
    SDPSolver,
    solve,
    solve_with_margin,
    values,
)

if TYPE_CHECKING:  # cvxpy is imported where a design is solved
    from cvxpy.constraints.constraint import Constraint
    from cvxpy.expressions.expression import Expression

__all__ = ["KinematicDesign", "certify_kinematic", "design_kinematic"]

#: Largest entry of ``P Y − I`` / ``S Z − I`` accepted for a stored inverse. The certificates use
#: the stored P and S themselves (Y and Z are kept for the record), so this only catches a file whose
#: matrices disagree: a float64 inverse is exact to ≈ 1e-12, a design perturbed by a relative 1e-7
#: moves S Z − I by cond(Z) · 1e-7 ≈ 6e-5, any real alteration by far more.
INVERSE_TOL = 1e-4


@dataclass(frozen=True)
class KinematicDesign:
    """Result of the kinematic synthesis (vertex order of :class:`KinematicTS`)."""

    Y: NDArray[np.float64]  #: (3, 3)
    P: NDArray[np.float64]  #: (3, 3) terminal cost, Y⁻¹
    K: NDArray[np.float64]  #: (8, 2, 3) vertex gains, u = K_i x
    Z: NDArray[np.float64]  #: (3, 3)
    S: NDArray[np.float64]  #: (3, 3) terminal set xᵀ S x ≤ 1, Z⁻¹
    certificates: tuple[Certificate, ...]
    solve_time_s: float
    status: str  #: solver statuses of the two SDPs
    inputs_hash: str = ""
    margin_imposed: float = 0.0  #: relative margin t built into both SDPs
    solver: str = "CLARABEL"


def _sym(M: Expression) -> Expression:
    return 0.5 * (M + M.T)





def design_kinematic(
    box: KinematicBox, settings: KinematicLMISettings, Tc: float, inputs_hash: str = "",
    *, solver: SDPSolver | str = SDPSolver.CLARABEL,
) -> KinematicDesign:
    """Solve both kinematic SDPs with cvxpy (Clarabel by default) and certify them.

    Every LMI carries the relative margin of :mod:`tsmpc.synthesis.sdp`'s ladder. Raises
    :class:`SolverError` when no margin is feasible or the solver fails, and
    :class:`~tsmpc.errors.CertificateError` when feasible answers never certify.
    """
    t0 = time.perf_counter()
    ts = KinematicTS(box, Tc)
    A, B = ts.A_vertices, ts.B
    Q, R = np.diag(settings.Q), np.diag(settings.R)
    ubar2 = np.diag(np.square(settings.u_bar))
    s = SDPSolver(str(solver).upper())

    def lqr(t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        return _lqr_lmi(A, B, Q, R, t, s)

    def lqr_certs(res: tuple[NDArray[np.float64], NDArray[np.float64], str]) -> list[Certificate]:
        Y, K, _ = res
        return certify_kinematic(A, B, Q, R, Y, K, None, ubar2)

    # SCS (first-order) answers to ≈ its eps, looser than Clarabel: its ladder starts stricter.
    ladder = LADDER_UP if s == SDPSolver.SCS else LADDER_DOWN
    try:
        (Y, K, st1), _, t_lqr = solve_with_margin(lqr, lqr_certs, "kinematic LQR-LMI", ladder)
    except Infeasible as exc:
        raise SolverError(
            f"kinematic LQR-LMI: no solution with a relative margin >= 3e-6 ({s.value}: "
            f"{exc.status}) over the box ω ∈ {box.omega}, v_d ∈ {box.v_d}, e_θ ∈ "
            f"{tuple(round(e, 4) for e in box.e_theta)}; narrow kinematic_box.v_d / "
            "kinematic_box.omega (or plan the reference slower) or change kinematic_lmi.Q/R"
        ) from None
    P = np.linalg.inv(Y)
    P = 0.5 * (P + P.T)

    def term(t: float) -> tuple[NDArray[np.float64], str]:
        return _terminal_lmi(A, B, K, ubar2, t, s, Y=Y)

    def term_certs(res: tuple[NDArray[np.float64], str]) -> list[Certificate]:
        return certify_kinematic(A, B, Q, R, Y, K, res[0], ubar2, P=P)

    try:
        (Z, st2), certs, t_term = solve_with_margin(term, term_certs, "kinematic terminal set",
                                                    ladder)
    except Infeasible as exc:
        raise SolverError(f"kinematic terminal-set LMI: no solution ({s.value}: {exc.status}); "
                          "raise kinematic_lmi.u_bar or narrow kinematic_box") from None
    S = np.linalg.inv(Z)
    S = 0.5 * (S + S.T)
    certs = certify_kinematic(A, B, Q, R, Y, K, Z, ubar2, P=P, S=S)
    from tsmpc.synthesis.certificates import check

    check(certs, "kinematic design")
    return KinematicDesign(Y=Y, P=P, K=K, Z=Z, S=S, certificates=tuple(certs),
                           solve_time_s=time.perf_counter() - t0, status=f"{st1}/{st2}",
                           inputs_hash=inputs_hash, margin_imposed=min(t_lqr, t_term),
                           solver=s.value)


#: Back-off of the log-det optimum before the margin is maximised: Y = 0.99 Y* (log det Y − 0.03).
BACKOFF = 0.99


def _lqr_block(
    A: NDArray[np.float64], B: NDArray[np.float64], Qh: NDArray[np.float64], Rh: NDArray[np.float64],
    Y: Expression | NDArray[np.float64], W: Expression, t: float,
) -> Expression:
    import cvxpy as cp

    n, m = 3, 2
    Zn, Znm = np.zeros((n, n)), np.zeros((n, m))
    AY = A @ Y + B @ W
    M = cp.bmat([
        [(1.0 - t) * Y, AY.T, (Qh @ Y).T, (Rh @ W).T],
        [AY, Y, Zn, Znm],
        [Qh @ Y, Zn, np.eye(n), Znm],
        [Rh @ W, Znm.T, Znm.T, np.eye(m)],
    ])
    return _sym(M)


def _lqr_lmi(
    A: NDArray[np.float64], B: NDArray[np.float64], Q: NDArray[np.float64], R: NDArray[np.float64],
    t: float, solver: SDPSolver,
) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """The LQR-LMI in two stages → (Y, K, status).

    1. max log det Y s.t. the LMI with relative margin t at every vertex (the paper's objective;
       the exponential cone often ends "optimal_inaccurate", a hair outside the feasible set);
    2. Y fixed at :data:`BACKOFF` · Y*, the gains nearest to stage 1's (least Frobenius distance)
       that satisfy the LMI with margin t — a convex problem without the exponential cone that
       the solver answers accurately, so the certificates hold by ≈ t.
    """
    import cvxpy as cp

    n, m, nv = 3, 2, A.shape[0]
    Qh, Rh = np.sqrt(Q), np.sqrt(R)
    Y = cp.Variable((n, n), symmetric=True)
    W = [cp.Variable((m, n)) for _ in range(nv)]
    cons: list[Constraint] = [Y[0, 1] == 0, Y[0, 2] == 0]
    cons += [_lqr_block(A[i], B, Qh, Rh, Y, W[i], t) >> 0 for i in range(nv)]
    status = solve(cp.Problem(cp.Maximize(cp.log_det(Y)), cons), solver, "kinematic LQR-LMI")
    Wv = values(W)
    if Y.value is None or Wv is None:
        raise Infeasible(status)
    Yv = BACKOFF * 0.5 * (Y.value + Y.value.T)
    W1 = [BACKOFF * w for w in Wv]  # the stage-1 gains K_i = W_i Y⁻¹, unchanged by the back-off
    W2 = [cp.Variable((m, n)) for _ in range(nv)]
    cons2: list[Constraint] = [_lqr_block(A[i], B, Qh, Rh, Yv, W2[i], t) >> 0 for i in range(nv)]
    obj = cp.Minimize(sum(cp.norm(W2[i] - W1[i], "fro") for i in range(nv)))
    status2 = solve(cp.Problem(obj, cons2), solver, "kinematic LQR-LMI (margin)")
    W2v = values(W2)
    if W2v is None:
        raise Infeasible(f"{status}; margin stage {status2}")
    P = np.linalg.inv(Yv)
    return Yv, np.array([w @ P for w in W2v]), f"{status}+{status2}"


def _terminal_lmi(
    A: NDArray[np.float64], B: NDArray[np.float64], K: NDArray[np.float64],
    ubar2: NDArray[np.float64], t: float, solver: SDPSolver, *, Y: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], str]:
    """max trace Z s.t. invariance and input LMIs with relative margin t → (Z, status).

    For SCS the LMIs are preconditioned: ``Z = D Z̃ D`` with ``D = diag(√(Y_jj / max Y))`` from the
    LQR stage's Y (known before this SDP) and the input rows normalised by ū. Z's eigenvalues span
    three decades; unscaled, SCS stops at its iteration limit ≈ 4e-2 (relative) outside the
    invariance LMI, scaled it converges in ≈ 30k iterations to the margin imposed. The problem is
    the same (a congruence and a positive row scaling); Clarabel, an interior-point method, answers
    the unscaled form accurately and keeps it.
    """
    import cvxpy as cp

    n = 3
    if solver == SDPSolver.SCS and Y is not None:
        d = np.sqrt(np.diag(Y) / np.max(np.diag(Y)))
        D, Di, ub = np.diag(d), np.diag(1.0 / d), np.sqrt(np.diag(ubar2))
        Zt = cp.Variable((n, n), symmetric=True)
        cons: list[Constraint] = [Zt[0, 1] == 0, Zt[0, 2] == 0]  # D is diagonal: Z̃ has Z's structure
        for i in range(A.shape[0]):
            Acl = Di @ (A[i] + B @ K[i]) @ D
            Kd = (K[i] @ D) / ub[:, None]
            cons.append(_sym(cp.bmat([[(1.0 - t) * Zt, (Acl @ Zt).T], [Acl @ Zt, Zt]])) >> 0)
            cons.append((1.0 - t) * np.eye(ub.size) - _sym(Kd @ Zt @ Kd.T) >> 0)
        status = solve(cp.Problem(cp.Maximize(cp.trace(D @ Zt @ D)), cons), solver,
                       "kinematic terminal-set LMI")
        if Zt.value is None:
            raise Infeasible(status)
        return D @ (0.5 * (Zt.value + Zt.value.T)) @ D, status
    Z = cp.Variable((n, n), symmetric=True)
    cons = [Z[0, 1] == 0, Z[0, 2] == 0]
    for i in range(A.shape[0]):
        Acl = A[i] + B @ K[i]
        cons.append(_sym(cp.bmat([[(1.0 - t) * Z, (Acl @ Z).T], [Acl @ Z, Z]])) >> 0)
        cons.append((1.0 - t) * ubar2 - _sym(K[i] @ Z @ K[i].T) >> 0)
    prob = cp.Problem(cp.Maximize(cp.trace(Z)), cons)
    status = solve(prob, solver, "kinematic terminal-set LMI")
    if Z.value is None:
        raise Infeasible(status)
    return 0.5 * (Z.value + Z.value.T), status


def certify_kinematic(
    A: NDArray[np.float64], B: NDArray[np.float64], Q: NDArray[np.float64], R: NDArray[np.float64],
    Y: NDArray[np.float64], K: NDArray[np.float64], Z: NDArray[np.float64] | None,
    ubar2: NDArray[np.float64],
    *, P: NDArray[np.float64] | None = None, S: NDArray[np.float64] | None = None,
) -> list[Certificate]:
    """Recompute every kinematic LMI with numpy (independently of the solver's matrices).

    * LQR decrease per vertex: ``A_clᵀ P A_cl − P + Q + KᵀRK ≺ 0``, relative to P;
    * terminal-set invariance per vertex: ``A_clᵀ S A_cl − S ≺ 0``, relative to S;
    * input bound per vertex: ``K Z Kᵀ − diag(ū²) ≺ 0``, relative to diag(ū²);
    * Y, Z positive definite (relative: inverse condition number).

    The MPC uses the stored terminal cost ``P`` and terminal set ``S``: when given, they are the
    matrices certified, and ``P Y = I`` / ``S Z = I`` are checked to :data:`INVERSE_TOL`, so a
    design whose P or S was altered after the solve is rejected. ``Z`` None: the LQR part only.
    """
    certs = [definite_certificate("Y positive definite", Y)]
    if Z is not None:
        certs.append(definite_certificate("Z positive definite", Z))
    for name, M, N in (("P = Y^-1", P, Y), ("S = Z^-1", S, Z)):
        if M is not None and N is not None:
            err = float(np.max(np.abs(M @ N - np.eye(N.shape[0]))))
            certs.append(consistency_certificate(name, err, INVERSE_TOL))
    Pc = np.linalg.inv(Y) if P is None else P
    Sc = None if Z is None else (np.linalg.inv(Z) if S is None else S)
    Zc = None if Sc is None else np.linalg.inv(Sc)
    for i in range(A.shape[0]):
        Acl = A[i] + B @ K[i]
        ric = Acl.T @ Pc @ Acl - Pc + Q + K[i].T @ R @ K[i]
        certs.append(lmi_certificate(f"LQR decrease, vertex {i}", ric, Pc))
        if Sc is not None and Zc is not None:
            certs.append(lmi_certificate(f"terminal-set invariance, vertex {i}",
                                         Acl.T @ Sc @ Acl - Sc, Sc))
            certs.append(lmi_certificate(f"terminal-set input bound, vertex {i}",
                                         K[i] @ Zc @ K[i].T - ubar2, ubar2))
    return certs
