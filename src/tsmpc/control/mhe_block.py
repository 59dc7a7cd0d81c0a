"""The MHE-UIO's step in the cascade as one block (issue 34): what the cascade does every T_d
around the estimator's window kernel.

:func:`mhe_inputs`: the sample the MHE gets — the measured speed less the course fit's
speed-sensor offset and the yaw rate (bias removed by the caller), both NaN when the gates refused
the sample (the estimator then rejects it and predicts) — and the input the plant received over
the last T_d: the command applied, or the platform's measured force / steering (the measured
angle plus the steering offset in force: the wheels' intended angle, what the MHE's model sees),
the force net of ``lqr.low_speed_resistance``'s part. :func:`mhe_block`: those inputs, the window
update and solve (:func:`tsmpc.kernels.mhe.mhe_step`: the non-finite sample rejected and counted,
a solver failure counted, the estimate's status) and the estimate handed on.

One definition, three callers: :class:`~tsmpc.control.cascade.Cascade` calls :func:`mhe_block`
through one compiled call (``tsmpc.kernels.blocks.mhe_call``), the run engine
(``tsmpc.kernels.engine.run``) and the batch compile it into their step (the batch's lanes solve
the window together: ``defer``, then :func:`estimate_out` on each lane's answer). A step the
block does not decide (:data:`MHE_DENSE`: a state bound active, a pivot failed) goes to the
estimator's dense QP (``MHEUIO.dense_step``), the same Python for all three. Without the compiled
kernel (``TSMPC_NO_JIT``, a ZOH model, the paper's UIO form) the cascade gives
:func:`mhe_inputs` to the estimator's own step.

Records: the parameters are :class:`MHEBlockParams`; the window's arrays a :class:`MHEWindow`; the
estimator's state the kernel's records (``mp`` parameters, ``ms`` = [x̂, F̂, x̄_0], ``mi`` =
[samples, rejected, failed], ``uk`` the input the window holds); the estimate handed on a float
vector of named slots (``EO_*``); the status a code (``EST_*`` of the inner block, or
:data:`MHE_DENSE`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.inner_block import EST_FAILED, EST_OK, EST_REJECTED, EST_WARMUP
from tsmpc.kernels.jit import _numba_ready, jitable, jitable_inline

__all__ = ["EO_F", "EO_FRAW", "EO_X", "MHE_DENSE", "N_EO", "MHEBlockParams", "MHEStep", "MHEWindow",
           "estimate_out", "mhe_block", "mhe_inputs"]

#: The step's status when the estimator's dense QP must decide (the others: EST_OK … EST_WARMUP).
MHE_DENSE = 0
#: The estimate's slots: x̂ = [v̂, α̂, ω̂], F̂ (the window's friction force), F̂_raw (the one-step UIO).
EO_X, EO_F, EO_FRAW = 0, 3, 4
N_EO = 5

mhe_step: Any = None  # no compiled kernel: the cascade runs the estimator's own step
if _numba_ready():
    from tsmpc.kernels import mhe as _km
    from tsmpc.kernels.mhe import mhe_step

    assert (_km.MHE_DENSE, _km.MHE_OK, _km.MHE_REJECTED, _km.MHE_FAILED, _km.MHE_WARMUP) == (
        MHE_DENSE, EST_OK, EST_REJECTED, EST_FAILED, EST_WARMUP)


class MHEBlockParams(NamedTuple):
    """The block's constants.

    Attributes:
        mass: the mass of the one-step UIO formula F̂_raw [kg] (the estimator's vehicle).
        defer: the window is solved by the caller (the batch's lanes), not here.
    """

    mass: float
    defer: bool


class MHEWindow(NamedTuple):
    """The estimator's window (its arrays, oldest sample first; tsmpc.kernels.mhe's)."""

    Y: NDArray[np.float64]  #: (N+1, 2) measurements [v, ω]
    W: NDArray[np.float64]  #: (N+1,) 1 = used, 0 = rejected
    U: NDArray[np.float64]  #: (N, 2) inputs [F_xR, δ] between the samples
    XS: NDArray[np.float64]  #: (N+1, 3) estimates at the samples
    A: NDArray[np.float64]  #: (N, 3, 3) the model along the window
    B: NDArray[np.float64]  #: (N, 3, 2)
    X: NDArray[np.float64]  #: (N+1, 3) the solve's states


class MHEStep(NamedTuple):
    """What a step decided: the status code, F̂_raw, the window's inputs n, the sample accepted,
    and the input [F_xR, δ] as the cascade gave it (the course fusion's)."""

    status: int
    F_raw: float
    n: int
    ok: bool
    u0: float
    u1: float


@jitable
def mhe_inputs(speeds_ok: bool, v: float, omega: float, speed_offset: float, F_applied: float,
               delta_applied: float, has_force: bool, force: float, has_steering: bool, steering: float,
               steer_offset: float, low: float) -> tuple[float, float, float, float]:
    """The MHE's sample ``y = [v − speed offset, ω]`` (NaN, NaN when the gates refused it) and the
    input ``u = [F_xR, δ]`` the plant received: the applied command, or the measured force /
    steering (plus the steering offset in force), the force less the low-speed part ``low``."""
    y0, y1 = (v - speed_offset, omega) if speeds_ok else (math.nan, math.nan)
    u0 = force if has_force else F_applied
    u1 = steering + steer_offset if has_steering else delta_applied
    if low != 0.0:  # lqr.low_speed_resistance: the MHE's model has the clipped resistance
        u0 = u0 - low
    return y0, y1, u0, u1


@jitable
def estimate_out(ms: NDArray[np.float64], est: NDArray[np.float64], F_raw: float) -> None:
    """The estimate of a decided step into ``est``: x̂ and F̂ the estimator's state, F̂_raw."""
    est[EO_X], est[EO_X + 1], est[EO_X + 2] = ms[0], ms[1], ms[2]
    est[EO_F] = ms[3]
    est[EO_FRAW] = F_raw


@jitable_inline
def mhe_block(p: MHEBlockParams, w: MHEWindow, mp: NDArray[np.float64], ms: NDArray[np.float64],
              mi: NDArray[np.int64], uk: NDArray[np.float64], est: NDArray[np.float64], speeds_ok: bool,
              v: float, omega: float, speed_offset: float, F_applied: float, delta_applied: float,
              has_force: bool, force: float, has_steering: bool, steering: float, steer_offset: float,
              low: float) -> MHEStep:
    """One T_d of the MHE-UIO (:func:`mhe_inputs`, then the kernel's window update and solve on
    the state ``ms``, ``mi``, ``uk``): the estimate in ``est`` unless the status is
    :data:`MHE_DENSE` (or ``p.defer``: the caller solves the window; ``est`` holds F̂_raw)."""
    y0, y1, u0, u1 = mhe_inputs(speeds_ok, v, omega, speed_offset, F_applied, delta_applied, has_force, force,
                                has_steering, steering, steer_offset, low)
    st, F_raw, n, ok = mhe_step(y0, y1, u0, u1, p.mass, w.Y, w.W, w.U, w.XS, w.A, w.B, w.X, mp, ms, mi, uk,
                                True, p.defer)
    if st != MHE_DENSE:
        estimate_out(ms, est, F_raw)
    else:
        est[EO_FRAW] = F_raw
    return MHEStep(st, F_raw, n, ok, u0, u1)
