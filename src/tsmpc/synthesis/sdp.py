"""Solving the design SDPs (the paper's LMI designs): solver choice, failures as :class:`SolverError`, and the
margin ladder that makes every certificate hold with a margin no solver tolerance can flip.

Each design poses its LMIs with a *relative margin* ``t`` built into the SDP (a decrease
condition ``A_clᵀ P A_cl − P + … ⪯ −t P`` is imposed as the Schur form with ``(1 − t) Y`` in
place of ``Y``; see the design modules). :func:`solve_with_margin` tries :data:`TARGET_MARGIN`
first; when the SDP is infeasible there it steps down (never below :data:`LADDER_FLOOR`, still
≥ 3× the certificate threshold); when the numpy certificates miss the threshold (an inaccurate
solver answer) it steps *up* — a stricter margin — and solves again. A solver status other than
"optimal" is accepted only through the certificates.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from enum import StrEnum
from typing import TYPE_CHECKING, Any, TypeVar

from tsmpc.errors import SolverError
from tsmpc.synthesis.certificates import TARGET_MARGIN, Certificate

if TYPE_CHECKING:  # cvxpy and numpy's types are imported where a problem is solved
    import numpy as np
    from cvxpy import Variable
    from numpy.typing import NDArray

__all__ = ["LADDER_DOWN", "LADDER_UP", "Infeasible", "SDPSolver", "solve", "solve_with_margin", "values"]

#: Margins tried, in order, while the SDP is infeasible (relative; the certificate threshold is 1e-6).
LADDER_DOWN = (TARGET_MARGIN, 1e-5, 3e-6)
LADDER_FLOOR = LADDER_DOWN[-1]
#: Stricter margins tried when the certificates of a feasible answer miss the threshold.
LADDER_UP = (4 * TARGET_MARGIN, 16 * TARGET_MARGIN)

T = TypeVar("T")


class SDPSolver(StrEnum):
    """SDP solver of the designs (through cvxpy). Clarabel is the default; SCS (first-order,
    looser) serves as the independent second solver of the machine-independence test."""

    CLARABEL = "CLARABEL"
    SCS = "SCS"


#: Solver options: Clarabel's defaults; SCS asked for far more accuracy than its default 1e-4, with
#: over-relaxation 1.8 (its default 1.5): the kinematic design's first answer then certifies, one
#: 100k-iteration solve of the LQR-LMI instead of two (measured 35.6 → 18.3 s of CPU).
_OPTIONS: dict[SDPSolver, dict[str, Any]] = {
    SDPSolver.CLARABEL: {},
    SDPSolver.SCS: {"eps_abs": 1e-6, "eps_rel": 1e-6, "max_iters": 100_000, "alpha": 1.8},
}


class Infeasible(Exception):  # internal control flow of the ladder, never escapes
    """The SDP has no solution at this margin (or the solver could not find one)."""

    def __init__(self, status: str) -> None:
        super().__init__(status)
        self.status = status


def solve(prob: Any, solver: SDPSolver | str, what: str, options: dict[str, Any] | None = None) -> str:
    """Solve a cvxpy problem; returns its status. Any solver exception (a crash, NaN/inf in the
    data) becomes :class:`SolverError` naming ``what``; an infeasible or unsolved problem raises
    :class:`Infeasible`. ``options`` are added to the solver's defaults of this module."""
    import cvxpy as cp
    from cvxpy import error as cp_error  # (not an attribute of cvxpy for a type checker)

    s = SDPSolver(str(solver).upper())
    try:
        with warnings.catch_warnings():  # the status is reported; certificates decide
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=getattr(cp, s.value), **{**_OPTIONS[s], **(options or {})})
    except cp_error.SolverError as exc:
        raise Infeasible(f"{s.value} failed ({exc})") from None
    except (ValueError, ArithmeticError, OverflowError) as exc:  # NaN/inf in the problem data
        raise SolverError(f"{what}: invalid problem data ({exc})") from None
    if prob.status not in ("optimal", "optimal_inaccurate"):
        raise Infeasible(str(prob.status))
    return str(prob.status)


def solve_with_margin(
    attempt: Callable[[float], T],
    certify: Callable[[T], list[Certificate]],
    what: str,
    ladder: tuple[float, ...] = LADDER_DOWN,
) -> tuple[T, list[Certificate], float]:
    """Run ``attempt(margin)`` along the ladder until ``certify`` says every certificate holds.

    Returns (design, certificates, margin imposed). Raises :class:`Infeasible` (with the last
    status) when no margin of ``ladder`` (default :data:`LADDER_DOWN`) is feasible, and
    ``CertificateError`` (from :func:`~tsmpc.synthesis.certificates.check`, listing the first
    feasible answer's failures) when feasible answers never certify at any margin of either
    ladder.
    """
    from tsmpc.synthesis.certificates import check

    # Each margin is solved and certified at most once: the stricter margins of LADDER_UP are the
    # same after every step down, and a solver's answer to the same problem does not change (a
    # design that fails everywhere otherwise solved them again for each step: 9 SDPs, not 5).
    tried: dict[float, tuple[T, list[Certificate]] | Infeasible] = {}

    def outcome(t: float) -> tuple[T, list[Certificate]] | Infeasible:
        if t not in tried:
            try:
                design = attempt(t)
            except Infeasible as exc:
                tried[t] = exc
            else:
                tried[t] = (design, certify(design))
        return tried[t]

    last: Infeasible | None = None
    failed: list[Certificate] | None = None  # certificates of the first feasible, failing answer
    for t in ladder:
        res = outcome(t)
        if isinstance(res, Infeasible):
            last = res
            continue
        design, certs = res
        if all(c.holds for c in certs):
            return design, certs, t
        failed = failed or certs
        for t_up in (u for u in LADDER_UP if u > t):  # inaccurate answer: a stricter margin
            res_up = outcome(t_up)
            if isinstance(res_up, Infeasible):
                break
            design_up, certs_up = res_up
            if all(c.holds for c in certs_up):
                return design_up, certs_up, t_up
    if failed is not None:
        check(failed, what)  # raises, listing what failed at the first feasible margin
    assert last is not None
    raise last


def values(xs: list[Variable]) -> list[NDArray[np.float64]] | None:
    """The solved variables' values, None when the solver left one unset."""
    out = []
    for x in xs:
        if x.value is None:
            return None
        out.append(x.value)
    return out
