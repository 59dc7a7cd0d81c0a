"""The narrow QP interface of the controllers and its two backends (TS-MPC, MHE-UIO).

* :func:`solve_daqp` — dense active-set QP (DAQP, MIT): the fast path, called fresh each step
  (with a time-varying Hessian a fresh solve beats updating a persistent workspace).
* :func:`solve_qcqp_clarabel` — the exact fallback for one ellipsoidal constraint
  ``‖Lᵀ(c + G z)‖ ≤ 1 (+ σ)``, S = LLᵀ, as a second-order cone, through Clarabel's own API (no
  cvxpy in a control loop); with ``soft_penalty`` the ellipsoid gets a slack σ ≥ 0 with the exact
  L1 penalty ``ρ σ``.

Both minimise ``½ zᵀ H z + fᵀ z`` subject to ``lb ≤ z ≤ ub`` and ``bl ≤ A z ≤ bu``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

__all__ = ["QPResult", "QPStatus", "solve_daqp", "solve_qcqp_clarabel"]

_INF = 1e30


class QPStatus(IntEnum):
    """Outcome of a QP solve."""

    OPTIMAL = 1
    INFEASIBLE = -1
    FAILED = -2


@dataclass(frozen=True)
class QPResult:
    """Solution of one QP: ``z`` is NaN-free only when ``status`` is OPTIMAL."""

    z: NDArray[np.float64]
    status: QPStatus
    iterations: int
    slack: float = 0.0  #: σ of the soft ellipsoid (Clarabel backend)
    active: NDArray[np.int32] | None = None  #: DAQP active-set flags, usable as a warm start


def solve_daqp(
    H: NDArray[np.float64], f: NDArray[np.float64], lb: NDArray[np.float64], ub: NDArray[np.float64],
    A: NDArray[np.float64], bl: NDArray[np.float64], bu: NDArray[np.float64],
    sense: NDArray[np.int32] | None = None,
) -> QPResult:
    """DAQP on ``½zᵀHz + fᵀz``, simple bounds first, then the rows of A. ``sense`` may carry the
    active set of a previous solve (flag 1) as a warm start."""
    import daqp

    n = f.size
    upper = np.concatenate([ub, bu])
    lower = np.concatenate([lb, bl])
    if sense is None:
        sense = np.zeros(upper.size, dtype=np.int32)
    try:
        z, _, flag, info = daqp.solve(H, f, A, upper, lower, sense)
    except Exception:
        return QPResult(np.full(n, np.nan), QPStatus.FAILED, 0)
    it = int(info.get("iterations", 0))
    if flag == -1:
        return QPResult(np.full(n, np.nan), QPStatus.INFEASIBLE, it)
    if flag < 0 or not np.all(np.isfinite(z)):
        return QPResult(np.full(n, np.nan), QPStatus.FAILED, it)
    lam = np.asarray(info.get("lam", np.zeros(upper.size)))
    active = (np.abs(lam) > 0).astype(np.int32)
    return QPResult(np.asarray(z, dtype=float), QPStatus.OPTIMAL, it, active=active)


def solve_qcqp_clarabel(
    H: NDArray[np.float64], f: NDArray[np.float64], lb: NDArray[np.float64], ub: NDArray[np.float64],
    A: NDArray[np.float64], bl: NDArray[np.float64], bu: NDArray[np.float64],
    S: NDArray[np.float64], c: NDArray[np.float64], G: NDArray[np.float64],
    soft_penalty: float | None = None, radius: float = 1.0,
) -> QPResult:
    """Exact QP + one ellipsoid ``‖Lᵀ(c + Gz)‖ ≤ radius + σ`` (``S = L Lᵀ``) with Clarabel.

    σ ≡ 0 for the hard problem. The soft problem adds ``soft_penalty · σ``, σ ≥ 0: the exact L1
    penalty of the ellipsoid in its norm form, which (unlike a slack on the squared level) stays
    well scaled when the terminal state is far outside the set.
    """
    import clarabel
    from scipy import sparse

    n = f.size
    soft = soft_penalty is not None
    nz = n + 1 if soft else n
    Lt = np.linalg.cholesky(S).T  # S = L Lᵀ → xᵀSx = ‖Lᵀx‖²
    m = c.size
    Pm = np.zeros((nz, nz))
    Pm[:n, :n] = H
    q = np.zeros(nz)
    q[:n] = f
    if soft_penalty is not None:  # (soft)
        q[n] = float(soft_penalty)

    rows: list[NDArray[np.float64]] = []
    rhs: list[NDArray[np.float64]] = []
    eye = np.eye(nz)[:n]
    # Nonnegative cone rows: b − A z ≥ 0.
    fin_u, fin_l = ub < _INF / 2, lb > -_INF / 2
    rows += [eye[fin_u], -eye[fin_l]]
    rhs += [ub[fin_u], -lb[fin_l]]
    Az = np.zeros((A.shape[0], nz))
    Az[:, :n] = A
    fu, fl = bu < _INF / 2, bl > -_INF / 2
    rows += [Az[fu], -Az[fl]]
    rhs += [bu[fu], -bl[fl]]
    if soft:
        e = np.zeros((1, nz))
        e[0, n] = -1.0  # σ ≥ 0
        rows.append(e)
        rhs.append(np.zeros(1))
    A_nn = np.vstack(rows)
    b_nn = np.concatenate(rhs)
    # Second-order cone: s = (1 + σ, Lᵀx) with x = c + G z, i.e. ‖Lᵀx‖ ≤ 1 + σ.
    Gz = np.zeros((m, nz))
    Gz[:, :n] = G
    A_soc = np.zeros((m + 1, nz))
    b_soc = np.zeros(m + 1)
    b_soc[0] = radius
    A_soc[1:] = -Lt @ Gz
    b_soc[1:] = Lt @ c
    if soft:
        A_soc[0, n] = -1.0
    Aall = sparse.csc_matrix(np.vstack([A_nn, A_soc]))
    ball = np.concatenate([b_nn, b_soc])
    # (defined in clarabel's compiled module, which has no type information)
    settings = clarabel.DefaultSettings()  # pyright: ignore[reportAttributeAccessIssue]
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-9
    settings.tol_feas = 1e-9
    cones = [clarabel.NonnegativeConeT(A_nn.shape[0]),  # pyright: ignore[reportAttributeAccessIssue]
             clarabel.SecondOrderConeT(m + 1)]  # pyright: ignore[reportAttributeAccessIssue]
    try:
        solver = clarabel.DefaultSolver(  # pyright: ignore[reportAttributeAccessIssue]
            sparse.triu(sparse.csc_matrix(Pm)).tocsc(), q, Aall, ball, cones, settings)
        sol = solver.solve()
    except Exception:
        return QPResult(np.full(n, np.nan), QPStatus.FAILED, 0)
    status = str(sol.status)
    z = np.asarray(sol.x, dtype=float)
    if "Infeasible" in status:
        return QPResult(np.full(n, np.nan), QPStatus.INFEASIBLE, int(sol.iterations))
    if not status.startswith(("Solved", "AlmostSolved")) or not np.all(np.isfinite(z)):
        return QPResult(np.full(n, np.nan), QPStatus.FAILED, int(sol.iterations))
    return QPResult(z[:n], QPStatus.OPTIMAL, int(sol.iterations), slack=float(z[n]) if soft else 0.0)
