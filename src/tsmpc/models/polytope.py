"""Scheduling boxes, TS membership functions and vertex enumeration (paper eq. "weighting
function"; the paper's kinematic model). One implementation shared by the kinematic and dynamic TS models.

Vertex ordering (documented once, used everywhere): with r premise variables, vertex ``i`` has
the binary digits ``b_0 … b_{r-1}`` of ``i`` with ``b_0`` the *most* significant bit, and premise
``j`` sits at its lower bound when ``b_j = 0`` and at its upper bound when ``b_j = 1``
(``itertools.product`` order). The membership of vertex ``i`` is
``μ_i = Π_j (η0_j if b_j = 0 else η1_j)`` with ``η0_j = (z̄_j − z_j)/(z̄_j − z̲_j)``, ``η1_j = 1 − η0_j``.

Because the memberships are multilinear interpolation weights, ``Σ μ_i(z) f(z_i) = f(z)`` exactly
for every function ``f`` that is multilinear in the premises; the TS models choose their premises
so that their matrices are (affine or multilinear), which makes the TS form exact.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.errors import ConfigError

__all__ = ["SchedulingBox"]


@dataclass(frozen=True)
class SchedulingBox:
    """Axis-aligned box of r premise variables.

    Attributes:
        names: premise names, length r.
        lower: lower bounds, shape (r,), ``lower < upper``.
        upper: upper bounds, shape (r,).
    """

    names: tuple[str, ...]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    _bits: NDArray[np.bool_] = field(init=False, repr=False, compare=False)

    def __init__(
        self, names: Sequence[str], lower: ArrayLike, upper: ArrayLike
    ) -> None:
        lo = np.asarray(lower, dtype=float).reshape(-1)
        hi = np.asarray(upper, dtype=float).reshape(-1)
        if not (len(names) == lo.size == hi.size):
            raise ConfigError("SchedulingBox: names, lower and upper must have the same length")
        if not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) or np.any(lo >= hi):
            raise ConfigError(f"SchedulingBox: need finite lower < upper, got {lo} and {hi}")
        lo.setflags(write=False)
        hi.setflags(write=False)
        r = lo.size
        idx = np.arange(2**r)[:, None]
        bits = ((idx >> (r - 1 - np.arange(r))[None, :]) & 1).astype(bool)
        bits.setflags(write=False)
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        object.__setattr__(self, "_bits", bits)

    @property
    def n_premises(self) -> int:
        """r."""
        return self.lower.size

    @property
    def n_vertices(self) -> int:
        """2^r."""
        return 2**self.n_premises

    @property
    def vertex_bits(self) -> NDArray[np.bool_]:
        """(2^r, r) booleans: True where the vertex takes the upper bound."""
        return self._bits

    def vertices(self) -> NDArray[np.float64]:
        """(2^r, r) premise values at the vertices, in the documented order."""
        return np.where(self._bits, self.upper, self.lower)

    def contains(self, z: ArrayLike, tol: float = 0.0) -> NDArray[np.bool_]:
        """(...,) True where every premise of ``z`` (..., r) lies in the box (± tol)."""
        z = np.asarray(z, dtype=float)
        return np.all((z >= self.lower - tol) & (z <= self.upper + tol), axis=-1)

    def clip(self, z: ArrayLike) -> tuple[NDArray[np.float64], int]:
        """Clip ``z`` (..., r) into the box; also return how many points were outside."""
        z = np.asarray(z, dtype=float)
        zc = np.clip(z, self.lower, self.upper)
        n_out = int(np.count_nonzero(np.any(zc != z, axis=-1)))
        return zc, n_out

    def memberships(self, z: ArrayLike) -> NDArray[np.float64]:
        """Memberships μ (..., 2^r) of premise values ``z`` (..., r).

        Values outside the box are clipped first (use :meth:`clip` to count them), so μ ≥ 0 and
        Σ μ = 1 always hold.
        """
        zc = np.clip(np.asarray(z, dtype=float), self.lower, self.upper)
        eta1 = (zc - self.lower) / (self.upper - self.lower)  # (..., r)
        eta0 = 1.0 - eta1
        # (..., 2^r, r): pick η1 where the vertex bit is set, then multiply over premises.
        w = np.where(self._bits, eta1[..., None, :], eta0[..., None, :])
        return np.prod(w, axis=-1)

    def blend(self, mu: ArrayLike, vertex_values: ArrayLike) -> NDArray[np.float64]:
        """Σ_i μ_i V_i for memberships (..., 2^r) and vertex values (2^r, *shape)."""
        mu = np.asarray(mu, dtype=float)
        v = np.asarray(vertex_values, dtype=float)
        return np.tensordot(mu, v, axes=([-1], [0]))
