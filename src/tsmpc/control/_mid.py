"""The cascade's step between the outer loop and the phase after the MHE, as phases (issue 34):
the glue written once that :meth:`Cascade._step <tsmpc.control.cascade.Cascade>` calls (compiled:
``tsmpc.kernels.blocks.after_call`` and ``mhe_call``; as Python with ``TSMPC_NO_JIT``) and the
run engine (``tsmpc.kernels.engine.run``) and the batch compile into their step.

:func:`cascade_after_plan`: after an MPC step, the plan's first input kept as the MPC's previous
input (:func:`~tsmpc.control._clock.plan_taken`: within what the car can turn during a restart),
then the outer block's part after the solve
(:func:`~tsmpc.control.outer_block.outer_after`: the plan's events, the speed governor's rate) on
the last call's command as the command record of :mod:`tsmpc.control._back` keeps it (a command
was made, it saturated, the drive force applied) and the last estimate (its status code, v̂, F̂).

:func:`cascade_estimate`: the MHE block (:func:`~tsmpc.control.mhe_block.mhe_block`) on its inputs
as the blocks' records hold them: the speed less the course fit's speed-sensor errors at it
(:func:`~tsmpc.estimation.fusion.speed_offset`, with ``fusion.course_speed``) and ω less the gyro's
bias of the fusion block's state (``fusion_block.FB_*``), the input applied over the last T_d, its
low-speed part and the steering offset in force (the command record and the fusion block's state).

Records: :class:`AfterState`; :class:`EstimateParams`, :class:`EstimateState`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control._back import CM_D, CM_F, CM_HASLAST, CM_LOW, CM_SAT
from tsmpc.control._clock import ClockParams, plan_taken
from tsmpc.control.fusion_block import FB_OFF, FB_OMEGA, speed_load
from tsmpc.control.mhe_block import MHEBlockParams, MHEStep, MHEWindow, mhe_block
from tsmpc.control.outer_block import GovernBlockParams, OuterBlockParams, RefArrays, outer_after
from tsmpc.estimation.fusion import speed_offset
from tsmpc.kernels.jit import jitable_inline

__all__ = ["AfterState", "EstimateParams", "EstimateState", "cascade_after_plan", "cascade_estimate"]


class AfterState(NamedTuple):
    """The state :func:`cascade_after_plan` reads and changes.

    Attributes:
        ob: the outer block's state (``outer_block.OB_*``).
        oc: the outer block's counters (``outer_block.OC_*``).
        cmd: the command record (``_back.CM_*``; read only).
        ck: the cascade's time's state (``_clock.CK_*``; read only).
        up: the MPC's previous input [v, ω] (the plan's first input is written into it).
    """

    ob: NDArray[np.float64]
    oc: NDArray[np.int64]
    cmd: NDArray[np.float64]
    ck: NDArray[np.float64]
    up: NDArray[np.float64]


@jitable_inline
def cascade_after_plan(p: OuterBlockParams, g: GovernBlockParams, c: ClockParams, r: RefArrays, s: AfterState,
                       u0: float, u1: float, ok: bool, v: float, status: int, n_clipped: int, t: float,
                       est_status: int,
                       v_hat: float, F_fr: float, road_mu: float, dmass: float,
                       buf: NDArray[np.float64]) -> None:
    """The plan's bookkeeping after the MPC step at time ``t`` (see the module docstring): its first
    input (u0, u1), the measured speed ``v`` (``ok``: the gates took it), its status code and clipped
    steps, the last estimate's status code, v̂ (NaN: none) and F̂ (read when a command was made),
    the road's μ (the oracle's grip), the mass fit's ΔM̂, the outer block's scratch."""
    plan_taken(c, s.ck, s.up, u0, u1, ok, v, v_hat)
    cmd = s.cmd
    outer_after(p, g, r, s.ob, s.oc, status, n_clipped, t, cmd[CM_HASLAST] != 0.0, est_status, v_hat, F_fr,
                cmd[CM_SAT] != 0.0, cmd[CM_F], road_mu, dmass, buf)


class EstimateParams(NamedTuple):
    """The MHE phase's parameters.

    Attributes:
        mhe: the MHE block's record.
        course_speed: ``fusion.course_speed``: the course fit's speed offset comes off the speed.
    """

    mhe: MHEBlockParams
    course_speed: bool


class EstimateState(NamedTuple):
    """The MHE phase's state: the estimator's records (``mhe_block``), the blocks' vectors it reads.

    Attributes:
        mp: the MHE's parameters.
        ms: its state [x̂, F̂, x̄_0, …].
        mi: its counters.
        uk: the input the window holds.
        est: the estimate handed on (``mhe_block.EO_*``).
        fb: the fusion block's state vector (read only).
        cmd: the command record (read only).
    """

    mp: NDArray[np.float64]
    ms: NDArray[np.float64]
    mi: NDArray[np.int64]
    uk: NDArray[np.float64]
    est: NDArray[np.float64]
    fb: NDArray[np.float64]
    cmd: NDArray[np.float64]


@jitable_inline
def cascade_estimate(p: EstimateParams, w: MHEWindow, s: EstimateState, speeds_ok: bool, v: float,
                     has_force: bool, force: float, has_steering: bool, steering: float) -> MHEStep:
    """The MHE block on the measured speed ``v`` (``speeds_ok``: the gates took the sample) and the
    platform's measured force / steering when it has them (see the module docstring)."""
    fb, cmd = s.fb, s.cmd
    off = speed_offset(speed_load(fb), v) if p.course_speed else 0.0
    return mhe_block(p.mhe, w, s.mp, s.ms, s.mi, s.uk, s.est, speeds_ok, v, fb[FB_OMEGA], off, cmd[CM_F],
                     cmd[CM_D], has_force, force, has_steering, steering, fb[FB_OFF], cmd[CM_LOW])
