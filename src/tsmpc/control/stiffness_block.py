"""The stiffness hand-over in the cascade as one block (issue 34): at an MPC step, the course
fusion's fitted axle stiffnesses reach the MHE-UIO's window model and the TS-LQR's reference gain.

:func:`stiffness_block`: the fusion's decision (:func:`tsmpc.estimation.fusion.stiffness_update`:
give them when both moved by over 1 % against those given, or none was given yet; when they
replace given ones, the slip fit's gain κ restarts) and, when it gives them, (Ĉ_f, Ĉ_r) into the
MHE's parameters (``mp``'s C_f, C_r: :data:`MP_CF`, :data:`MP_CR`), the TS-LQR law's (``prm``'s:
:data:`PRM_CF`, :data:`PRM_CR`) and the record of those given (``sa``: slots ``SA_*``).
:func:`give_stiffness` writes a pair of parameter slots (the estimators' own
``set_cornering_stiffness`` use it too).

One definition, three callers: :class:`~tsmpc.control.cascade.Cascade` calls it as Python (it is
one call per MPC step, over records the cascade holds), the run engine
(``tsmpc.kernels.engine.run``) and the batch compile it into their step. The Python objects around
the arrays — the estimators' vehicle and numpy models (their slow paths), the steering-offset fit's
balance — follow the record ``sa`` (the cascade: ``MHEUIO.model_stiffness``,
``TSLQR.model_stiffness``, ``Fusion.set_stiffness``; the engine reads ``sa`` where it needs them).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tsmpc.estimation.fusion import CourseParams, CourseState, stiffness_update
from tsmpc.kernels.jit import jitable

__all__ = ["MP_CF", "MP_CR", "N_SA", "PRM_CF", "PRM_CR", "SA_CF", "SA_CR", "SA_HAS", "give_stiffness",
           "stiffness_block"]

#: The record of the stiffnesses given: [given (1.0) or not (0.0), C_f, C_r].
SA_HAS, SA_CF, SA_CR = 0, 1, 2
N_SA = 3
#: C_f, C_r in the MHE's parameters (tsmpc.kernels.mhe's MP_CF, MP_CR; tests/test_stiffness_block.py
#: checks they agree: importing the kernels here would bring numba in with the estimator) and in
#: the TS-LQR law's ``prm`` = [M, I, C_f, C_r, a, b, μ_o g, d].
MP_CF, MP_CR = 23, 24
PRM_CF, PRM_CR = 2, 3


@jitable
def give_stiffness(prm: NDArray[np.float64], i_f: int, i_r: int, C_f: float, C_r: float) -> None:
    """(C_f, C_r) into the parameter slots ``i_f``, ``i_r`` of ``prm``."""
    prm[i_f], prm[i_r] = C_f, C_r


@jitable
def stiffness_block(p: CourseParams, s: CourseState, sa: NDArray[np.float64] | list[float],
                    mp: NDArray[np.float64], prm: NDArray[np.float64]) -> tuple[bool, CourseState]:
    """An MPC step's hand-over: the fitted (Ĉ_f, Ĉ_r) against those given (``sa``: an array in
    compiled code, the cascade's list of floats), into the MHE's ``mp``, the TS-LQR's ``prm`` and
    ``sa`` when the fusion gives them: (given, the course state after it — κ restarted when they
    replaced given ones). A plain tuple: a NamedTuple costs the cascade ≈ 0.2 µs a call."""
    give, cf, cr, s = stiffness_update(p, s, sa[SA_HAS] != 0.0, sa[SA_CF], sa[SA_CR])
    if give:
        give_stiffness(mp, MP_CF, MP_CR, cf, cr)
        give_stiffness(prm, PRM_CF, PRM_CR, cf, cr)
        sa[SA_HAS], sa[SA_CF], sa[SA_CR] = 1.0, cf, cr
    return give, s
