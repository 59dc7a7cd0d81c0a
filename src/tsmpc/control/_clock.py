"""The cascade's time, as phases (issue 34): the glue written once that :class:`Cascade
<tsmpc.control.cascade.Cascade>` calls (compiled: ``tsmpc.kernels.blocks.clock_call`` and inside
the phases of :mod:`tsmpc.control._front` and :mod:`tsmpc.control._mid`; as Python with
``TSMPC_NO_JIT``) and the run engine (``tsmpc.kernels.engine.run``) and the batch compile into their
step.

* :func:`cascade_clock`: the call's time — ``t`` when it follows the previous call (later by at
  most ``max_time_jump_s``), else the cascade's own clock, previous + T_d (``time_rejected``).
* :func:`cascade_sample` (in :func:`~tsmpc.control._front.cascade_front`, before the gates): the
  sample's stamp (a sample from the future or with a non-finite stamp: ``stamp_rejected``; older
  than ``max_age_s``: ``stale_rejected``) and the recovery's watch of the speed samples (the blind
  stop begins after ``recovery.blind_after_s`` without a usable speed / yaw-rate sample and ends
  at the next one: ``recoveries``; the gates then take the next pose and the reference is
  re-anchored at the car at the next MPC step).
* :func:`cascade_time` (in :func:`~tsmpc.control._front.cascade_outer`, before the errors): the
  recovery's restart at an MPC step — the reference time moved back to the reference sample
  nearest to the car (re-anchoring), or advancing at the car's speed over the reference's until the
  car is as fast (catch-up) — and the reference sample ``k`` of the step (the time base).
* :func:`plan_taken` (in :func:`~tsmpc.control._mid.cascade_after_plan`): the plan's first input
  kept as the MPC's previous input (the TS-LQR's references until the next MPC step), within
  what the car can turn at its speed during a restart (``recovery.yaw_rate_bound``).

What stays with the caller are the Python objects' resets these phases ask for (the TS-LQR's
filter at a recovery; the MPC's and the cascade's last plan at a re-anchoring) and the
conversion of the call's ``t`` and the sample's stamp to floats. The run engine never blinds
the cascade: its step returns (the Python loop runs) when the blind stop begins.

Records: :class:`ClockParams` (:func:`pack_clock` / :func:`unpack_clock` for compiled calls), the
state vector (``CK_*`` slots, :func:`clock_state`) and the counters (``CC_*``: the run engine's
first event counters, in its order).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.gates import GS_FREE, GateParams, nearest_sample, plausible_speeds, speed_bounded_yaw_rate
from tsmpc.control.outer_block import OB_OFFB, OB_TOFF, RefArrays
from tsmpc.kernels.jit import jitable, jitable_inline

__all__ = ["CC_BLIND", "CC_RECOVER", "CC_STALE", "CC_STAMP", "CC_TIME", "CK_BLIND", "CK_CATCHUP",
           "CK_OUTAGE", "CK_REANCHOR", "CK_TLAST", "CK_TMEAS", "N_CC", "N_CK", "N_CKP", "ClockParams",
           "cascade_clock", "cascade_sample", "cascade_time", "clock_state", "pack_clock", "plan_taken",
           "unpack_clock"]

#: The state's slots (floats; NaN: none yet; flags 1.0 / 0.0): the last call's time, the time of
#: the last usable speed / yaw-rate sample (the blind clock), the blind stop's start, a
#: re-anchoring due at the next MPC step with a pose, the outage it ends, the reference waiting
#: for the car's speed after a re-anchoring.
CK_TLAST, CK_TMEAS, CK_BLIND, CK_REANCHOR, CK_OUTAGE, CK_CATCHUP = range(6)
N_CK = 6
#: The counters: calls whose time was rejected, samples with a rejected stamp, calls in the blind
#: stop (the caller's blind law counts them), recoveries, stale samples.
CC_TIME, CC_STAMP, CC_BLIND, CC_RECOVER, CC_STALE = range(5)
N_CC = 5
#: Length of the packed parameter vector (:func:`pack_clock`).
N_CKP = 10


class ClockParams(NamedTuple):
    """The phases' parameters.

    Attributes:
        Td: the call period T_d [s].
        Tc: the MPC's period T_c [s].
        max_jump: a call time more than this after the previous one is rejected [s].
        max_age: a sample whose stamp is older than this is stale [s].
        recovery: ``recovery.enabled`` (the blind stop, the restart).
        blind_after: ``recovery.blind_after_s`` [s].
        n_inner: calls per MPC period.
        fixed_base: ``rates.inner_steps_per_outer`` (the published run's time base: ``n_inner``
            calls per reference sample).
        bound: ``recovery.yaw_rate_bound`` (with the recovery).
        curvature_max: the kinematic bicycle's tightest path curvature tan(δ_max)/L [1/m].
    """

    Td: float
    Tc: float
    max_jump: float
    max_age: float
    recovery: bool
    blind_after: float
    n_inner: int
    fixed_base: bool
    bound: bool
    curvature_max: float


def pack_clock(p: ClockParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_clock` reads."""
    return np.array(list(p), dtype=np.float64)


@jitable
def unpack_clock(a: NDArray[np.float64]) -> ClockParams:
    """The record of :func:`pack_clock`'s vector."""
    return ClockParams(a[0], a[1], a[2], a[3], a[4] != 0.0, a[5], int(a[6]), a[7] != 0.0, a[8] != 0.0, a[9])


def clock_state() -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(state, counters) of a reset cascade: no call yet, not blind, no restart due."""
    ck = np.zeros(N_CK)
    ck[CK_TLAST] = ck[CK_TMEAS] = ck[CK_BLIND] = math.nan
    return ck, np.zeros(N_CC, dtype=np.int64)


@jitable_inline
def cascade_clock(p: ClockParams, ck: NDArray[np.float64], cc: NDArray[np.int64], t: float) -> float:
    """The call's time of the caller's ``t`` (NaN when it is no number; see the module docstring)."""
    last = ck[CK_TLAST]
    if math.isnan(last):  # the first call
        ok = math.isfinite(t) and abs(t) < 1e9
        tt = t if ok else 0.0
    else:
        ok = math.isfinite(t) and last < t <= last + p.max_jump + 1e-9
        tt = t if ok else last + p.Td
    if not ok:
        cc[CC_TIME] += 1
    ck[CK_TLAST] = tt
    return tt


@jitable_inline
def cascade_sample(p: ClockParams, gates: GateParams, ck: NDArray[np.float64], cc: NDArray[np.int64],
                   gs: NDArray[np.float64], t: float, has_stamp: bool, stamp: float, v: float,
                   omega: float) -> tuple[bool, bool]:
    """The sample at the call's time ``t`` (its ``stamp`` when it has one: NaN when it is no
    number; its speed and yaw rate): (fresh, the blind stop ended at it — the caller resets the
    TS-LQR's filter, which did not run while blind). See the module docstring."""
    fresh = True
    if has_stamp:
        if not math.isfinite(stamp) or stamp > t + p.Td + 1e-9:  # from the future: garbage
            cc[CC_STAMP] += 1
            fresh = False
        elif t - stamp > p.max_age + 1e-12:
            cc[CC_STALE] += 1
            fresh = False
    if not p.recovery:
        return fresh, False
    # (the speed gate's answer, before the gate block counts it)
    ok = fresh and plausible_speeds(gates, v, omega) and math.isfinite(v) and math.isfinite(omega)
    if math.isnan(ck[CK_TMEAS]):
        ck[CK_TMEAS] = t  # the blind clock starts at the first call
    recovered = False
    if ok:
        if not math.isnan(ck[CK_BLIND]):
            cc[CC_RECOVER] += 1
            ck[CK_REANCHOR] = 1.0
            gs[GS_FREE] = 1.0  # the gates take the next pose
            ck[CK_OUTAGE] = t - ck[CK_TMEAS]
            recovered = True
        ck[CK_TMEAS], ck[CK_BLIND] = t, math.nan
    elif math.isnan(ck[CK_BLIND]) and t - ck[CK_TMEAS] > p.blind_after:
        ck[CK_BLIND] = t
    return fresh, recovered


@jitable_inline
def _reference_sample(p: ClockParams, r: RefArrays, ob: NDArray[np.float64], t: float) -> int:
    """The reference sample at the reference time t − offset, within the reference."""
    return min(max(math.floor((t - ob[OB_TOFF]) / p.Tc + 1e-6), 0), len(r.x) - 1)


@jitable_inline
def cascade_time(p: ClockParams, r: RefArrays, ck: NDArray[np.float64], ob: NDArray[np.float64],
                 up: NDArray[np.float64], calls: int, t: float, pose_ok: bool, X: float, Y: float, v: float,
                 omega: float, v_hat: float) -> tuple[int, bool]:
    """An MPC step's time at the call's time ``t`` (``calls`` made before it): the recovery's
    restart on the pose (X, Y; ``pose_ok``), the measured speed and yaw rate and the last
    estimate's v̂ (NaN: none), then the reference sample — (k, re-anchored: the caller forgets
    the MPC's and its own last plan). ``up``: the MPC's previous input (the measured speed and
    yaw rate at a re-anchoring)."""
    restarted = False
    if ck[CK_REANCHOR] != 0.0 and pose_ok:  # after a blind stop: nearest sample over the outage + 1 s
        kr = _reference_sample(p, r, ob, t)
        back = math.ceil((ck[CK_OUTAGE] + 1.0) / p.Tc)
        k = nearest_sample(r.x, r.y, max(kr - back, 0), kr, X, Y)
        ob[OB_TOFF] += (kr - k) * p.Tc
        ck[CK_REANCHOR], ck[CK_CATCHUP] = 0.0, 1.0
        ob[OB_OFFB] = 0.0  # the offset-free estimate: what it integrated while blind was no course
        if math.isfinite(v) and math.isfinite(omega):
            up[0], up[1] = max(v, 0.0), omega
        restarted = True
    elif ck[CK_CATCHUP] != 0.0:  # the reference time at the car's speed over the reference's
        kr = _reference_sample(p, r, ob, t)
        vr = r.v[kr]
        rate = min(max(v_hat / vr, 0.0), 1.0) if vr > 0.0 and math.isfinite(v_hat) else 1.0
        if rate >= 1.0:
            ck[CK_CATCHUP] = 0.0
        else:
            ob[OB_TOFF] += (1.0 - rate) * p.Tc
    if p.fixed_base:  # a fixed number of calls per reference sample (the published run's time base)
        return calls // p.n_inner, restarted
    return max(math.floor((t - ob[OB_TOFF]) / p.Tc + 1e-6), 0), restarted


@jitable_inline
def plan_taken(p: ClockParams, ck: NDArray[np.float64], up: NDArray[np.float64], u0: float, u1: float,
               ok: bool, v: float, v_hat: float) -> None:
    """The plan's first input (u0, u1) as the MPC's previous input ``up``; during a restart (a
    re-anchoring due or the catch-up) its yaw rate within what the car can turn at the measured
    speed ``v`` when the gates took it (``ok``) and it is finite, else at the last estimate's v̂
    (gates.speed_bounded_yaw_rate)."""
    up[0], up[1] = u0, u1
    if p.bound and (ck[CK_REANCHOR] != 0.0 or ck[CK_CATCHUP] != 0.0):
        w = speed_bounded_yaw_rate(u1, v if ok and math.isfinite(v) else v_hat, p.curvature_max)
        if w != u1:
            up[1] = w
