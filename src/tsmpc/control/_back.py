"""The cascade's step after the MHE, as one phase (issue 34): the glue between the blocks, written
once, that :meth:`Cascade._step <tsmpc.control.cascade.Cascade>` calls (compiled:
``tsmpc.kernels.blocks.back_call``; as Python with ``TSMPC_NO_JIT``) and the run engine
(``tsmpc.kernels.engine.run``) and the batch compile into their step.

:func:`cascade_back` is, in this order: the dead reckoning of the pose on the estimate (the gate
block's :func:`~tsmpc.control.gates.reckon_block`), the fusion block after the MHE
(:func:`~tsmpc.control.fusion_block.after_at`: the course fusion's sample, the steering-offset
fit's), the inner block (:func:`~tsmpc.control.inner_block.inner_block`: friction step, mass terms,
TS-LQR, events) and :func:`cascade_command`: the servo (:func:`~tsmpc.control.fusion_block.servo_at`)
and the command's bookkeeping in the command record (``CM_*`` slots). When the inner block's
compiled law does not decide (:data:`~tsmpc.control.ts_lqr.LQR_NUMPY`: no compiled law, or N̄
singular) it returns before the command; the caller runs the numpy law and then
:func:`cascade_command`. The configurations the inner block does not express (the oracle, the
published run's law, the blind stop) take :func:`back_start` (reckoning and fusion), their own law
and :func:`cascade_command`.

Records: :class:`BackParams` (the blocks' parameters), :class:`BackState` (the blocks' state
vectors: the gate block's pose record, the fusion block's state and open interval, the stiffnesses
given, the command record, the TS-LQR's and the inner block's state and counters), the result
:class:`BackOut`; the estimate's status arrives as a code (``inner_block.EST_*``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.fusion_block import FusionParams, after_at, given_steer, servo_at, slip_load
from tsmpc.control.gates import GateParams, reckon_block
from tsmpc.control.inner_block import InnerBlockParams, inner_block
from tsmpc.control.ts_lqr import LQR_NUMPY, LQRLaw
from tsmpc.estimation.fusion import SteerParams, slip_correction
from tsmpc.kernels.jit import jitable_inline

__all__ = ["CM_ALPHA", "CM_CALLS", "CM_D", "CM_F", "CM_HASLAST", "CM_LOW", "CM_SAT", "N_CM", "BackOut",
           "BackParams", "BackState", "back_start", "cascade_back", "cascade_command", "command_state"]

#: The command record's slots (floats; flags 1.0 / 0.0): the input the plant got over the last
#: T_d ([F_xR, δ]: the wheels' intended angle, what the MHE's model sees), its low-speed part, the
#: calls made, a command was made, the last estimate's α̂ and the last command saturated.
CM_F, CM_D, CM_LOW, CM_CALLS, CM_HASLAST, CM_ALPHA, CM_SAT = range(7)
N_CM = 7


class BackParams(NamedTuple):
    """The phase's parameters: its blocks' records.

    Attributes:
        gates: the gate block's bounds (the dead reckoning's T_d).
        fusion: the fusion block's record.
        steer: the steering-offset fit's parameters as the config gives them (the stiffnesses
            given by the stiffness block replace the model's: ``BackState.sa``).
        inner: the inner block's record.
    """

    gates: GateParams
    fusion: FusionParams
    steer: SteerParams
    inner: InnerBlockParams


class BackState(NamedTuple):
    """The phase's state: its blocks' vectors, changed in place.

    Attributes:
        pose: the gate block's pose record (``gates.PO_*``).
        fb: the fusion block's state vector (``fusion_block.FB_*``).
        cur: the course fusion's open interval (``fusion_block.IV_*``).
        sa: the stiffnesses given (``stiffness_block.SA_*``).
        cmd: the command record (``CM_*``).
        lqr: the TS-LQR's state.
        ib: the inner block's state (``inner_block.IB_*``).
        ring: the inner block's window of speeds.
        cnt: the inner block's counters (``inner_block.IC_*``).
    """

    pose: NDArray[np.float64]
    fb: NDArray[np.float64]
    cur: NDArray[np.float64]
    sa: NDArray[np.float64]
    cmd: NDArray[np.float64]
    lqr: NDArray[np.float64]
    ib: NDArray[np.float64]
    ring: NDArray[np.float64]
    cnt: NDArray[np.int64]


class BackOut(NamedTuple):
    """What :func:`cascade_back` decided.

    Attributes:
        F_xR: rear force [N].
        delta: the angle sent to the servo [rad] (the TS-LQR's with :data:`LQR_NUMPY`).
        saturated: an inner-loop saturation was active.
        status: the TS-LQR step's (``ts_lqr.LQR_*``); :data:`LQR_NUMPY`: the numpy law decides.
        F_comp: the friction compensation [N].
        F_low_speed: the low-speed residual [N].
    """

    F_xR: float
    delta: float
    saturated: bool
    status: int
    F_comp: float
    F_low_speed: float


def command_state() -> NDArray[np.float64]:
    """The command record of a reset cascade (no command yet)."""
    return np.zeros(N_CM)


@jitable_inline
def back_start(p: BackParams, s: BackState, ok: bool, pose_ok: bool, th: float, v: float, v_hat: float,
               a_hat: float, w_hat: float, est_status: int, delta: float, force: float, blind: bool) -> None:
    """The pose dead-reckoned one T_d on the estimate (v̂, α̂, ω̂), then the fusion block after the
    MHE on the sample (``ok``: speeds accepted and fresh; ``pose_ok``; the measured θ and v), the
    estimate and its status code, the input [``force``, ``delta``] the MHE's model saw."""
    # the velocity heading of the dead reckoning: α̂ with the slip fit's correction at the car's own
    # lateral acceleration (the outer loop takes the reference's, against a fast loop through ω; the
    # pose integrates it, and between poses at 1-2 Hz the uncorrected α̂ is the pose's drift)
    a_dr = a_hat + slip_correction(slip_load(s.fb), v_hat * w_hat) if p.fusion.slip else a_hat
    reckon_block(p.gates, s.pose, v_hat, a_dr, w_hat)
    cmd = s.cmd
    after_at(p.fusion, s.fb, given_steer(p.steer, s.sa), s.cur, ok, pose_ok, th, v, v_hat, a_hat, w_hat,
             delta, force, est_status, blind, cmd[CM_HASLAST] != 0.0 and cmd[CM_SAT] != 0.0)


@jitable_inline
def cascade_command(p: BackParams, s: BackState, F: float, delta: float, saturated: bool, low: float,
                    alpha: float) -> float:
    """The command of the inner loop's (F_xR, ``delta``): the angle sent (the servo), and the
    command record (the applied input, its low-speed part, the call counted, the estimate's
    ``alpha`` and the saturation kept for the next call)."""
    sent, wheels = servo_at(p.fusion, s.fb, given_steer(p.steer, s.sa), delta)
    cmd = s.cmd
    cmd[CM_F], cmd[CM_D], cmd[CM_LOW] = F, wheels, low
    cmd[CM_CALLS] += 1.0
    cmd[CM_HASLAST], cmd[CM_ALPHA], cmd[CM_SAT] = 1.0, alpha, 1.0 if saturated else 0.0
    return sent


@jitable_inline
def cascade_back(p: BackParams, law: LQRLaw | None, s: BackState, ok: bool, pose_ok: bool, th: float,
                 v: float, v_hat: float, a_hat: float, w_hat: float, F_fr: float, F_raw: float,
                 est_status: int, delta: float, force: float, v_ref: float, w_ref: float) -> BackOut:
    """The step after the MHE (see the module docstring): :func:`back_start`, the inner block on the
    estimate (F̂ window and one-step, the status code) and the references (v_ref, ω_ref), and —
    unless the numpy law must decide — :func:`cascade_command`."""
    back_start(p, s, ok, pose_ok, th, v, v_hat, a_hat, w_hat, est_status, delta, force, False)
    out = inner_block(p.inner, law, s.lqr, s.ib, s.ring, s.cnt, v_hat, a_hat, w_hat, F_fr, F_raw, est_status,
                      v_ref, w_ref)
    if out.status == LQR_NUMPY:
        return BackOut(out.F_xR, out.delta, out.saturated, out.status, out.F_comp, out.F_low_speed)
    sent = cascade_command(p, s, out.F_xR, out.delta, out.saturated, out.F_low_speed, a_hat)
    return BackOut(out.F_xR, sent, out.saturated, out.status, out.F_comp, out.F_low_speed)
