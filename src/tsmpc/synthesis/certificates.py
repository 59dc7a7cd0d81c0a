"""Numerical certificates of LMI designs (SPEC §6): every LMI is recomputed with numpy after the
solve, never trusting a solver status. A certificate's ``margin`` is the largest eigenvalue of a
matrix that must be negative definite; it holds when the margin is strictly negative."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from tsmpc.errors import CertificateError

__all__ = ["Certificate", "check", "neg_def_margin"]


@dataclass(frozen=True)
class Certificate:
    """One recomputed LMI: ``margin`` = λ_max of a matrix that must be ≺ 0."""

    name: str
    margin: float

    @property
    def holds(self) -> bool:
        """True when the margin is strictly negative."""
        return bool(self.margin < 0.0)


def neg_def_margin(M: ArrayLike) -> float:
    """λ_max of the symmetric part of M (negative ⇔ M ≺ 0)."""
    M = np.asarray(M, dtype=float)
    return float(np.max(np.linalg.eigvalsh(0.5 * (M + M.swapaxes(-1, -2)))))


def check(certs: Iterable[Certificate], what: str = "design") -> None:
    """Raise :class:`CertificateError` listing every certificate that does not hold."""
    bad = [c for c in certs if not c.holds]
    if bad:
        lines = ", ".join(f"{c.name} (margin {c.margin:.3g})" for c in bad[:8])
        more = f" and {len(bad) - 8} more" if len(bad) > 8 else ""
        raise CertificateError(f"{what}: certificate(s) violated: {lines}{more}")
