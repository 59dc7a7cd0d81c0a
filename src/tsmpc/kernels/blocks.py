"""The cascade's compiled calls of its blocks (their one definitions: the inner block
:func:`tsmpc.control.inner_block.inner_block`, the gates :func:`tsmpc.control.gates.gate_block` and
the dead reckoning :func:`tsmpc.control.gates.reckon_block`,
the outer step's :func:`tsmpc.control.outer_block.outer_errors` and
:func:`tsmpc.control.outer_block.outer_after`, the MHE-UIO's step :func:`tsmpc.control.mhe_block.mhe_block`;
the cascade's phases :func:`tsmpc.control._clock.cascade_clock` (:func:`clock_call`),
:func:`tsmpc.control._front.cascade_front`, :func:`tsmpc.control._front.cascade_outer`,
:func:`tsmpc.control._back.cascade_back` and its parts: :func:`front_call`, :func:`outer_phase_call`,
:func:`back_call`, :func:`start_call`, :func:`command_call` on :func:`pack_back`'s vector):
the blocks' records rebuilt from arrays inside the compiled code, because numba's dispatcher types
a record argument field by field (≈ 0.15 µs a field, more than the block's work), an array at once.

:func:`pack` writes :class:`~tsmpc.control.inner_block.InnerBlockParams` and the TS-LQR's
:class:`~tsmpc.control.ts_lqr.LQRLaw` scalars into one float vector (their own packings); :func:`inner_call`
rebuilds both records from it (and the law's arrays, passed as they are: ``prm`` is written in place
by the stiffness fit) and runs the block. :func:`pack_gates`, :func:`gate_call` and
:func:`reckon_call` do the same for the gate block's :class:`~tsmpc.control.gates.GateBlockParams`;
:func:`outer_call` and :func:`after_call` rebuild the outer block's records from their packed vectors
(:func:`~tsmpc.control.outer_block.pack_outer`, :func:`~tsmpc.control.outer_block.pack_govern`) and
its reference from one (8, L) array (:class:`~tsmpc.control.outer_block.RefArrays`' rows).

The block's machine code is part of this module's cache entry although its source is not: the
entry carries the hash of the block modules (:func:`tsmpc.kernels.forget_stale`, as the run engine's).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tsmpc import kernels
from tsmpc.control._back import BackParams, BackState, back_start, cascade_back, cascade_command
from tsmpc.control._clock import ClockParams, cascade_clock, clock_state, pack_clock, unpack_clock
from tsmpc.control._front import (
    FrontParams,
    FrontState,
    OuterParams,
    OuterState,
    cascade_front,
    cascade_outer,
)
from tsmpc.control._mid import AfterState, EstimateParams, EstimateState, cascade_after_plan, cascade_estimate
from tsmpc.control.fusion_block import N_FB, N_FBP, unpack_fusion
from tsmpc.control.gates import (
    GateBlockParams,
    GateParams,
    gate_block,
    gate_state,
    pack_gate_block,
    reckon_block,
    unpack_gate_block,
)
from tsmpc.control.inner_block import (
    N_IBK,
    InnerBlockParams,
    inner_block,
    pack_inner_block,
    start_state,
    unpack_inner_block,
)
from tsmpc.control.mhe_block import MHEBlockParams, MHEWindow, mhe_block
from tsmpc.control.outer_block import RefArrays, outer_after, outer_errors, unpack_govern, unpack_outer
from tsmpc.control.ts_lqr import N_LAW, InnerParams, LQRLaw, pack_law, unpack_law
from tsmpc.estimation.friction_step import FrictionStepParams
from tsmpc.estimation.fusion import N_CP, MassParams, pack_course, unpack_course
from tsmpc.kernels.jit import BLOCK_MODULES

__all__ = ["after_call", "after_plan_call", "back_call", "clock_call", "command_call", "estimate_call",
           "front_call", "gate_call", "inner_call", "mhe_call", "outer_call", "outer_phase_call", "pack",
           "pack_back", "pack_gates", "reckon_call", "warm"]

# entries compiled from other versions of the blocks (or of the law, kernels/lqr.py) are deleted
# before the first call below loads one
kernels.forget_stale(kernels._tree_folder(kernels.numba_cache_dir()), "blocks", ("blocks", "lqr", "mhe"),
                     "blocks.blocks-sha256", BLOCK_MODULES)

#: :func:`pack`'s vector: the inner block's record (inner_block.pack_inner_block), the law's scalars
#: (ts_lqr.pack_law)
N_BP = N_IBK + N_LAW


def pack(p: InnerBlockParams, law: LQRLaw) -> np.ndarray:
    """The scalars of the block's records as the float vector :func:`inner_call` reads
    (:func:`~tsmpc.control.inner_block.pack_inner_block`, then :func:`~tsmpc.control.ts_lqr.pack_law`)."""
    return np.concatenate([pack_inner_block(p), pack_law(law)])


@njit(cache=True, fastmath=False)
def _records(bp, Kv, zlo, zhi, bits, prm):
    """(InnerBlockParams, LQRLaw) of the packed vector and the law's arrays."""
    return unpack_inner_block(bp[:N_IBK]), unpack_law(bp[N_IBK:], Kv, zlo, zhi, bits, prm)


@njit(cache=True, fastmath=False)
def inner_call(bp, Kv, zlo, zhi, bits, prm, s, st, ring, cnt, v, alpha, omega, F_window, F_raw, status,
               v_ref, w_ref):
    """:func:`~tsmpc.control.inner_block.inner_block` of the packed records: (F_xR, δ, saturated,
    compensation, low-speed residual, the TS-LQR step's status)."""
    p, law = _records(bp, Kv, zlo, zhi, bits, prm)
    out = inner_block(p, law, s, st, ring, cnt, v, alpha, omega, F_window, F_raw, status, v_ref, w_ref)
    return out.F_xR, out.delta, out.saturated, out.F_comp, out.F_low_speed, out.status


def pack_gates(p: GateBlockParams) -> np.ndarray:
    """The gate block's record as the float vector :func:`gate_call` reads (GateParams' fields, then
    recovery, reinit_s, repeat: :func:`~tsmpc.control.gates.pack_gate_block`)."""
    return pack_gate_block(p)


@njit(cache=True, fastmath=False)
def _gate_params(gbp):
    """GateParams of the packed record."""
    return GateParams(gbp[0], gbp[1], gbp[2], gbp[3], gbp[4], gbp[5])


@njit(cache=True, fastmath=False)
def gate_call(gbp, gs, cnt, pose, t, fresh, X, Y, theta, v, omega, stamp):
    """:func:`~tsmpc.control.gates.gate_block` of the packed record: (fresh, speeds plausible, pose
    accepted)."""
    return gate_block(unpack_gate_block(gbp), gs, cnt, pose, t, fresh, X, Y, theta, v, omega, stamp)


@njit(cache=True, fastmath=False)
def reckon_call(gbp, pose, v, alpha, omega):
    """:func:`~tsmpc.control.gates.reckon_block` of the packed record."""
    reckon_block(_gate_params(gbp), pose, v, alpha, omega)


@njit(cache=True, fastmath=False)
def _refs(refs):
    """The reference record of its (8, L) stack."""
    return RefArrays(refs[0], refs[1], refs[2], refs[3], refs[4], refs[5], refs[6], refs[7])


@njit(cache=True, fastmath=False)
def outer_call(opk, refs, ob, cnt, gate, slip, t, k, pose_ok, X, Y, th, has_last, alpha_last, has_pred,
               pred_y, v_prev, e, win_v, win_w, buf):
    """:func:`~tsmpc.control.outer_block.outer_errors` of the packed record: True when governed."""
    return outer_errors(unpack_outer(opk), _refs(refs), ob, cnt, gate, slip, t, k, pose_ok, X, Y, th,
                        has_last, alpha_last, has_pred, pred_y, v_prev, e, win_v, win_w, buf)


@njit(cache=True, fastmath=False)
def after_call(opk, gpk, refs, ob, cnt, status, n_clipped, t, has_last, est_status, v_hat, F_fr, saturated,
               F_applied, road_mu, dmass, buf):
    """:func:`~tsmpc.control.outer_block.outer_after` of the packed records."""
    outer_after(unpack_outer(opk), unpack_govern(gpk), _refs(refs), ob, cnt, status, n_clipped, t, has_last,
                est_status, v_hat, F_fr, saturated, F_applied, road_mu, dmass, buf)


@njit(cache=True, fastmath=False)
def mhe_call(mass, Y, W, U, XS, A, B, X, mp, ms, mi, uk, est, speeds_ok, v, omega, speed_offset, F_applied,
             delta_applied, has_force, force, has_steering, steering, steer_offset, low):
    """:func:`~tsmpc.control.mhe_block.mhe_block` of the estimator's arrays (the window solved
    here): (status, F̂_raw, n, sample accepted, u0, u1) as a plain tuple (a NamedTuple's boxing
    costs ≈ 0.45 µs a call)."""
    r = mhe_block(MHEBlockParams(mass, False), MHEWindow(Y, W, U, XS, A, B, X), mp, ms, mi, uk, est,
                  speeds_ok, v, omega, speed_offset, F_applied, delta_applied, has_force, force, has_steering,
                  steering, steer_offset, low)
    return r.status, r.F_raw, r.n, r.ok, r.u0, r.u1


@njit(cache=True, fastmath=False)
def after_plan_call(opk, gpk, ckp, refs, ob, cnt, cmd, ck, up, u0, u1, ok, v, status, n_clipped, t,
                    est_status, v_hat, F_fr, road_mu, dmass, buf):
    """:func:`~tsmpc.control._mid.cascade_after_plan` of the packed records (the clock's:
    :func:`~tsmpc.control._clock.pack_clock`)."""
    cascade_after_plan(unpack_outer(opk), unpack_govern(gpk), unpack_clock(ckp), _refs(refs),
                       AfterState(ob, cnt, cmd, ck, up), u0, u1, ok, v, status, n_clipped, t, est_status,
                       v_hat, F_fr, road_mu, dmass, buf)


@njit(cache=True, fastmath=False)
def clock_call(ckp, ck, cc, t):
    """:func:`~tsmpc.control._clock.cascade_clock` of the packed record: the call's time."""
    return cascade_clock(unpack_clock(ckp), ck, cc, t)


@njit(cache=True, fastmath=False)
def estimate_call(mass, Y, W, U, XS, A, B, X, mp, ms, mi, uk, est, fb, cmd, course_speed, speeds_ok, v,
                  has_force, force, has_steering, steering):
    """:func:`~tsmpc.control._mid.cascade_estimate` of the estimator's arrays and the blocks' vectors:
    (status, F̂_raw, n, sample accepted, u0, u1) as a plain tuple."""
    r = cascade_estimate(EstimateParams(MHEBlockParams(mass, False), course_speed),
                         MHEWindow(Y, W, U, XS, A, B, X), EstimateState(mp, ms, mi, uk, est, fb, cmd),
                         speeds_ok, v, has_force, force, has_steering, steering)
    return r.status, r.F_raw, r.n, r.ok, r.u0, r.u1


# ---------------------------------------------------------------------------- the phase after the MHE
#: The packed vector of :func:`pack_back`: GateParams' 6 fields, the fusion block's record
#: (fusion_block.pack_fusion), the course fusion's CourseParams (N_CP fields, fusion.pack_course),
#: the inner block's (:func:`pack`).
BK_GATE, BK_FUS = 0, 6
BK_COURSE = BK_FUS + N_FBP
BK_INNER = BK_COURSE + N_CP
N_BK = BK_INNER + N_BP


def pack_back(p: BackParams, law: LQRLaw | None) -> np.ndarray:
    """The phase's records (and the law's scalars; zeros without a compiled law) as the float
    vector :func:`back_call` reads."""
    from tsmpc.control.fusion_block import pack_fusion

    inner = pack(p.inner, law) if law is not None else np.zeros(N_BP)
    out = np.concatenate([np.array(p.gates, dtype=np.float64), pack_fusion(p.fusion, p.steer),
                          pack_course(p.fusion.cp), inner])
    assert out.size == N_BK
    return out


@njit(cache=True, fastmath=False)
def _course_params(a):
    """CourseParams of its packed fields (:func:`~tsmpc.estimation.fusion.unpack_course`)."""
    return unpack_course(a)


@njit(cache=True, fastmath=False)
def _back_params(pk):
    """BackParams of the packed vector (the inner block's record without the law)."""
    fbp, sp = unpack_fusion(pk[BK_FUS:BK_FUS + N_FBP], _course_params(pk[BK_COURSE:BK_INNER]))
    return BackParams(_gate_params(pk), fbp, sp, unpack_inner_block(pk[BK_INNER:BK_INNER + N_IBK]))


@njit(cache=True, fastmath=False)
def back_call(pk, Kv, zlo, zhi, bits, prm, pose, fb, cur, sa, cmd, s, st, ring, cnt, ok, pose_ok, th, v,
              v_hat, a_hat, w_hat, F_fr, F_raw, status, delta, force, v_ref, w_ref):
    """:func:`~tsmpc.control._back.cascade_back` of the packed records: (F_xR, δ sent, saturated,
    the TS-LQR step's status, compensation, low-speed residual)."""
    _p, law = _records(pk[BK_INNER:], Kv, zlo, zhi, bits, prm)
    state = BackState(pose, fb, cur, sa, cmd, s, st, ring, cnt)
    out = cascade_back(_back_params(pk), law, state, ok, pose_ok, th, v, v_hat, a_hat, w_hat, F_fr, F_raw,
                       status, delta, force, v_ref, w_ref)
    return out.F_xR, out.delta, out.saturated, out.status, out.F_comp, out.F_low_speed


@njit(cache=True, fastmath=False)
def start_call(pk, pose, fb, cur, sa, cmd, ok, pose_ok, th, v, v_hat, a_hat, w_hat, status, delta, force,
               blind):
    """:func:`~tsmpc.control._back.back_start` of the packed records (the command record read only)."""
    back_start(_back_params(pk), BackState(pose, fb, cur, sa, cmd, fb, fb, fb, np.empty(0, np.int64)), ok,
               pose_ok, th, v, v_hat, a_hat, w_hat, status, delta, force, blind)


@njit(cache=True, fastmath=False)
def command_call(pk, fb, sa, cmd, F, delta, saturated, low, alpha):
    """:func:`~tsmpc.control._back.cascade_command` of the packed records: the angle sent."""
    e = cmd[:0]
    return cascade_command(_back_params(pk), BackState(e, fb, e, sa, cmd, e, e, e, np.empty(0, np.int64)), F,
                           delta, saturated, low, alpha)


@njit(cache=True, fastmath=False)
def front_call(gbp, pk, ckp, n_inner, gs, gcnt, pose, fb, ivs, cur, cmd, ck, cc, t, has_stamp, X, Y, th, v,
               omega, stamp, t_off, v_d, w_d):
    """:func:`~tsmpc.control._front.cascade_front` of the packed records (the gate block's,
    :func:`pack_gates`; the fusion block's, :func:`pack_back`; the clock's,
    :func:`~tsmpc.control._clock.pack_clock`): (fresh, speeds plausible, pose accepted, the MPC
    runs, ω less the bias, the blind stop ended)."""
    fbp, _sp = unpack_fusion(pk[BK_FUS:BK_FUS + N_FBP], _course_params(pk[BK_COURSE:BK_INNER]))
    gp = unpack_gate_block(gbp)
    state = FrontState(gs, gcnt, pose, fb, ivs, cur, cmd, ck, cc)
    out = cascade_front(FrontParams(gp, fbp, n_inner, unpack_clock(ckp)), state, t, has_stamp, X, Y, th, v,
                        omega, stamp, t_off, v_d, w_d)
    return out.fresh, out.speeds_ok, out.pose_ok, out.mpc_step, out.omega, out.recovered


@njit(cache=True, fastmath=False)
def outer_phase_call(pk, opk, ckp, stiffness, refs, fb, ivs, sa, mp, prm, ob, oc, gate, pose, cmd, ck, up, t,
                     pose_ok, X, Y, v, omega, v_hat, has_pred, pred_y, e, win_v, win_w, buf):
    """:func:`~tsmpc.control._front.cascade_outer` of the packed records (the course fusion's of
    :func:`pack_back`, the outer block's of ``outer_block.pack_outer``, the clock's) and the (8, L)
    reference: (k, re-anchored, the stiffnesses given, governed)."""
    p = OuterParams(stiffness, _course_params(pk[BK_COURSE:BK_INNER]), unpack_outer(opk), unpack_clock(ckp))
    state = OuterState(fb, ivs, sa, mp, prm, ob, oc, gate, pose, cmd, ck, up)
    return cascade_outer(p, _refs(refs), state, t, pose_ok, X, Y, v, omega, v_hat, has_pred, pred_y, e, win_v,
                         win_w, buf)


def warm() -> None:
    """Compile (or load from the cache) the signatures the cascade uses."""
    gs, gcnt = gate_state()
    gp = GateBlockParams(GateParams(-1.0, 40.0, 4.0, 0.05, 0.01, 0.01), True, 2.0, True)
    pose = np.array([1.0, 2.0, 0.1, 0.0])
    gate_call(pack_gates(gp), gs, gcnt, pose, 0.01, True, 1.0, 2.0, 0.1, 10.0, 0.1, -np.inf)
    reckon_call(pack_gates(gp), pose, 10.0, 0.0, 0.1)
    Kv = np.zeros((8, 2, 6))
    Kv[:, 0, 0] = -100.0
    Kv[:, 1, 2] = -0.1
    bits = np.array([[(i >> j) & 1 for j in range(3)] for i in range(8)], dtype=np.bool_)
    prm = np.array([683.0, 560.0, 25000.0, 25000.0, 0.758, 1.036, 4.9, 0.4])
    p = InnerBlockParams(True, FrictionStepParams(30, 5.0), True, MassParams(683.0, 0.01, 30, 0.3, True),
                         InnerParams(True, False, True, 2.0, 3000.0))
    law = LQRLaw(Kv, np.array([-0.4, 2.0, -0.1]), np.array([0.4, 20.0, 0.1]), bits, prm, 10.0, 0.9, 0.01,
                 -2000.0, 10000.0, -0.4, 0.4, True, 0.3)
    o3, n = np.ones(3), 3  # the MHE block (a window of 3; the types are the cascade's)
    mp = np.concatenate([o3, np.ones(2), o3, [1e-10], -o3 * 100, o3 * 100, -o3, o3 * 20,
                         [683.0, 560.0, 25000.0, 25000.0, 0.7, 1.0, 4.9, 0.4, 0.01]])
    estimate_call(683.0, np.zeros((n + 1, 2)), np.ones(n + 1), np.zeros((n, 2)), np.ones((n + 1, 3)) * 5.0,
                  np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n + 1, 3)), mp, np.ones(7) * 5.0,
                  np.zeros(3, dtype=np.int64), np.zeros(2), np.zeros(5), np.zeros(N_FB), np.zeros(7), False,
                  True, 5.0, False, 0.0, False, 0.0)
    st, ring, cnt = start_state(30)
    inner_call(pack(p, law), law.Kv, law.zlo, law.zhi, law.bits, law.prm, np.zeros(6), st, ring, cnt, 10.0,
               0.0, 0.0, 100.0, 90.0, 1, 10.0, 0.0)
    _warm_phases(gp, p, law, pose, gs, gcnt)


def _warm_phases(gp: GateBlockParams, p: InnerBlockParams, law: LQRLaw, pose: np.ndarray, gs: np.ndarray,
                 gcnt: np.ndarray) -> None:
    """Compile (or load) the phases' calls for the cascade's types (the warm-up's records)."""
    from tsmpc.control.fusion_block import FusionParams, fusion_state
    from tsmpc.estimation import fusion as fu

    cp = fu.course_params(0.1, 0.05, True, 25000.0, 25000.0, 683.0, 560.0, 0.758, 1.036, 9.81, 0.01, 10)
    gyro = fu.gyro_params(0.01, 0.01, 0.01)
    sp = fu.steer_params(0.01, 25000.0, 25000.0, 0.758, 1.036, 683.0, 560.0)
    fusion = FusionParams(True, True, True, True, -0.4, 0.4, gyro, cp)
    bpk = pack_back(BackParams(gp.gates, fusion, sp, p), law)
    fb, ivs, cur = fusion_state(fu.gyro_start(gyro), fu.steer_start(sp), 0.0, 0.0, fu.course_start(cp),
                                fu.NO_INTERVAL)
    cmd, sa, ref = np.zeros(7), np.zeros(3), np.ones((2, 20)) * 10.0
    ckp = pack_clock(ClockParams(0.01, 0.1, 0.1, 0.1, True, 0.5, 10, False, True, 0.8))
    ck, cc = clock_state()
    clock_call(ckp, ck, cc, 0.02)
    front_call(pack_gates(gp), bpk, ckp, 10, gs, gcnt, pose, fb, ivs, cur, cmd, ck, cc, 0.02, False, 1.0, 2.0,
               0.1, 10.0, 0.1, -np.inf, 0.0, ref[0], ref[1])
    st, ring, cnt = start_state(30)
    back_call(bpk, law.Kv, law.zlo, law.zhi, law.bits, law.prm, pose, fb, cur, sa, cmd, np.zeros(6), st, ring,
              cnt, True, True, 0.1, 10.0, 10.0, 0.0, 0.1, 100.0, 90.0, 1, 0.0, 0.0, 10.0, 0.1)
    start_call(bpk, pose, fb, cur, sa, cmd, True, True, 0.1, 10.0, 10.0, 0.0, 0.1, 1, 0.0, 0.0, False)
    command_call(bpk, fb, sa, cmd, 0.0, 0.0, False, 0.0, 0.0)
