"""The stiffness hand-over in the cascade as one block (issue 34): at an MPC step, the course
fusion's fitted lateral model — the axle stiffnesses, and once the joint lateral fit is ready the
yaw inertia and the CoG too — reaches the MHE-UIO's window model and the TS-LQR's reference gain.

:func:`stiffness_block`: the fusion's decision (:func:`tsmpc.estimation.fusion.stiffness_update`:
give them when any moved by over 1 % against those given, or none was given yet; when they
replace given ones, the slip fit's gain κ restarts) and, when it gives them, (Ĉ_f, Ĉ_r, Î_z, â, b̂)
into the MHE's parameters (``mp``: :data:`MP_CF` … :data:`MP_B`), the TS-LQR law's (``prm``:
:data:`PRM_I` … :data:`PRM_B`) and the record of those given (``sa``: slots ``SA_*``).
:func:`give_model` writes the five parameter slots (the estimators' own
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

__all__ = [
    "MP_A", "MP_B", "MP_CF", "MP_CR", "MP_I", "N_SA", "PRM_A", "PRM_B", "PRM_CF", "PRM_CR", "PRM_I", "SA_A",
    "SA_B", "SA_CF", "SA_CR", "SA_HAS", "SA_I", "give_model", "stiffness_block",
]

#: The record of the lateral model given: [given (1.0) or not (0.0), C_f, C_r, I_z, a, b].
SA_HAS, SA_CF, SA_CR, SA_I, SA_A, SA_B = 0, 1, 2, 3, 4, 5
N_SA = 6
#: I_z, C_f, C_r, a, b in the MHE's parameters (tsmpc.kernels.mhe's MP_I …; tests/test_stiffness_block.py
#: checks they agree: importing the kernels here would bring numba in with the estimator) and in
#: the TS-LQR law's ``prm`` = [M, I, C_f, C_r, a, b, μ_o g, d].
MP_I, MP_CF, MP_CR, MP_A, MP_B = 22, 23, 24, 25, 26
PRM_I, PRM_CF, PRM_CR, PRM_A, PRM_B = 1, 2, 3, 4, 5


@jitable
def give_model(prm: NDArray[np.float64], i_i: int, i_f: int, i_r: int, i_a: int, i_b: int, C_f: float,
               C_r: float, inertia: float, a: float, b: float) -> None:
    """The lateral model (C_f, C_r, I_z, a, b) into the parameter slots ``i_*`` of ``prm``."""
    prm[i_i], prm[i_f], prm[i_r], prm[i_a], prm[i_b] = inertia, C_f, C_r, a, b


@jitable
def stiffness_block(p: CourseParams, s: CourseState, sa: NDArray[np.float64] | list[float],
                    mp: NDArray[np.float64], prm: NDArray[np.float64]) -> tuple[bool, CourseState]:
    """An MPC step's hand-over: the fitted lateral model against the one given (``sa``: an array in
    compiled code, the cascade's list of floats), into the MHE's ``mp``, the TS-LQR's ``prm`` and
    ``sa`` when the fusion gives it: (given, the course state after it — κ restarted when it
    replaced a given one). A plain tuple: a NamedTuple costs the cascade ≈ 0.2 µs a call."""
    give, cf, cr, ii, aa, bb, s = stiffness_update(p, s, sa[SA_HAS] != 0.0, sa[SA_CF], sa[SA_CR], sa[SA_I],
                                                   sa[SA_A])
    if give:
        give_model(mp, MP_I, MP_CF, MP_CR, MP_A, MP_B, cf, cr, ii, aa, bb)
        give_model(prm, PRM_I, PRM_CF, PRM_CR, PRM_A, PRM_B, cf, cr, ii, aa, bb)
        sa[SA_HAS], sa[SA_CF], sa[SA_CR], sa[SA_I], sa[SA_A], sa[SA_B] = 1.0, cf, cr, ii, aa, bb
    return give, s
