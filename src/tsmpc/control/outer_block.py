"""The outer step of the cascade as one block (issue 34): what the cascade does at an MPC step
around the TS-MPC's solve.

Before the solve, :func:`outer_errors`: the pose the MPC sees (the accepted or dead-reckoned pose,
or — ``fusion.predict_pose`` off, the paper — the last accepted one, held), the reference it is
measured against (sample k, or — once the speed governor has acted — the reference at the governed
time τ = t − offset, interpolated: :func:`governed_sample`), the errors [e_x, e_y, e_θ] (body frame,
paper eq. "kinematic model"; or against the path's tangent heading and of the velocity pose
θ + α̂, α̂ the MHE's slip plus the course fit's correction, bounded by the slip gate:
:mod:`tsmpc.control.slip_aware`), the offset-free correction of e_θ
(:func:`~tsmpc.control.offset_free.offset_update`) and the MPC's window of v_d, ω_d (from sample k,
or governed: :func:`~tsmpc.control.governor.governed_fill`). After it, :func:`outer_after`: the
plan's events and the speed governor's step (:func:`~tsmpc.control.governor.governor_inputs`,
:func:`~tsmpc.control.governor.governor_update`; the reference time offset advances by
(1 − r) T_c).

One definition, three callers: :class:`~tsmpc.control.cascade.Cascade` calls both through one
compiled call each (``tsmpc.kernels.blocks.outer_call`` / ``after_call``; as Python with
``TSMPC_NO_JIT``), the run engine (``tsmpc.kernels.engine.run``) and the batch compile them into
their step. The solve itself stays the caller's (the TS-MPC's compiled step, or its Python path).

Records: the parameters are :class:`OuterBlockParams` and :class:`GovernBlockParams` (packed into
float vectors by :func:`pack_outer` / :func:`pack_govern`, rebuilt by :func:`unpack_outer` /
:func:`unpack_govern` inside compiled code); the reference a :class:`RefArrays` of its signals
(a window past the end as :meth:`~tsmpc.planning.reference.Reference.window` reads it:
:func:`window_fill`, :func:`window_pose`); the state a float vector of named slots (``OB_*``: the
held pose, the slip gate's pose count, the offset estimate, the reference time offset, the
governor's rate, grip and spin hold), the slip gate's poses an array beside it, the events an
integer vector of named counters (``OC_*``).

The recovery paths (re-anchoring after a blind stop, waiting for the car, the restart's yaw-rate
bound) stay the cascade's Python: the run engine never reaches them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.governor import (
    GovernorParams,
    GovernorState,
    GripParams,
    governed_fill,
    governed_index,
    governor_inputs,
    governor_update,
    interp_unit,
)
from tsmpc.control.inner_block import EST_OK
from tsmpc.control.offset_free import OffsetParams, offset_update
from tsmpc.control.slip_aware import slip_gate_update
from tsmpc.estimation.fusion import SlipFit, slip_correction
from tsmpc.kernels.jit import jitable

__all__ = [
    "MPC_FALLBACK", "MPC_OPTIMAL", "MPC_SOFT", "N_GBP", "N_OB", "N_OBP", "N_OC", "OB_GATEN",
    "OB_GRIP", "OB_HOLD", "OB_HTH", "OB_HX", "OB_HY", "OB_OFFB", "OB_RATE", "OB_TOFF", "OC_CLIPPED",
    "OC_FALLBACK", "OC_GACT", "OC_GSTEPS", "OC_POSE_REJ", "OC_SOFT", "GovernBlockParams",
    "OuterBlockParams", "RefArrays", "governed_sample", "outer_after", "outer_errors", "outer_state",
    "pack_govern", "pack_outer", "pose_errors", "scratch_size", "unpack_govern", "unpack_outer",
    "window_fill", "window_pose"
]

#: The plan's status as a code (MPCStatus OPTIMAL, SOFT, FALLBACK).
MPC_OPTIMAL, MPC_SOFT, MPC_FALLBACK = 1, 2, 3

#: The state's slots: the held pose (X, Y, θ), the slip gate's poses held, the offset-free
#: estimate b̂ [rad], the reference time offset t − τ [s], the governor's rate r, grip μ̂_t (NaN:
#: none yet) and spin hold [s].
OB_HX, OB_HY, OB_HTH, OB_GATEN, OB_OFFB, OB_TOFF, OB_RATE, OB_GRIP, OB_HOLD = range(9)
N_OB = 9
#: The event counters: MPC steps on a rejected pose; plans softened, fallen back; scheduling
#: values clipped (summed); governor actions (r left 1), governed MPC steps (r < 1).
OC_POSE_REJ, OC_SOFT, OC_FALLBACK, OC_CLIPPED, OC_GACT, OC_GSTEPS = range(6)
N_OC = 6
#: Lengths of the packed parameter vectors (:func:`pack_outer`, :func:`pack_govern`).
N_OBP, N_GBP = 16, 24


class RefArrays(NamedTuple):
    """The reference's signals the block reads (float64, C-contiguous; sample period T_c).

    Attributes:
        x: the tracked reference's x_d [m].
        y: its y_d [m].
        theta: its heading θ_d [rad].
        v: its speed v_d [m/s].
        omega: its yaw rate ω_d [rad/s].
        tangent: the path's tangent heading at each sample [rad] (slip_aware.py).
        mpc_v: the MPC's reference speed (the planner's samples or each step's averages) [m/s].
        mpc_omega: the MPC's reference yaw rate [rad/s].
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    theta: NDArray[np.float64]
    v: NDArray[np.float64]
    omega: NDArray[np.float64]
    tangent: NDArray[np.float64]
    mpc_v: NDArray[np.float64]
    mpc_omega: NDArray[np.float64]


class OuterBlockParams(NamedTuple):
    """The outer step's switches and constants.

    Attributes:
        slip_aware: errors of the velocity pose θ + α̂ (``mpc.slip_aware``).
        tangent_heading: against the path's tangent heading (``mpc.tangent_heading``).
        course_slip: α̂ corrected by the course fit (``fusion.course_slip``).
        predict_pose: a rejected pose is dead-reckoned, not held (``fusion.predict_pose``).
        slip_sigma: the slip gate's position noise σ [m].
        offset: the offset-free correction runs (``mpc.offset_free_s`` > 0).
        off: its parameters.
        governor: the speed governor runs (``governor.enabled``).
        Tc: the MPC's period [s].
        N: the MPC's horizon.
        ref_dt: the reference's sample period [s] (the governed time's samples).
        ref_closed: the reference is a closed lap (a window past its end wraps).
        ref_turn: a closed lap's heading turn per lap, a whole number of 2π [rad].
        mpc_dt: the MPC reference's sample period [s].
        mpc_closed: the MPC reference is a closed lap.
    """

    slip_aware: bool
    tangent_heading: bool
    course_slip: bool
    predict_pose: bool
    slip_sigma: float
    offset: bool
    off: OffsetParams
    governor: bool
    Tc: float
    N: int
    ref_dt: float
    ref_closed: bool
    ref_turn: float
    mpc_dt: float
    mpc_closed: bool


class GovernBlockParams(NamedTuple):
    """The speed governor as the outer block runs it.

    Attributes:
        gov: the governor's parameters.
        grip: how it reads the grip.
        preview: reference samples it looks ahead (≥ the MPC's horizon).
        v_min: the friction estimate is read only from this speed on (the dynamic box's) [m/s].
        mass_estimate: the resistance is read with the mass estimate (``fusion.mass_estimate``).
    """

    gov: GovernorParams
    grip: GripParams
    preview: int
    v_min: float
    mass_estimate: bool


def outer_state(pose: NDArray[np.float64] | None) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(state, counters) at the start: the pose held (zeros: none yet), no offset, rate 1."""
    ob = np.zeros(N_OB)
    if pose is not None:
        ob[OB_HX:OB_HTH + 1] = pose
    ob[OB_RATE], ob[OB_GRIP] = 1.0, math.nan
    return ob, np.zeros(N_OC, dtype=np.int64)


def scratch_size(N: int, preview: int) -> int:
    """Length of the scratch vector the block takes (the windows it interpolates)."""
    return 2 * (N + 3) + 2 * (preview + 1) + 15


def pack_outer(p: OuterBlockParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_outer` reads."""
    return np.array([p.slip_aware, p.tangent_heading, p.course_slip, p.predict_pose, p.slip_sigma, p.offset,
                     p.off.gain, p.off.Tc, p.governor, p.Tc, p.N, p.ref_dt, p.ref_closed, p.ref_turn,
                     p.mpc_dt, p.mpc_closed], dtype=np.float64)


@jitable
def unpack_outer(a: NDArray[np.float64]) -> OuterBlockParams:
    """The record of :func:`pack_outer`'s vector."""
    return OuterBlockParams(a[0] != 0.0, a[1] != 0.0, a[2] != 0.0, a[3] != 0.0, a[4], a[5] != 0.0,
                            OffsetParams(a[6], a[7]), a[8] != 0.0, a[9], int(a[10]), a[11], a[12] != 0.0,
                            a[13], a[14], a[15] != 0.0)


def pack_govern(p: GovernBlockParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_govern` reads (GovernorParams' 11 fields,
    GripParams' 10, then preview, v_min, mass_estimate)."""
    return np.array([*p.gov, *p.grip, p.preview, p.v_min, p.mass_estimate], dtype=np.float64)


@jitable
def unpack_govern(a: NDArray[np.float64]) -> GovernBlockParams:
    """The record of :func:`pack_govern`'s vector."""
    gov = GovernorParams(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10])
    grip = GripParams(a[11] != 0.0, a[12], a[13], a[14], a[15], a[16], a[17], a[18], a[19], a[20])
    return GovernBlockParams(gov, grip, int(a[21]), a[22], a[23] != 0.0)


@jitable
def window_fill(a: NDArray[np.float64], k: int, closed: bool, out: NDArray[np.float64]) -> None:
    """``out`` = ``Reference.window(k, out.size)``'s samples of a signal held past an open
    reference's end and wrapped past a closed lap's (v, ω): ``a[k + i]``, else ``a[(k + i) % L]``
    (closed) or ``a[L − 1]``."""
    L = a.size
    for i in range(out.size):
        j = k + i
        if j >= L:
            j = j % L if closed else L - 1
        out[i] = a[j]


@jitable
def window_pose(p: OuterBlockParams, r: RefArrays, k: int, ox: NDArray[np.float64], oy: NDArray[np.float64],
                oth: NDArray[np.float64]) -> None:
    """``Reference.window(k, n)``'s x, y, θ (n = ``ox.size``): past a closed lap's end the lap
    again, θ continued by whole turns; past an open reference's end the pose continued along its
    last v, ω (one T from the last sample, then on)."""
    L = r.x.size
    for i in range(ox.size):
        j = k + i
        if j < L:
            ox[i], oy[i], oth[i] = r.x[j], r.y[j], r.theta[j]
        elif p.ref_closed:
            lap = j // L
            jj = j - lap * L
            ox[i], oy[i], oth[i] = r.x[jj], r.y[jj], r.theta[jj] + lap * p.ref_turn
        else:
            px, py, pth = (ox[i - 1], oy[i - 1], oth[i - 1]) if i > 0 else (r.x[L - 1], r.y[L - 1],
                                                                          r.theta[L - 1])
            th = pth + r.omega[L - 1] * p.ref_dt
            oth[i] = th
            ox[i] = px + r.v[L - 1] * math.cos(th) * p.ref_dt
            oy[i] = py + r.v[L - 1] * math.sin(th) * p.ref_dt


@jitable
def governed_sample(p: OuterBlockParams, r: RefArrays, tau: float, rate: float,
                    buf: NDArray[np.float64]) -> tuple[float, float, float, float, float]:
    """(x_d, y_d, θ_d, v_d, ω_d) at governed time ``tau`` (reference time since its first sample)
    at rate ``rate``: interpolated between the samples around τ, v_d and ω_d times the rate
    (:func:`~tsmpc.control.governor.governed_window`'s first sample). ``buf``: ≥ 15 scratch."""
    k0, s0 = governed_index(tau, p.ref_dt)
    bx, by, bth, bv, bw = buf[0:3], buf[3:6], buf[6:9], buf[9:12], buf[12:15]
    window_pose(p, r, k0, bx, by, bth)
    window_fill(r.v, k0, p.ref_closed, bv)
    window_fill(r.omega, k0, p.ref_closed, bw)
    return (interp_unit(bx, s0), interp_unit(by, s0), interp_unit(bth, s0), interp_unit(bv, s0) * rate,
            interp_unit(bw, s0) * rate)


@jitable
def pose_errors(X: float, Y: float, th: float, xd: float, yd: float, thd: float,
                e: NDArray[np.float64]) -> None:
    """[e_x, e_y, e_θ] of the pose (X, Y, θ) against (x_d, y_d, θ_d) into ``e``: the vehicle-frame
    errors of :func:`~tsmpc.models.kinematic.pose_to_errors`, e_θ wrapped to [−π, π)."""
    dx = xd - X
    dy = yd - Y
    c, s = math.cos(th), math.sin(th)
    e[0] = c * dx + s * dy
    e[1] = -s * dx + c * dy
    e[2] = (thd - th + math.pi) % (2.0 * math.pi) - math.pi


@jitable
def outer_errors(p: OuterBlockParams, r: RefArrays, ob: NDArray[np.float64], cnt: NDArray[np.int64],
                 gate: NDArray[np.float64], slip: SlipFit, t: float, k: int, pose_ok: bool, X: float,
                 Y: float, th: float, has_last: bool, alpha_last: float, has_pred: bool, pred_y: float,
                 v_prev: float, e: NDArray[np.float64], win_v: NDArray[np.float64],
                 win_w: NDArray[np.float64], buf: NDArray[np.float64]) -> bool:
    """An MPC step's errors into ``e`` and its window of v_d, ω_d into ``win_v``, ``win_w``
    (N + 1 each); True when they are the governed reference's.

    ``k``: the reference sample of time ``t``; (X, Y, θ): the cascade's pose (accepted when
    ``pose_ok``, else dead-reckoned); ``alpha_last``: the last estimate's α̂ (``has_last``);
    ``slip``: the course fit's slip model; ``pred_y``: the previous plan's prediction of e_y now
    (``has_pred``); ``v_prev``: the MPC's previous speed command; ``gate``: the slip gate's poses;
    ``buf``: scratch (:func:`scratch_size`)."""
    if not pose_ok:  # the MPC never sees NaN nor a jump: the dead-reckoned pose
        cnt[OC_POSE_REJ] += 1
    else:
        ob[OB_HX], ob[OB_HY], ob[OB_HTH] = X, Y, th
    if not (pose_ok or p.predict_pose):  # (the paper) the pose of the last accepted sample, held
        X, Y, th = ob[OB_HX], ob[OB_HY], ob[OB_HTH]
    governed = p.governor and (cnt[OC_GACT] > 0 or ob[OB_RATE] < 1.0)
    n = p.N + 1
    if governed:  # the reference at the governed time τ = t − offset (governor.py)
        tau, rate = t - ob[OB_TOFF], ob[OB_RATE]
        xd, yd, thd, vd, wd = governed_sample(p, r, tau, rate, buf)
        ay = vd * wd
        x = tau / p.Tc
        kt = min(max(math.floor(x), 0), r.tangent.size - 2)
        f = min(max(x - kt, 0.0), 1.0)
        th_tan = (1.0 - f) * r.tangent[kt] + f * r.tangent[kt + 1]
        k0, s0 = governed_index(tau, p.mpc_dt)
        bv, bw = buf[15:15 + n + 2], buf[15 + n + 2:15 + 2 * (n + 2)]
        window_fill(r.mpc_v, k0, p.mpc_closed, bv)
        window_fill(r.mpc_omega, k0, p.mpc_closed, bw)
        governed_fill(bv, s0, rate, rate, win_v)
        governed_fill(bw, s0, rate, rate, win_w)
    else:
        kk = min(k, r.x.size - 1)
        xd, yd, thd, th_tan = r.x[kk], r.y[kk], r.theta[kk], r.tangent[kk]
        ay = r.v[kk] * r.omega[kk]
        window_fill(r.mpc_v, k, p.mpc_closed, win_v)
        window_fill(r.mpc_omega, k, p.mpc_closed, win_w)
    if p.slip_aware or p.tangent_heading:  # slip_aware.py
        a_hat = alpha_last if p.slip_aware and has_last else 0.0
        if p.slip_aware and has_last:
            # the course-fitted model error at the reference's lateral acceleration (a
            # feed-forward: the measured one would close a fast loop through ω, fusion.py)
            a_hat += slip_correction(slip, ay) if p.course_slip else 0.0
        if p.slip_aware:  # α̂ bounded by the measured course over ground
            a_hat, ng = slip_gate_update(p.slip_sigma, gate, int(ob[OB_GATEN]), X, Y, th, a_hat)
            ob[OB_GATEN] = ng
        th_ref = th_tan if p.tangent_heading else thd
        a = a_hat if math.isfinite(a_hat) else 0.0
        pose_errors(X, Y, th + a, xd, yd, th_ref + 0.5 * 0.0, e)
    else:
        pose_errors(X, Y, th, xd, yd, thd, e)
    if p.offset:  # the offset-free outer loop (offset_free.py)
        ob[OB_OFFB] = offset_update(p.off, ob[OB_OFFB], e[1], pred_y, has_pred, v_prev)
        e[2] = e[2] + ob[OB_OFFB]
    return governed


@jitable
def outer_after(p: OuterBlockParams, g: GovernBlockParams, r: RefArrays, ob: NDArray[np.float64],
                cnt: NDArray[np.int64], status: int, n_clipped: int, t: float, has_last: bool,
                est_status: int, v_hat: float, F_fr: float, saturated: bool, F_applied: float, road_mu: float,
                dmass: float, buf: NDArray[np.float64]) -> None:
    """After an MPC step: the plan's events (its status code ``MPC_*``, ``n_clipped``) and — the
    governor on — its rate for the next step from the grip estimate and the reference ahead; the
    reference time offset advances by (1 − r) T_c.

    The last call's estimate: ``has_last``, its status code ``est_status`` (``EST_*``), v̂, F̂_fr,
    the inner loop saturated; ``F_applied``: the drive force the plant got [N]; ``road_mu``: the
    true μ(road) (the oracle row); ``dmass``: the mass estimate's ΔM̂ [kg] (read with
    ``mass_estimate``); ``buf``: scratch (:func:`scratch_size`)."""
    cnt[OC_SOFT] += 1 if status == MPC_SOFT else 0
    cnt[OC_FALLBACK] += 1 if status == MPC_FALLBACK else 0
    cnt[OC_CLIPPED] += n_clipped
    if not p.governor:
        return
    mass = g.grip.mass
    if g.mass_estimate:
        mass += dmass
    # the friction estimate means nothing below the dynamic box's speeds (the resistance fades at
    # standstill; the MHE starts up there) nor from a rejected or failed sample
    usable = has_last and est_status == EST_OK and v_hat >= g.v_min
    grip, spinning, force_per_kg = governor_inputs(g.grip, F_fr if has_last else math.nan, usable, mass,
                                                   has_last and saturated, F_applied, road_mu)
    k = min(max(math.floor((t - ob[OB_TOFF]) / p.Tc + 1e-6), 0), r.v.size - 1)
    n = g.preview + 1
    o = 15 + 2 * (p.N + 3)
    bv, bw = buf[o:o + n], buf[o + n:o + 2 * n]
    window_fill(r.v, k, p.ref_closed, bv)
    window_fill(r.omega, k, p.ref_closed, bw)
    before = ob[OB_RATE]
    s = governor_update(g.gov, GovernorState(before, ob[OB_GRIP], ob[OB_HOLD]), grip, force_per_kg, bv, bw,
                        spinning)
    rate = s.rate
    ob[OB_RATE], ob[OB_GRIP], ob[OB_HOLD] = rate, s.grip, s.spin_hold
    cnt[OC_GACT] += 1 if before >= 1.0 and rate < 1.0 else 0
    cnt[OC_GSTEPS] += 1 if rate < 1.0 else 0
    ob[OB_TOFF] += (1.0 - rate) * p.Tc
