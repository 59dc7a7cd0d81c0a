"""The cascade's step before the outer loop and the MHE, as one phase (issue 34): the glue between
the blocks, written once, that :meth:`Cascade._step <tsmpc.control.cascade.Cascade>` calls
(compiled: ``tsmpc.kernels.blocks.front_call``; as Python with ``TSMPC_NO_JIT``) and the run
engine (``tsmpc.kernels.engine.run``) and the batch compile into their step.

:func:`cascade_front` is, in this order: the sample gates (the gate block
:func:`~tsmpc.control.gates.gate_block`: stale, implausible, repeated samples and pose jumps
refused), whether the MPC runs at this call (every ``n_inner`` calls, counted in the command
record of :mod:`tsmpc.control._back`), and the fusion block before the MPC and the MHE
(:func:`~tsmpc.control.fusion_block.before_at`: the yaw-rate bias fit's sample, ω less the bias,
the course fusion's close at an accepted pose). What the cascade does before it in Python — the
call's clock, the sample's stamp, the recovery's watch of the speed samples — and the first
call's start from the measurement are not part of it (the run engine's samples carry no stamp and
its runs cannot blind the cascade).

Records: :class:`FrontParams`, :class:`FrontState` (the blocks' state vectors, changed in place),
the result :class:`FrontOut`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control._back import CM_CALLS
from tsmpc.control.fusion_block import FusionParams, before_at
from tsmpc.control.gates import GateBlockParams, gate_block
from tsmpc.kernels.jit import jitable_inline

__all__ = ["FrontOut", "FrontParams", "FrontState", "cascade_front"]


class FrontParams(NamedTuple):
    """The phase's parameters.

    Attributes:
        gates: the gate block's record.
        fusion: the fusion block's record.
        n_inner: calls per MPC period (the MPC runs at every ``n_inner``-th call).
    """

    gates: GateBlockParams
    fusion: FusionParams
    n_inner: int


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
    """

    gs: NDArray[np.float64]
    gcnt: NDArray[np.int64]
    pose: NDArray[np.float64]
    fb: NDArray[np.float64]
    ivs: NDArray[np.float64]
    cur: NDArray[np.float64]
    cmd: NDArray[np.float64]


class FrontOut(NamedTuple):
    """What :func:`cascade_front` decided.

    Attributes:
        fresh: the sample is fresh (not stale, not a repeat).
        speeds_ok: its speed and yaw rate are plausible.
        pose_ok: its pose was accepted.
        mpc_step: the MPC runs at this call.
        omega: the yaw rate less the gyro's bias [rad/s] (the blocks after it use it).
    """

    fresh: bool
    speeds_ok: bool
    pose_ok: bool
    mpc_step: bool
    omega: float


@jitable_inline
def cascade_front(p: FrontParams, s: FrontState, t: float, fresh: bool, X: float, Y: float, th: float,
                  v: float, omega: float, stamp: float, t_off: float,
                  v_d: Sequence[float] | NDArray[np.float64],
                  w_d: Sequence[float] | NDArray[np.float64]) -> FrontOut:
    """The step before the outer loop (see the module docstring) on the call's time ``t``, the
    sample (``fresh`` by its stamp; pose, speed, raw yaw rate; ``stamp``: −∞ when it has none),
    the reference time offset ``t_off`` and the reference's v_d, ω_d."""
    fresh, speeds_ok, pose_ok = gate_block(p.gates, s.gs, s.gcnt, s.pose, t, fresh, X, Y, th, v, omega,
                                           stamp)
    mpc_step = int(s.cmd[CM_CALLS]) % p.n_inner == 0
    om = before_at(p.fusion, s.fb, s.ivs, s.cur, pose_ok, X, Y, th, fresh and speeds_ok, v, omega, mpc_step,
                   t, t_off, v_d, w_d)
    return FrontOut(fresh, speeds_ok, pose_ok, mpc_step, om)
