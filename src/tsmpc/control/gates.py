"""Sample gates and dead reckoning of the cascade (beyond the paper; issue 24): which sensor samples
:class:`~tsmpc.control.cascade.Cascade` accepts, and where the car is between accepted poses.

Each function here is a block's one definition (:mod:`tsmpc.kernels.jit`): the Python cascade
calls it as Python, the run engine and the batch compile it.

* :func:`plausible_speeds`: a finite speed or yaw rate no vehicle of the config can have is
  rejected (NaN passes: the MHE-UIO rejects it and counts it).
* :func:`pose_consistent`: a pose further from the dead-reckoned pose than the car can have
  drifted since the last accepted one — ``POSE_JUMP_M`` + ``POSE_DRIFT_M_PER_S`` per second
  without a pose, plus five noise σ — or a heading off by more than ``HEADING_JUMP_RAD`` +
  ``HEADING_DRIFT_RAD_PER_S`` per second (plus five σ) is a jump, not a measurement.
* :func:`dead_reckon`: between accepted poses the pose advances by one T_d on the estimate
  (v̂, α̂, ω̂): the course is θ + α̂ (paper eq. "kinematic model": Ẋ = v cos(θ + α)).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from tsmpc.kernels.jit import exact_hypot, jitable

__all__ = [
    "HEADING_DRIFT_RAD_PER_S",
    "HEADING_JUMP_RAD",
    "POSE_DRIFT_M_PER_S",
    "POSE_JUMP_M",
    "GateParams",
    "dead_reckon",
    "plausible_speeds",
    "pose_consistent",
]

#: Drift allowed between the dead-reckoned and a measured pose: metres plus metres per second
#: without an accepted pose (dead reckoning on the estimate drifts slowly; a pose jump does not).
POSE_JUMP_M = 1.0
POSE_DRIFT_M_PER_S = 2.0
#: Heading counterpart [rad, rad/s].
HEADING_JUMP_RAD = 0.3
HEADING_DRIFT_RAD_PER_S = 0.5


class GateParams(NamedTuple):
    """Bounds of the gates, from the config (:class:`~tsmpc.control.cascade.Cascade` builds them).

    Attributes:
        v_lo: lowest plausible speed [m/s] (negative by the noise allowance).
        v_hi: highest plausible speed [m/s] (twice every speed bound of the config, plus noise).
        w_limit: largest plausible |yaw rate| [rad/s].
        pose_noise: five position noise σ [m] added to the pose-jump allowance.
        heading_noise: five heading noise σ [rad] added to the heading-jump allowance.
        Td: call period T_d [s] (one dead-reckoning step).
    """

    v_lo: float
    v_hi: float
    w_limit: float
    pose_noise: float
    heading_noise: float
    Td: float


@jitable
def plausible_speeds(p: GateParams, v: float, omega: float) -> bool:
    """False for a finite speed or yaw rate no vehicle of this config can have (NaN: True, the
    MHE rejects it)."""
    if not (math.isfinite(v) and math.isfinite(omega)):
        return True
    return p.v_lo <= v <= p.v_hi and abs(omega) <= p.w_limit


@jitable
def pose_consistent(p: GateParams, X: float, Y: float, theta: float, px: float, py: float, pth: float,
                    dt: float) -> bool:
    """Is the finite pose (X, Y, θ) where the car can be, ``dt`` seconds after the last accepted
    pose, given the dead-reckoned pose (px, py, pth)?"""
    dt = max(dt, 0.0)
    far = exact_hypot(X - px, Y - py) > POSE_JUMP_M + POSE_DRIFT_M_PER_S * dt + p.pose_noise
    dth = (theta - pth + math.pi) % (2.0 * math.pi) - math.pi
    turned = abs(dth) > HEADING_JUMP_RAD + HEADING_DRIFT_RAD_PER_S * dt + p.heading_noise
    return not (far or turned)


@jitable
def dead_reckon(p: GateParams, px: float, py: float, pth: float, v: float, alpha: float,
                omega: float) -> tuple[float, float, float]:
    """The pose one T_d later on the estimate (v̂, α̂, ω̂); unchanged when the estimate is not
    finite. The speed is clipped to [0, v_hi]."""
    if not (math.isfinite(v) and math.isfinite(alpha) and math.isfinite(omega)):
        return px, py, pth
    v = min(max(v, 0.0), p.v_hi)
    heading = pth + alpha
    return (px + v * math.cos(heading) * p.Td, py + v * math.sin(heading) * p.Td,
            pth + omega * p.Td)
