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

The block's glue — what the cascade does with them every T_d — is one definition too:
:func:`gate_block` (the speed gate, the pose gate and the accepted pose written into the block's
pose record, ``PO_*``: X, Y, θ and the last accepted pose's time) and :func:`reckon_block` (the
record advanced by :func:`dead_reckon`). The cascade's phases call them
(:func:`tsmpc.control._front.cascade_front`, :func:`tsmpc.control._back.cascade_back`):
:class:`~tsmpc.control.cascade.Cascade` through :mod:`tsmpc.kernels.blocks` (as Python under
``TSMPC_NO_JIT``), the run engine on its state slots ``SF_POSE`` … ``SF_POSET``, the batch per lane.

Recovery (``[recovery]``, issue 38): whatever came before, a run of valid samples brings the cascade
back —

* :func:`jump_run`: poses rejected as jumps for ``pose_reinit_s``, each consistent with the one
  before, re-initialise the pose (the dead reckoning drifted, not the sensor);
* :func:`blind_stop`: with no speed / yaw-rate sample for ``blind_after_s`` the cascade cannot
  estimate the car any more: it brakes to a stop on its last steering (a minimal-risk manoeuvre)
  instead of driving on a model's open-loop prediction;
* :func:`nearest_sample`: on the first valid sample after a blind stop, the reference time is
  re-anchored at the reference sample nearest to the car, so the car resumes the plan from where it
  stands instead of chasing a reference that went on without it. The gates and the MHE-UIO take
  the new samples at once (the pose gate accepts the first finite pose; the window fills in
  N T_d);
* :func:`speed_bounded_yaw_rate`: on the restart from rest (from the end of the blind stop until the
  car has the reference's speed), the yaw-rate reference the outer loop hands the TS-LQR is bounded
  by the car's speed, |ω| ≤ v tan(δ_max)/L (``yaw_rate_bound``). The kinematic error model of the
  outer loop (paper eq. "kinematic model") treats v and ω as independent inputs, so at rest it can
  turn in place; a car cannot, and a TS-LQR asked to swings the steering to its limit before the car
  rolls, and the car starts off with that heading error. Only on the restart: a moving car asked
  for more than the bound saturates its steering, which is what a large error needs — bounded
  always, the robustness case "initial offset" (2 m, 0.2 rad at 1 m/s) measured max |e_y| 0.34 m
  after its first 5 s, against 0.06 m unbounded (paper reference). Above ω_max L / tan(δ_max)
  (5.4 m/s with the default car) it never binds.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.estimation.fusion import RepeatState, repeat_check
from tsmpc.kernels.jit import exact_hypot, jitable

__all__ = [
    "HEADING_DRIFT_RAD_PER_S",
    "HEADING_JUMP_RAD",
    "N_GBK",
    "POSE_DRIFT_M_PER_S",
    "POSE_JUMP_M",
    "GateBlockParams",
    "GateParams",
    "blind_stop",
    "dead_reckon",
    "gate_block",
    "jump_run",
    "nearest_sample",
    "pack_gate_block",
    "plausible_speeds",
    "pose_consistent",
    "pose_gate",
    "reckon_block",
    "speed_bounded_yaw_rate",
    "speed_gate",
    "unpack_gate_block",
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


class GateBlockParams(NamedTuple):
    """The sample gates' block (:func:`speed_gate`, :func:`pose_gate`) as the cascade composes it.

    Attributes:
        gates: the bounds.
        recovery: a run of consistent jump rejections may re-initialise the pose (``recovery``).
        reinit_s: how long that run must last [s] (``recovery.pose_reinit_s``).
        repeat: a sample equal to the previous one is missing (``fusion.reject_repeated_samples``).
    """

    gates: GateParams
    recovery: bool
    reinit_s: float
    repeat: bool


#: Length of :func:`pack_gate_block`'s vector (GateParams' 6 fields, then recovery, reinit_s, repeat).
N_GBK = 9


def pack_gate_block(p: GateBlockParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_gate_block` reads (compiled callers rebuild it:
    the run engine's parameter slots)."""
    return np.array([*p.gates, p.recovery, p.reinit_s, p.repeat], dtype=np.float64)


@jitable
def unpack_gate_block(a: NDArray[np.float64]) -> GateBlockParams:
    """The record of :func:`pack_gate_block`'s vector."""
    return GateBlockParams(GateParams(a[0], a[1], a[2], a[3], a[4], a[5]), a[6] != 0.0, a[7], a[8] != 0.0)


#: The gate block's state slots (a float vector): the pose gate owes the next pose (after a blind
#: stop), the run of jump rejections (its start, NaN: none; the last rejected pose and its time),
#: the repeat guard's previous sample (RepeatState).
(GS_FREE, GS_JT0, GS_JX, GS_JY, GS_JTH, GS_JT,
 GS_RHAS, GS_RX, GS_RY, GS_RTH, GS_RV, GS_RW, GS_RSTAMP) = range(13)
N_GS = 13
#: Its event counters: implausible speeds, repeated samples, non-finite fresh poses, poses taken
#: after a run of jumps, poses rejected as jumps.
GC_SPEED, GC_REPEATED, GC_NAN, GC_REINIT, GC_JUMP = range(5)
N_GC = 5
#: The pose the block keeps (a float vector; the run engine's SF_POSE … SF_POSET): the last accepted
#: pose or, after it, the dead-reckoned one (X, Y, θ), and the time of the last accepted pose.
PO_X, PO_Y, PO_TH, PO_T = range(4)
N_PO = 4


def gate_state() -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(state, counters) of the gate block at the start: no run, no previous sample."""
    gs = np.zeros(N_GS)
    gs[GS_JT0:GS_JT + 1] = np.nan
    gs[GS_RSTAMP] = -np.inf
    return gs, np.zeros(N_GC, dtype=np.int64)


@jitable
def speed_gate(p: GateParams, cnt: NDArray[np.int64], v: float, omega: float) -> bool:
    """:func:`plausible_speeds`, an implausible sample counted."""
    if plausible_speeds(p, v, omega):
        return True
    cnt[GC_SPEED] += 1
    return False


@jitable
def pose_gate(p: GateBlockParams, gs: NDArray[np.float64], cnt: NDArray[np.int64], t: float, fresh: bool,
              X: float, Y: float, theta: float, v: float, omega: float, stamp: float, has_pose: bool,
              px: float, py: float, pth: float, pose_t: float) -> tuple[bool, bool]:
    """(fresh, the pose is accepted) of a sample (X, Y, θ, v, ω, its stamp; −inf: none) at time
    ``t``: a sample equal to the previous one is not fresh (a stalled bus re-delivering it: missing,
    like NaN); a fresh finite pose is accepted when the gate owes one (``has_pose`` False: the
    first; or after a blind stop) or it is consistent with the dead-reckoned pose (px, py, pth)
    ``t − pose_t`` after the last accepted one (:func:`pose_consistent`), or — ``recovery`` — it ends
    a run of consistent jump rejections (:func:`jump_run`). Counted in ``cnt``."""
    if p.repeat:
        same, r = repeat_check(RepeatState(gs[GS_RHAS] != 0.0, gs[GS_RX], gs[GS_RY], gs[GS_RTH], gs[GS_RV],
                                           gs[GS_RW], gs[GS_RSTAMP]), X, Y, theta, v, omega, stamp)
        gs[GS_RHAS], gs[GS_RX], gs[GS_RY], gs[GS_RTH] = 1.0 if r.has else 0.0, r.X, r.Y, r.theta
        gs[GS_RV], gs[GS_RW], gs[GS_RSTAMP] = r.v, r.omega, r.stamp
        if same:
            fresh = False
            cnt[GC_REPEATED] += 1
    finite = math.isfinite(X) and math.isfinite(Y) and math.isfinite(theta)
    if fresh and not finite:
        cnt[GC_NAN] += 1  # counted at every call (pose_rejected: at the MPC's steps)
    if not (fresh and finite):
        return fresh, False
    if not has_pose or gs[GS_FREE] != 0.0 or pose_consistent(p.gates, X, Y, theta, px, py, pth, t - pose_t):
        gs[GS_FREE], gs[GS_JT0] = 0.0, math.nan
        return fresh, True
    if p.recovery:
        take, gs[GS_JT0] = jump_run(p.gates, p.reinit_s, gs[GS_JT0], gs[GS_JX], gs[GS_JY], gs[GS_JTH],
                                    gs[GS_JT], X, Y, theta, t)
        gs[GS_JX], gs[GS_JY], gs[GS_JTH], gs[GS_JT] = X, Y, theta, t
        if take:
            cnt[GC_REINIT] += 1
            gs[GS_JT0] = math.nan
            return fresh, True
    cnt[GC_JUMP] += 1
    return fresh, False


@jitable
def gate_block(p: GateBlockParams, gs: NDArray[np.float64], cnt: NDArray[np.int64], pose: NDArray[np.float64],
               t: float, fresh: bool, X: float, Y: float, theta: float, v: float, omega: float,
               stamp: float) -> tuple[bool, bool, bool]:
    """The gates of a call at time ``t`` (the cascade's ``_gate``, the engine's every step): (fresh,
    speeds plausible, pose accepted) — :func:`speed_gate`, then :func:`pose_gate` against the pose
    record ``pose`` (``PO_*``: the dead-reckoned pose, the last accepted pose's time), which an
    accepted pose replaces (its time ``t``)."""
    speeds_ok = speed_gate(p.gates, cnt, v, omega)
    fresh, pose_ok = pose_gate(p, gs, cnt, t, fresh, X, Y, theta, v, omega, stamp, True, pose[PO_X],
                               pose[PO_Y], pose[PO_TH], pose[PO_T])
    if pose_ok:
        pose[PO_X], pose[PO_Y], pose[PO_TH], pose[PO_T] = X, Y, theta, t
    return fresh, speeds_ok, pose_ok


@jitable
def reckon_block(p: GateParams, pose: NDArray[np.float64], v: float, alpha: float, omega: float) -> None:
    """The pose record ``pose`` (``PO_*``) one T_d on (:func:`dead_reckon` on the estimate
    (v̂, α̂, ω̂)); the last accepted pose's time stays."""
    pose[PO_X], pose[PO_Y], pose[PO_TH] = dead_reckon(p, pose[PO_X], pose[PO_Y], pose[PO_TH], v, alpha, omega)


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


@jitable
def jump_run(p: GateParams, reinit_s: float, run_t0: float, lx: float, ly: float, lth: float, lt: float,
             X: float, Y: float, theta: float, t: float) -> tuple[bool, float]:
    """A pose rejected as a jump, against the run of rejected poses before it (the last one at
    (lx, ly, lth), time ``lt``; the run began at ``run_t0``, NaN: no run): (take it, the run's new
    start). Poses that agree with one another for ``reinit_s`` while the dead-reckoned pose
    disagrees with all of them are the car: the dead reckoning drifted (an estimate that ran away
    while the sensors were out), and the gate takes them instead of locking the car out."""
    if run_t0 != run_t0 or not pose_consistent(p, X, Y, theta, lx, ly, lth, t - lt):
        return False, t  # a new run starts here
    return t - run_t0 >= reinit_s, run_t0


@jitable
def blind_stop(v_hat: float, delta_last: float, mass: float, decel: float, f_min: float,
               f_max: float) -> tuple[float, float]:
    """The command of the blind stop (F_xR [N], δ [rad]): brake at ``decel`` on the estimated
    speed's sign, within the force limits, on the last steering (the car keeps the curvature it
    had); no force once the estimate says it stands."""
    F = 0.0
    if v_hat > 0.05:
        F = max(min(-mass * decel, f_max), f_min)
    return F, delta_last


@jitable
def nearest_sample(ref_x: NDArray[np.float64], ref_y: NDArray[np.float64], k_lo: int, k_hi: int, X: float,
                   Y: float) -> int:
    """The reference sample in [k_lo, k_hi] nearest to (X, Y) (the first of equals)."""
    best, kb = math.inf, k_lo
    for k in range(k_lo, k_hi + 1):
        d = (ref_x[k] - X) ** 2 + (ref_y[k] - Y) ** 2
        if d < best:
            best, kb = d, k
    return kb


@jitable
def speed_bounded_yaw_rate(omega: float, v: float, curvature_max: float) -> float:
    """The yaw rate ``omega`` [rad/s] within what a car at speed ``v`` [m/s] can turn,
    |ω| ≤ max(v, 0) κ_max with κ_max = tan(δ_max)/L [1/m] the kinematic bicycle's tightest path
    curvature (ω = v tan δ / L); ``omega`` itself (the same float) when it is within, or when
    ``v`` is not finite (no speed to bound it by)."""
    if not math.isfinite(v):
        return omega
    lim = max(v, 0.0) * curvature_max
    return min(max(omega, -lim), lim)
