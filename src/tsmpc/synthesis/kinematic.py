"""Kinematic LQR-LMI and terminal set (paper eqs. "Feasibility-LMI" and
"terminal_set_computation"; SPEC §6).

LQR-LMI: common ``Y ≻ 0``, per-vertex ``W_i``; for every vertex i of the TS error model::

    [ Y            (A_i Y + B W_i)ᵀ   (Q½ Y)ᵀ   (R½ W_i)ᵀ ]
    [ A_i Y + B W_i   Y                 0          0       ]  ⪰ ε I
    [ Q½ Y            0                 I          0       ]
    [ R½ W_i          0                 0          I       ]

which is the Schur form of ``(A_i+BK_i)ᵀP(A_i+BK_i) − P + Q + K_iᵀRK_i ≺ 0`` with ``P = Y⁻¹``,
``K_i = W_i Y⁻¹``. B is constant, so the closed loop with ``K(ρ) = Σμ_i K_i`` is the same convex
combination and the vertex LMIs cover the whole box. Objective: maximise log det Y (the paper
states none; this one reproduces the published S best).

Terminal set: maximise trace Z subject to ``(A_i+BK_i) Z (A_i+BK_i)ᵀ ⪯ Z`` (invariance) and
``K_i Z K_iᵀ ⪯ diag(ū²)`` (inputs) for every vertex; ``S = Z⁻¹``, χ = {x : xᵀSx ≤ 1}.

Symmetry: mirroring (e_y, e_θ, ω) → −(e_y, e_θ, ω) maps the vertex set onto itself, so averaging any
feasible (Y, Z) with its mirror image is feasible and not worse (log det is concave, trace linear).
Hence an optimum with ``Y₁₂ = Y₁₃ = Z₁₂ = Z₁₃ = 0`` exists and we impose that structure: it gives
the paper's S structure exactly instead of up to solver noise.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import KinematicBox, KinematicLMISettings
from tsmpc.errors import CertificateError, SolverError
from tsmpc.models.kinematic import KinematicTS
from tsmpc.synthesis.certificates import Certificate, check, neg_def_margin

__all__ = ["KinematicDesign", "design_kinematic"]

#: Strictness of every LMI (⪰ ε I), so recomputed certificates have a strictly negative margin.
#: Clarabel's log-det solve can end "optimal_inaccurate" a hair outside the feasible set; the design
#: is then re-solved with the next, stricter ε (the certificates decide, never the status).
LMI_EPS = (1e-6, 1e-5, 3e-5)
#: Largest entry of ``P Y − I`` / ``S Z − I`` accepted for a stored inverse (the SDP's Y, Z are
#: well conditioned: cond ≈ 1e2–1e4, so a float64 inverse is exact to ≈ 1e-12).
INVERSE_TOL = 1e-8


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


def _sym(M: object) -> object:
    return 0.5 * (M + M.T)  # type: ignore[operator]


def design_kinematic(
    box: KinematicBox, settings: KinematicLMISettings, Tc: float, inputs_hash: str = ""
) -> KinematicDesign:
    """Solve both kinematic SDPs with cvxpy + Clarabel and certify them.

    Raises :class:`SolverError` when an SDP fails and :class:`CertificateError` when the
    recomputed certificates do not hold with any strictness of :data:`LMI_EPS`.
    """
    err: CertificateError | None = None
    for eps in LMI_EPS:
        try:
            return _design(box, settings, Tc, inputs_hash, eps)
        except CertificateError as exc:
            err = exc
    assert err is not None
    raise err


def _design(
    box: KinematicBox, settings: KinematicLMISettings, Tc: float, inputs_hash: str, eps: float
) -> KinematicDesign:
    import cvxpy as cp

    t0 = time.perf_counter()
    ts = KinematicTS(box, Tc)
    A, B = ts.A_vertices, ts.B
    Q, R = np.diag(settings.Q), np.diag(settings.R)
    Qh, Rh = np.sqrt(Q), np.sqrt(R)
    n, m, nv = 3, 2, ts.n_vertices
    Zn, Znm = np.zeros((n, n)), np.zeros((n, m))

    Y = cp.Variable((n, n), symmetric=True)
    W = [cp.Variable((m, n)) for _ in range(nv)]
    cons = [Y[0, 1] == 0, Y[0, 2] == 0]
    for i in range(nv):
        AY = A[i] @ Y + B @ W[i]
        M = cp.bmat([
            [Y, AY.T, (Qh @ Y).T, (Rh @ W[i]).T],
            [AY, Y, Zn, Znm],
            [Qh @ Y, Zn, np.eye(n), Znm],
            [Rh @ W[i], Znm.T, Znm.T, np.eye(m)],
        ])
        cons.append(_sym(M) >> eps * np.eye(2 * n + n + m))
    p1 = cp.Problem(cp.Maximize(cp.log_det(Y)), cons)
    with warnings.catch_warnings():  # the status is reported; certificates decide
        warnings.simplefilter('ignore', UserWarning)
        p1.solve(solver=cp.CLARABEL)
    if Y.value is None or p1.status not in ("optimal", "optimal_inaccurate"):
        raise SolverError(f"kinematic LQR-LMI: Clarabel returned {p1.status!r}")
    Yv = 0.5 * (Y.value + Y.value.T)
    P = np.linalg.inv(Yv)
    P = 0.5 * (P + P.T)
    K = np.array([w.value @ P for w in W])

    ubar2 = np.diag(np.square(settings.u_bar))
    Z = cp.Variable((n, n), symmetric=True)
    cons = [Z[0, 1] == 0, Z[0, 2] == 0]
    for i in range(nv):
        Acl = A[i] + B @ K[i]
        cons.append(_sym(cp.bmat([[Z, (Acl @ Z).T], [Acl @ Z, Z]])) >> eps * np.eye(2 * n))
        cons.append(ubar2 - _sym(K[i] @ Z @ K[i].T) >> eps * np.eye(m))
    p2 = cp.Problem(cp.Maximize(cp.trace(Z)), cons)
    with warnings.catch_warnings():  # the status is reported; certificates decide
        warnings.simplefilter('ignore', UserWarning)
        p2.solve(solver=cp.CLARABEL)
    if Z.value is None or p2.status not in ("optimal", "optimal_inaccurate"):
        raise SolverError(f"kinematic terminal-set LMI: Clarabel returned {p2.status!r}")
    Zv = 0.5 * (Z.value + Z.value.T)
    S = np.linalg.inv(Zv)
    S = 0.5 * (S + S.T)

    certs = certify_kinematic(A, B, Q, R, Yv, K, Zv, ubar2, P=P, S=S)
    check(certs, "kinematic design")
    return KinematicDesign(Y=Yv, P=P, K=K, Z=Zv, S=S, certificates=tuple(certs),
                           solve_time_s=time.perf_counter() - t0,
                           status=f"{p1.status}/{p2.status}", inputs_hash=inputs_hash)


def certify_kinematic(
    A: NDArray[np.float64], B: NDArray[np.float64], Q: NDArray[np.float64], R: NDArray[np.float64],
    Y: NDArray[np.float64], K: NDArray[np.float64], Z: NDArray[np.float64], ubar2: NDArray[np.float64],
    *, P: NDArray[np.float64] | None = None, S: NDArray[np.float64] | None = None,
) -> list[Certificate]:
    """Recompute every kinematic LMI with numpy (independently of the solver's matrices).

    The MPC uses the stored terminal cost ``P`` and terminal set ``S``, not Y and Z: when given,
    they are certified too (``P Y = I`` and ``S Z = I`` to :data:`INVERSE_TOL`), so a design whose
    P or S was altered after the solve is rejected.
    """
    certs = [Certificate("Y positive definite", neg_def_margin(-Y)),
             Certificate("Z positive definite", neg_def_margin(-Z))]
    for name, M, N in (("P = Y^-1", P, Y), ("S = Z^-1", S, Z)):
        if M is not None:
            err = float(np.max(np.abs(M @ N - np.eye(N.shape[0]))))
            certs.append(Certificate(name, err - INVERSE_TOL if np.isfinite(err) else np.inf))
    P = np.linalg.inv(Y)
    for i in range(A.shape[0]):
        Acl = A[i] + B @ K[i]
        # The Riccati inequality itself, and the Schur block the SDP imposed (scaled by Y).
        ric = Acl.T @ P @ Acl - P + Q + K[i].T @ R @ K[i]
        certs.append(Certificate(f"LQR vertex {i}", neg_def_margin(Y @ ric @ Y)))
        certs.append(Certificate(f"invariance vertex {i}", neg_def_margin(Acl @ Z @ Acl.T - Z)))
        certs.append(Certificate(f"input vertex {i}", neg_def_margin(K[i] @ Z @ K[i].T - ubar2)))
    return certs
