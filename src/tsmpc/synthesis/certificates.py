"""Numerical certificates of LMI designs (SPEC §6): every LMI is recomputed with numpy after the
solve, never trusting a solver status.

A certificate reports two numbers for a matrix ``M`` that must be negative definite:

* ``margin`` — λ_max(M), in the units of the LMI (negative when it holds);
* ``relative`` — the same, relative to the LMI's own scale: λ_max(S^{-1/2} M S^{-1/2}) for the
  positive definite scale S of that LMI (the Lyapunov matrix for a decrease condition, the input
  bound for an input constraint). It is invariant to how states and inputs are scaled, so one
  threshold fits every design.

A certificate *holds* when ``relative <= -MIN_RELATIVE_MARGIN``: a margin 100× the SDP solvers'
tolerance (≈ 1e-8), so neither a solver's last iterate nor a different BLAS kernel (another CPU,
another thread count) can flip it. The designs impose a larger margin in the SDP itself
(:data:`TARGET_MARGIN`) for the same reason.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.errors import CertificateError

__all__ = [
    "MIN_RELATIVE_MARGIN",
    "TARGET_MARGIN",
    "Certificate",
    "check",
    "consistency_certificate",
    "definite_certificate",
    "lmi_certificate",
    "neg_def_margin",
    "relative_margin",
    "worst",
]

#: Smallest relative margin a certificate must have: 100× the SDP solvers' tolerance (1e-8).
MIN_RELATIVE_MARGIN = 1e-6
#: Relative margin the SDPs impose on every LMI (decrease, invariance, input bound): 100× the
#: certificate threshold, so a design perturbed by 1e-7 (relative) still certifies.
TARGET_MARGIN = 1e-4


@dataclass(frozen=True)
class Certificate:
    """One recomputed condition ``M ≺ 0``.

    Attributes:
        name: what was checked (LMI and vertex / grid point).
        margin: λ_max(M), absolute (units of the LMI).
        relative: λ_max of M relative to the LMI's scale (dimensionless).
    """

    name: str
    margin: float
    relative: float

    @property
    def holds(self) -> bool:
        """True when the relative margin is at least :data:`MIN_RELATIVE_MARGIN` below zero."""
        return bool(self.margin < 0.0 and self.relative <= -MIN_RELATIVE_MARGIN)


def _sym(M: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * (M + np.swapaxes(M, -1, -2))


def neg_def_margin(M: ArrayLike) -> float:
    """λ_max of the symmetric part of M (negative ⇔ M ≺ 0)."""
    return float(np.max(np.linalg.eigvalsh(_sym(np.asarray(M, dtype=float)))))


def relative_margin(M: ArrayLike, S: ArrayLike) -> float:
    """λ_max(S^{-1/2} M S^{-1/2}) for symmetric M and positive definite S (generalised eigenvalue;
    +inf when S is not positive definite)."""
    M, S = _sym(np.asarray(M, dtype=float)), _sym(np.asarray(S, dtype=float))
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        return float("inf")
    Li = np.linalg.inv(L)
    return float(np.max(np.linalg.eigvalsh(_sym(Li @ M @ Li.T))))


def lmi_certificate(name: str, M: ArrayLike, scale: ArrayLike) -> Certificate:
    """Certificate of ``M ≺ 0`` relative to the positive definite ``scale``."""
    M = np.asarray(M, dtype=float)
    if not np.all(np.isfinite(M)):
        return Certificate(name, float("inf"), float("inf"))
    return Certificate(name, neg_def_margin(M), relative_margin(M, scale))


def definite_certificate(name: str, X: ArrayLike) -> Certificate:
    """Certificate of ``X ≻ 0``: margin −λ_min, relative −λ_min/λ_max (inverse condition number)."""
    X = np.asarray(X, dtype=float)
    if not np.all(np.isfinite(X)):
        return Certificate(name, float("inf"), float("inf"))
    ev = np.linalg.eigvalsh(_sym(X))
    return Certificate(name, float(-ev[0]), float(-ev[0] / max(abs(ev[-1]), 1e-300)))


def consistency_certificate(name: str, error: float, tol: float) -> Certificate:
    """A stored matrix agrees with what it is derived from: ``error`` below ``tol``
    (margin error − tol, relative error/tol − 1)."""
    if not np.isfinite(error):
        return Certificate(name, float("inf"), float("inf"))
    return Certificate(name, float(error - tol), float(error / tol - 1.0))


def worst(certs: Iterable[Certificate]) -> Certificate:
    """The certificate with the largest (least negative) relative margin."""
    return max(certs, key=lambda c: c.relative)


def check(certs: Iterable[Certificate], what: str = "design") -> None:
    """Raise :class:`CertificateError` listing every certificate that does not hold."""
    bad = sorted((c for c in certs if not c.holds), key=lambda c: -c.relative)
    if bad:
        lines = ", ".join(f"{c.name} (margin {c.margin:.3g}, relative {c.relative:.3g})"
                          for c in bad[:8])
        more = f" and {len(bad) - 8} more" if len(bad) > 8 else ""
        raise CertificateError(
            f"{what}: certificate(s) violated (a relative margin <= -{MIN_RELATIVE_MARGIN:g} is "
            f"required): {lines}{more}")
