"""The cascade's step before the outer loop and the MHE, as one phase (issue 34): the glue between
the blocks, written once, that :meth:`Cascade._step <tsmpc.control.cascade.Cascade>` calls
(compiled: ``tsmpc.kernels.blocks.front_call``; as Python with ``TSMPC_NO_JIT``) and the run
engine (``tsmpc.kernels.engine.run``) and the batch compile into their step.

:func:`cascade_front` is, in this order: the sample's stamp and the recovery's watch of the
speed samples (:func:`~tsmpc.control._clock.cascade_sample`), the sample gates (the gate block
:func:`~tsmpc.control.gates.gate_block`: implausible, repeated samples and pose jumps
refused), whether the MPC runs at this call (every ``n_inner`` calls, counted in the command
record of :mod:`tsmpc.control._back`), and the fusion block before the MPC and the MHE
(:func:`~tsmpc.control.fusion_block.before_at`: the yaw-rate bias fit's sample, ω less the bias,
the course fusion's close at an accepted pose). The call's clock
(:func:`~tsmpc.control._clock.cascade_clock`) comes before it, and the first call's start from the
measurement is not part of it (the run engine's cascades start from a state; its samples carry no
stamp).

At an MPC step, :func:`cascade_outer` is the part before the solve: the recovery's restart and the
reference sample ``k`` (the time base; :func:`~tsmpc.control._clock.cascade_time`), the stiffness block
(:func:`~tsmpc.control.stiffness_block.stiffness_block`, ``fusion.stiffness_estimate``: the course
fits' stiffnesses handed to the MHE's and the TS-LQR's parameters) and the outer block's errors and
window (:func:`~tsmpc.control.outer_block.outer_errors` on the pose record, the slip fit of the
fusion block's state and the last estimate's α̂ of the command record; the previous plan's
prediction unless the reference waits for the car after a re-anchoring). The Python models around
the parameters the stiffness block wrote follow in the cascade, and so do the resets a
re-anchoring asks for (the MPC's and the cascade's last plan).

Records: :class:`FrontParams`, :class:`FrontState` (the blocks' state vectors, changed in place),
the result :class:`FrontOut`; :class:`OuterParams`, :class:`OuterState`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control._back import CM_ALPHA, CM_CALLS, CM_HASLAST
from tsmpc.control._clock import CK_CATCHUP, ClockParams, cascade_sample, cascade_time
from tsmpc.control.fusion_block import FusionParams, before_at, course_load, course_store, slip_load
from tsmpc.control.gates import PO_TH, PO_X, PO_Y, GateBlockParams, gate_block
from tsmpc.control.outer_block import OuterBlockParams, RefArrays, outer_errors
from tsmpc.control.stiffness_block import stiffness_block
from tsmpc.estimation.fusion import CourseParams
from tsmpc.kernels.jit import jitable, jitable_inline

__all__ = ["FrontOut", "FrontParams", "FrontState", "OuterParams", "OuterState", "cascade_front",
           "cascade_outer", "stiffness_step"]


class FrontParams(NamedTuple):
    """The phase's parameters.

    Attributes:
        gates: the gate block's record.
        fusion: the fusion block's record.
        n_inner: calls per MPC period (the MPC runs at every ``n_inner``-th call).
        clock: the cascade's time's record (the stamp's age, the recovery's blind clock).
    """

    gates: GateBlockParams
    fusion: FusionParams
    n_inner: int
    clock: ClockParams


class FrontState(NamedTuple):
    """The phase's state: its blocks' vectors, changed in place.

    Attributes:
        gs: the gate block's state (``gates.GS_*``).
        gcnt: the gate block's counters (``gates.GC_*``).
        pose: the gate block's pose record (``gates.PO_*``).
        fb: the fusion block's state vector (``fusion_block.FB_*``).
        ivs: the course fusion's ring of intervals (``fusion_block.IV_*`` rows).
        cur: the course fusion's open interval.
        cmd: the command record (``_back.CM_*``; read only: the calls made).
        ck: the cascade's time's state (``_clock.CK_*``).
        cc: its counters (``_clock.CC_*``).
    """

    gs: NDArray[np.float64]
    gcnt: NDArray[np.int64]
    pose: NDArray[np.float64]
    fb: NDArray[np.float64]
    ivs: NDArray[np.float64]
    cur: NDArray[np.float64]
    cmd: NDArray[np.float64]
    ck: NDArray[np.float64]
    cc: NDArray[np.int64]


class FrontOut(NamedTuple):
    """What :func:`cascade_front` decided.

    Attributes:
        fresh: the sample is fresh (not stale, not a repeat).
        speeds_ok: its speed and yaw rate are plausible.
        pose_ok: its pose was accepted.
        mpc_step: the MPC runs at this call.
        omega: the yaw rate less the gyro's bias [rad/s] (the blocks after it use it).
        recovered: the blind stop ended at this sample (the caller resets the TS-LQR's filter).
    """

    fresh: bool
    speeds_ok: bool
    pose_ok: bool
    mpc_step: bool
    omega: float
    recovered: bool


@jitable_inline
def cascade_front(p: FrontParams, s: FrontState, t: float, has_stamp: bool, X: float, Y: float, th: float,
                  v: float, omega: float, stamp: float, t_off: float,
                  v_d: Sequence[float] | NDArray[np.float64],
                  w_d: Sequence[float] | NDArray[np.float64]) -> FrontOut:
    """The step before the outer loop (see the module docstring) on the call's time ``t``, the
    sample (pose, speed, raw yaw rate; its ``stamp`` when it ``has_stamp``, else −∞), the
    reference time offset ``t_off`` and the reference's v_d, ω_d."""
    fresh, recovered = cascade_sample(p.clock, p.gates.gates, s.ck, s.cc, s.gs, t, has_stamp, stamp, v, omega)
    fresh, speeds_ok, pose_ok = gate_block(p.gates, s.gs, s.gcnt, s.pose, t, fresh, X, Y, th, v, omega,
                                           stamp)
    mpc_step = int(s.cmd[CM_CALLS]) % p.n_inner == 0
    om = before_at(p.fusion, s.fb, s.ivs, s.cur, pose_ok, X, Y, th, fresh and speeds_ok, v, omega, mpc_step,
                   t, t_off, v_d, w_d)
    return FrontOut(fresh, speeds_ok, pose_ok, mpc_step, om, recovered)


class OuterParams(NamedTuple):
    """The MPC step's part before the solve: its parameters.

    Attributes:
        stiffness: the stiffness block runs (``fusion.stiffness_estimate`` with the course fusion).
        cp: the course fusion's parameters.
        outer: the outer block's record.
        clock: the cascade's time's record (the restart, the time base).
    """

    stiffness: bool
    cp: CourseParams
    outer: OuterBlockParams
    clock: ClockParams


class OuterState(NamedTuple):
    """Its state: the blocks' vectors, changed in place.

    Attributes:
        fb: the fusion block's state vector (``fusion_block.FB_*``).
        ivs: the course fusion's ring of intervals.
        sa: the stiffnesses given (``stiffness_block.SA_*``).
        mp: the MHE's parameters (the stiffness block writes C_f, C_r).
        prm: the TS-LQR law's parameters (the same).
        ob: the outer block's state (``outer_block.OB_*``).
        oc: the outer block's counters (``outer_block.OC_*``).
        gate: the slip gate's MPC poses.
        pose: the gate block's pose record (``gates.PO_*``).
        cmd: the command record (``_back.CM_*``; read only).
        ck: the cascade's time's state (``_clock.CK_*``).
        up: the MPC's previous input [v, ω].
    """

    fb: NDArray[np.float64]
    ivs: NDArray[np.float64]
    sa: NDArray[np.float64]
    mp: NDArray[np.float64]
    prm: NDArray[np.float64]
    ob: NDArray[np.float64]
    oc: NDArray[np.int64]
    gate: NDArray[np.float64]
    pose: NDArray[np.float64]
    cmd: NDArray[np.float64]
    ck: NDArray[np.float64]
    up: NDArray[np.float64]


@jitable
def stiffness_step(cp: CourseParams, fb: NDArray[np.float64], ivs: NDArray[np.float64],
                   sa: NDArray[np.float64], mp: NDArray[np.float64], prm: NDArray[np.float64]) -> bool:
    """The stiffness block on the course state of the fusion block's vectors: True when it gave the
    stiffnesses (then in ``sa``, ``mp``, ``prm``; κ restarted when they replaced given ones — the
    state is unchanged otherwise). (A call of its own in compiled callers: inlined, the course
    state's 8 intervals cost the batch about 4 %.)"""
    give, cs = stiffness_block(cp, course_load(fb, ivs), sa, mp, prm)
    if give:
        course_store(cs, fb, ivs)
    return give


@jitable_inline
def cascade_outer(p: OuterParams, r: RefArrays, s: OuterState, t: float, pose_ok: bool, X: float, Y: float,
                  v: float, omega: float, v_hat: float, has_pred: bool, pred_y: float, e: NDArray[np.float64],
                  win_v: NDArray[np.float64], win_w: NDArray[np.float64],
                  buf: NDArray[np.float64]) -> tuple[int, bool, bool, bool]:
    """An MPC step before the solve (see the module docstring) at the call's time ``t`` on the
    sample's pose (X, Y; ``pose_ok``), measured speed and yaw rate less the bias, the last
    estimate's v̂ (NaN: none) and the last plan's prediction of e_y now (``has_pred``): (the
    reference sample k, re-anchored, the stiffness block gave the stiffnesses, the errors and
    window are the governed reference's)."""
    pose, cmd = s.pose, s.cmd
    k, restarted = cascade_time(p.clock, r, s.ck, s.ob, s.up, int(cmd[CM_CALLS]), t, pose_ok, X, Y, v, omega,
                                v_hat)
    has_pred = has_pred and s.ck[CK_CATCHUP] == 0.0  # (a restart waiting for the car: no learning)
    give = stiffness_step(p.cp, s.fb, s.ivs, s.sa, s.mp, s.prm) if p.stiffness else False
    governed = outer_errors(p.outer, r, s.ob, s.oc, s.gate, slip_load(s.fb), t, k, pose_ok, pose[PO_X],
                            pose[PO_Y], pose[PO_TH], cmd[CM_HASLAST] != 0.0, cmd[CM_ALPHA], has_pred, pred_y,
                            s.up[0], e, win_v, win_w, buf)
    return k, restarted, give, governed
