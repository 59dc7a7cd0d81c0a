"""Offset-free outer loop (beyond the paper): the heading error the MPC sees corrected by a
constant-disturbance estimate, integrated from the MPC's own one-step prediction error.

Why. The kinematic error model the TS-MPC predicts with (paper eq. "kinematic model") has
no term for what the loops below it get wrong *at steady state*, and the one that shows is the
course: the car drives a few mrad off the velocity heading θ + α̂ the MPC measures (a slip model
with the wrong stiffness or centre of gravity, a yaw-rate or steering bias the fits have not removed
yet). It leaves a steady lateral offset: like any state feedback without integral action, the MPC
settles where its error weights balance the bias (an LQR's u = −K e settles at K e = −bias).
Measured on the generalisation class (issue 35, paper reference): the default's lateral error there
was mostly such an offset, +1 to +4.5 cm held for tens of seconds, where the oracle-tuned
controller's mean is 0.

Offset-free MPC (Pannocchia & Rawlings 2003; Maeder, Borrelli & Morari 2009) adds a constant
disturbance to the prediction model and estimates it from the prediction error. Here one, a heading
disturbance b [rad] in ė_y = v_d sin(e_θ + b): the car drives b off the heading the MPC sees. The
MPC gets e_θ + b̂, so it steers the *course* onto the path and e_y → 0. Its innovation is the lateral
error against the previous plan's prediction of it, r_y = e_y(k) − x_pred[1]_y (the MPC's own
prediction, made in the corrected coordinates), integrated with gain g = T_c / τ
(``mpc.offset_free_s`` = τ)::

    b̂ ← b̂ + g r_y / (T_c max(v, V_FLOOR))          (v: the MPC's previous speed command)

bounded by ``HEADING_MAX``. At steady state the innovations vanish on average, so the offset does.
Between poses (1–10 Hz) the MPC sees the dead-reckoned pose, whose steps carry no b; the pose that
ends the gap carries it all, so the sum of the updates over the gap is the same (the estimate
ripples within it, which a τ of several seconds smooths). τ sets the trade: a slower one leaves the
offset for longer, a faster one feeds the estimate the MPC's own transients (3 s made a car that
oscillates in yaw diverge; 10 s is the setting measured).

Opt-in (``mpc.offset_free_s`` = 0 by default): the estimate also reacts to what is dynamics, not a
constant offset — an understeering car's corner entry (C_f −40 %) raised the largest lateral error
it lowers elsewhere (docs/design-decisions.md).

The along-track counterpart (a speed disturbance d_v in ė_x, the inner loop sent v + d̂_v) was
measured and left out: it took 5 % off RMSE x on the paper reference but put 3.6 % on RMSE v there
and 5 % on RMSE v and 5–10 % on max |e_y| on the race tracks of the mismatch benchmark.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.kernels.jit import jitable

__all__ = ["HEADING_MAX", "V_FLOOR", "NoOffset", "OffsetFree", "OffsetParams", "offset_update"]

#: Bound of the estimate: a course 0.05 rad (2.9°) off the measured velocity heading is beyond every
#: sensor and model error of the generalisation class (slip-model errors of a few mrad, steering
#: offsets within 1°, which the steering fit takes out); a larger innovation is a transient, not a
#: bias, and the bound keeps it from winding the estimate up.
HEADING_MAX = 0.05
#: Speed below which the update is scaled as at this speed [m/s] (a heading error moves the car
#: sideways in proportion to its speed: at rest the innovation says nothing about b).
V_FLOOR = 1.0


class OffsetParams(NamedTuple):
    """The estimator's constants.

    Attributes:
        gain: T_c / τ, the share of an innovation integrated per MPC step.
        Tc: the MPC's period [s].
    """

    gain: float
    Tc: float


@jitable
def offset_update(p: OffsetParams, b: float, e_y: float, pred_y: float, has_pred: bool, v: float) -> float:
    """One MPC step: the heading disturbance b̂ [rad] after the innovation of the lateral error
    ``e_y`` against the previous plan's prediction of it, ``pred_y`` (none without a previous
    plan); ``v`` the MPC's previous speed command [m/s]. The MPC then gets e_θ + b̂."""
    if not has_pred:
        return b
    r = e_y - pred_y
    if not (math.isfinite(r) and math.isfinite(v)):
        return b
    vs = v if v > V_FLOOR else V_FLOOR
    b = b + p.gain * r / (p.Tc * vs)
    return min(max(b, -HEADING_MAX), HEADING_MAX)


class OffsetFree:
    """A standalone online wrapper of :func:`offset_update` (``mpc.offset_free_s`` > 0): :meth:`correct`
    at each MPC step, before the MPC. The cascade runs :func:`offset_update` inside its outer block
    (:func:`tsmpc.control.outer_block.outer_errors`, the estimate in its state).

    Args:
        Tc: the MPC's period [s].
        time_constant_s: τ [s].
    """

    def __init__(self, Tc: float, time_constant_s: float) -> None:
        self.params = OffsetParams(float(Tc) / float(time_constant_s), float(Tc))
        self.reset()

    def reset(self) -> None:
        """The estimate back to 0."""
        self.heading = 0.0  #: b̂ [rad]

    def correct(self, e: NDArray[np.float64], plan: Any, v: float) -> NDArray[np.float64]:
        """The errors the MPC gets: ``e`` with e_θ + b̂, after the update by the innovation of
        ``e`` against the previous plan's prediction of them (``plan.x_pred[1]``; None: no update)."""
        xp = None if plan is None else plan.x_pred
        if xp is None or len(xp) < 2:
            b = offset_update(self.params, self.heading, float(e[1]), 0.0, False, v)
        else:
            b = offset_update(self.params, self.heading, float(e[1]), float(xp[1][1]), True, v)
        self.heading = b
        out = np.array(e, dtype=float)
        out[2] = out[2] + b
        return out


class NoOffset:
    """``mpc.offset_free_s`` = 0 (the paper): the errors as measured."""

    heading = 0.0

    def reset(self) -> None:
        """Nothing to forget."""

    def correct(self, e: NDArray[np.float64], plan: Any, v: float) -> NDArray[np.float64]:
        """``e`` unchanged."""
        return e
