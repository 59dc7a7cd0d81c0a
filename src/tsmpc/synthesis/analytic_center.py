"""The analytic centre of a system of LMIs: the point a feasibility problem's
interior-point solver converges to when the problem has no objective.

For affine symmetric matrix functions ``M_k(x) = F0_k + Σ_j x_j F_kj`` (k = 1 … m) the analytic
centre is the minimiser of the log-det barrier

    φ(x) = − Σ_k log det M_k(x)        over {x : M_k(x) ≻ 0 for every k}

(Boyd & Vandenberghe, *Convex Optimization*, §8.5.3). On a problem without objective every
point of a primal-dual interior-point method's central path is this point, so it is what such a
solver tends to when it is run to convergence — a canonical "interior point" of the feasible set.
It does not depend on the units the LMIs are written in: a change of variables x = T z and a
congruence M_k → S_k M_k S_kᵀ with constant invertible T, S_k change φ by a constant only.

:func:`analytic_center` computes it by Newton's method with a backtracking line search from a
strictly feasible start (the barrier is self-concordant: the damped iteration converges from
anywhere in the interior, quadratically near the centre). numpy only; no solver involved.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tsmpc.errors import SolverError

__all__ = ["AffineLMI", "CenterResult", "analytic_center", "log_det_barrier"]


@dataclass(frozen=True)
class AffineLMI:
    """``M(x) = F0 + Σ_j x_j F[j] ≻ 0``: ``F0`` (d, d) symmetric, ``F`` (n_x, d, d) symmetric."""

    F0: NDArray[np.float64]
    F: NDArray[np.float64]

    def at(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """M(x) (d, d)."""
        return self.F0 + np.tensordot(x, self.F, axes=(0, 0))


@dataclass(frozen=True)
class CenterResult:
    """Newton's answer: the centre ``x``, the iterations taken and the final Newton decrement
    λ(x)² = ∇φᵀ ∇²φ⁻¹ ∇φ (λ²/2 bounds φ(x) − φ(x*) near the centre)."""

    x: NDArray[np.float64]
    iterations: int
    decrement_sq: float


def log_det_barrier(lmis: Sequence[AffineLMI], x: NDArray[np.float64]) -> float:
    """φ(x) = −Σ log det M_k(x); +inf when some M_k(x) is not positive definite."""
    val = 0.0
    for lmi in lmis:
        try:
            L = np.linalg.cholesky(lmi.at(x))
        except np.linalg.LinAlgError:
            return float("inf")
        val -= 2.0 * float(np.sum(np.log(np.diag(L))))
    return val


def _gradient_hessian(lmis: Sequence[AffineLMI], x: NDArray[np.float64]
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """∇φ_j = −Σ_k tr(M_k⁻¹ F_kj), ∇²φ_ij = Σ_k tr(M_k⁻¹ F_ki M_k⁻¹ F_kj)."""
    n = x.size
    g = np.zeros(n)
    H = np.zeros((n, n))
    for lmi in lmis:
        L = np.linalg.cholesky(lmi.at(x))
        Li = np.linalg.inv(L)
        G = Li @ lmi.F @ Li.T  # L⁻¹ F_j L⁻ᵀ: symmetric, tr(M⁻¹F_i M⁻¹F_j) = ⟨G_i, G_j⟩
        Gf = G.reshape(n, -1)
        g -= np.einsum("jii->j", G)
        H += Gf @ Gf.T
    return g, H


def analytic_center(lmis: Sequence[AffineLMI], x0: NDArray[np.float64], *, tol: float = 1e-12,
                    max_iter: int = 100) -> CenterResult:
    """The analytic centre of ``lmis`` by damped Newton from the strictly feasible ``x0``.

    Stops when λ²/2 ≤ ``tol``. Raises :class:`SolverError` when ``x0`` is not strictly feasible,
    when the barrier has no minimiser (an unbounded feasible set: a singular Hessian or a step
    without end) or when ``max_iter`` iterations do not converge.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    f = log_det_barrier(lmis, x)
    if not np.isfinite(f):
        raise SolverError("analytic centre: the start point is not strictly feasible")
    lam2 = float("inf")
    for it in range(1, max_iter + 1):
        g, H = _gradient_hessian(lmis, x)
        try:
            dx = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            raise SolverError("analytic centre: singular barrier Hessian (the feasible set is "
                              "unbounded or has no interior)") from None
        lam2 = float(-g @ dx)
        if not np.isfinite(lam2):
            raise SolverError("analytic centre: non-finite Newton step")
        if lam2 / 2.0 <= tol:
            return CenterResult(x, it - 1, lam2)
        step = 1.0
        while True:  # backtracking (Armijo 1/4, halving): stays strictly feasible
            f_new = log_det_barrier(lmis, x + step * dx)
            if f_new <= f - 0.25 * step * lam2:
                break
            step *= 0.5
            if step < 1e-12:
                raise SolverError("analytic centre: the line search stalled")
        x = x + step * dx
        f = f_new
    raise SolverError(f"analytic centre: no convergence in {max_iter} Newton steps "
                      f"(λ² = {lam2:.3g})")
