"""Whole-run engine: the simulator's loop (:func:`tsmpc.sim.simulator.simulate`) with the cascade
(:class:`tsmpc.control.cascade.Cascade`) and the built-in plant in one compiled call.

Every T_d the kernel does what one iteration of ``simulate`` does — the sensor step
(:func:`tsmpc.sensors.sensor_step`, on the run's draws and the fault's records that
:class:`~tsmpc.sensors.SensorRun` set up), the outer-step log and the divergence test (the
recorder block, :mod:`tsmpc.sim.record_block`), ``Cascade.step`` (sample gates, dead reckoning,
the course fusion and its fits, the slip-aware outer-loop errors, the TS-MPC every T_c/T_d calls,
the MHE-UIO, the mass-error terms, the TS-LQR) and the plant's T_d/h RK4 steps — and logs into
the recorder block's preallocated arrays through its functions, as the Python loop does.
The blocks are the compiled kernels the Python wrappers call: the TS-MPC's step (paper eq. "MPC";
:func:`~tsmpc.kernels.mpc.guarded_step`), the MHE-UIO's window (eqs. "MHE", "disturb_estimation";
:func:`~tsmpc.kernels.mhe.window_step`, inside the MHE block :func:`~tsmpc.control.mhe_block.mhe_block`
with its inputs and status), the TS-LQR (Sec. 3.2; its step's block
:func:`~tsmpc.control.ts_lqr.inner_step` around :func:`~tsmpc.kernels.lqr.lqr_step`, inside the
inner block :func:`~tsmpc.control.inner_block.inner_block` with friction-step detection and the
mass terms)
and the plant's RK4 block (the single-track plant; :func:`~tsmpc.kernels.plant.rk4_block`). The
``@jitable`` blocks (:mod:`tsmpc.kernels.jit`: the sample gates, the fusion estimators of
:mod:`tsmpc.estimation.fusion`, friction-step detection, the outer step's errors, window, offset
correction and speed governor of :mod:`tsmpc.control.outer_block`, …) are the cascade's own
functions, compiled in, their records loaded from and stored to the state slots around each call.
The cascade's glue between them is written once too, as its phases (issue 34), which
``Cascade.step`` calls and this kernel compiles in: :func:`~tsmpc.control._clock.cascade_clock`
(the call's time), :func:`~tsmpc.control._front.cascade_front` (the stamp and the recovery's
watch, the gates, the MPC's turn, the fusion block before the MPC),
:func:`~tsmpc.control._front.cascade_outer` (an MPC step before the solve: the recovery's restart
and the reference sample, the stiffness block, the outer block's errors and window),
:func:`~tsmpc.control._mid.cascade_after_plan` (the plan's bookkeeping: its input kept, the outer
block after the solve), :func:`~tsmpc.control._mid.cascade_estimate` (the MHE block on its inputs)
and :func:`~tsmpc.control._back.cascade_back` (after the MHE: dead reckoning, the fusion block after
it, the inner block, the servo and the command record). The recovery's blind stop is the Python
loop's: the kernel returns BLINDED when it begins and the caller gives up (the run goes to the
Python loop). What remains here is ported operation by operation (same order, same rounding,
Python's ``min``/``max``/``%`` and ``math.hypot``): the simulator's loop, the MPC's fast path and
the plan's copy, the order of the phases in ``Cascade._step`` and the start state
(``_PORTED`` in :mod:`tsmpc.sim.engine`), so the engine reproduces the Python loop to the last
bit. ``run`` strings a step's phases together: :func:`_start_phase`, :func:`_mpc_fast`,
:func:`_plan_phase`, :func:`_mhe_phase`, the phase after the MHE and :func:`_plant_phase` (inlined
into it; on arrays borrowed from the caller, :func:`run_borrowed`, they cost the engine's run
about 3 % against the phases written out in ``run``).

Where a block's compiled fast path does not decide a step (the MPC's condensed QP / SOCP path, the
MHE's dense QP with an active state bound, a singular reference gain of the TS-LQR, a non-finite
plant state) the kernel *returns* with a code and the state of the step in its arrays; the caller
(:mod:`tsmpc.sim.engine`) runs that block's Python path, writes its answer back and calls the
kernel again, which resumes where it stopped (``si[SI_PHASE]``).

The state lives in flat arrays indexed by the module constants below (numba compiles them as
constants): ``fp``/``ip`` parameters, ``sf``/``si`` state, ``sc`` the current step's intermediate
values.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from llvmlite import ir
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic as _numba_intrinsic

from tsmpc.control._back import (
    CM_HASLAST,
    CM_SAT,
    N_CM,
    BackParams,
    BackState,
    cascade_back,
    cascade_command,
)
from tsmpc.control._clock import (
    CC_BLIND,
    CC_RECOVER,
    CC_STALE,
    CC_STAMP,
    CC_TIME,
    CK_BLIND,
    CK_TLAST,
    N_CC,
    N_CK,
    N_CKP,
    cascade_clock,
    unpack_clock,
)
from tsmpc.control._front import (
    FrontParams,
    FrontState,
    OuterParams,
    OuterState,
    cascade_front,
    cascade_outer,
)
from tsmpc.control._mid import (
    AfterState,
    EstimateParams,
    EstimateState,
    cascade_after_plan,
    cascade_estimate,
)
from tsmpc.control.fusion_block import (
    N_FB,
    N_FBP,
    unpack_fusion,
)
from tsmpc.control.gates import (
    GC_JUMP,
    GC_NAN,
    GC_REINIT,
    GC_REPEATED,
    GC_SPEED,
    N_GBK,
    N_GC,
    N_GS,
    N_PO,
    PO_T,
    unpack_gate_block,
)
from tsmpc.control.inner_block import (
    EST_FAILED,
    EST_OK,
    EST_REJECTED,
    EST_WARMUP,
    IC_FAILED,
    IC_FSTEPS,
    IC_REJECTED,
    IC_SATURATED,
    N_IB,
    N_IBK,
    N_IC,
    block_delta_mass,
    unpack_inner_block,
)
from tsmpc.control.mhe_block import MHE_DENSE, N_EO, MHEBlockParams, MHEWindow
from tsmpc.control.outer_block import (
    N_GBP,
    N_OB,
    N_OBP,
    N_OC,
    OB_RATE,
    OB_TOFF,
    OC_CLIPPED,
    OC_FALLBACK,
    OC_POSE_REJ,
    OC_SOFT,
    RefArrays,
    unpack_govern,
    unpack_outer,
)
from tsmpc.control.stiffness_block import N_SA
from tsmpc.control.ts_lqr import LQR_NUMPY, N_LAW, unpack_law
from tsmpc.estimation.fusion import N_CP, unpack_course
from tsmpc.kernels.jit import cpython_hypot
from tsmpc.kernels.mhe import (  # the MHE's records
    MHE_FAILED,
    MHE_OK,
    MHE_REJECTED,
    MHE_WARMUP,
    MI_NFAIL,
    MI_NREJ,
    MS_ARR,
    MS_F,
    MS_MARGIN,
    N_MI,
    N_MS,
)
from tsmpc.kernels.mpc import guarded_step
from tsmpc.kernels.plant import rk4_block
from tsmpc.scenarios import apply_events, paper_mu, patch_mu
from tsmpc.sensors import N_SP, N_SS, SensorDraws, sensor_step, store_state, unpack_params, unpack_state
from tsmpc.sim.record_block import (  # (LI_TMHE, LI_TLQR, LO_TMPC: the engine's block times)
    LI_TLQR,
    LI_TMHE,
    LO_TMPC,
    logged_reference,
    off_road,
    record_inner,
    record_outer,
    record_plan,
    travelled,
)
from tsmpc.vehicle.actuators import (
    ActuatorParams,
    ActuatorState,
    actuator_start,
    actuator_substep,
    applied_mean,
    wheel_steering,
)
from tsmpc.vehicle.single_track import friction_force

__all__ = ["friction_mu", "hypot_py", "run", "ticks", "warm"]

# ---------------------------------------------------------------------------- return codes
# (BLINDED: the blind stop began — recovery's blind stop and restart run in the Python loop)
DONE, NEED_MPC, NEED_MHE, NEED_LQR, NEED_PLANT, DIVERGED, BLINDED = range(7)
# phases of a step (where a resumed call continues)
PH_START, PH_PLAN, PH_MHE, PH_POST_MHE, PH_POST_LQR, PH_POST_PLANT = range(6)
PH_PLANT = 6  # (within a call: the command is made, the plant steps)
# MHE statuses (EstimatorStatus) and MPC statuses (MPCStatus) as codes
ST_OK, ST_REJECTED, ST_FAILED, ST_WARMUP = MHE_OK, MHE_REJECTED, MHE_FAILED, MHE_WARMUP
assert (ST_OK, ST_REJECTED, ST_FAILED, ST_WARMUP) == (EST_OK, EST_REJECTED, EST_FAILED, EST_WARMUP)
MPC_OPTIMAL, MPC_SOFT, MPC_FALLBACK = 1, 2, 3
# event counters: the cascade's own, then the gate block's, the inner block's and the outer block's
# (their GC_*, IC_* and OC_* counters, views of ev)
(EV_TIME_REJ, EV_STAMP_REJ, EV_BLIND, EV_RECOVER, EV_STALE_REJ, EV_STEP_ERR, EV_GATES) = range(7)
# (the first N_CC are the cascade's time's counters, tsmpc.control._clock's CC_* slots)
assert (CC_TIME, CC_STAMP, CC_BLIND, CC_RECOVER, CC_STALE, N_CC) == (
    EV_TIME_REJ, EV_STAMP_REJ, EV_BLIND, EV_RECOVER, EV_STALE_REJ, EV_STEP_ERR)
EV_INNER = EV_GATES + N_GC
EV_OUTER = EV_INNER + N_IC
N_EVENTS = EV_OUTER + N_OC
#: the slot of each of Cascade.events' counters, in its order
EVENT_SLOTS = (EV_OUTER + OC_SOFT, EV_OUTER + OC_FALLBACK, EV_OUTER + OC_CLIPPED, EV_INNER + IC_REJECTED,
               EV_INNER + IC_FAILED, EV_INNER + IC_SATURATED, EV_OUTER + OC_POSE_REJ, EV_TIME_REJ,
               EV_STAMP_REJ, EV_GATES + GC_SPEED,
               EV_GATES + GC_JUMP, EV_GATES + GC_NAN, EV_GATES + GC_REINIT, EV_BLIND, EV_RECOVER,
               EV_STALE_REJ, EV_STEP_ERR, EV_GATES + GC_REPEATED, EV_INNER + IC_FSTEPS)

# ---------------------------------------------------------------------------- float parameters
(FP_TD, FP_TC, FP_H, FP_MU_NOM, FP_MG, FP_MHE_MASS, FP_BOUND, FP_A_GF, FP_A_GD, FP_A_RMAX,
 FP_A_DOFF) = range(11)
FP_FB = 11  # the fusion block's parameters (N_FBP values, tsmpc.control.fusion_block.pack_fusion)
FP_SENS = FP_FB + N_FBP  # the sensor block's parameters (N_SP of them, tsmpc.sensors.pack_params)
FP_OB = FP_SENS + N_SP  # the outer block's OuterBlockParams (N_OBP values, outer_block.pack_outer)
FP_GB = FP_OB + N_OBP  # its GovernBlockParams (N_GBP values, outer_block.pack_govern)
FP_CK = FP_GB + N_GBP  # the cascade's time's ClockParams (N_CKP values, _clock.pack_clock)
FP_GBK = FP_CK + N_CKP  # the gate block's GateBlockParams (N_GBK values, gates.pack_gate_block)
FP_IBK = FP_GBK + N_GBK  # the inner block's InnerBlockParams (N_IBK values, inner_block.pack_inner_block)
FP_LAW = FP_IBK + N_IBK  # the TS-LQR's LQRLaw's scalars (N_LAW values, ts_lqr.pack_law)
FP_CP = FP_LAW + N_LAW  # the course fusion's CourseParams (N_CP values, fusion.pack_course)
N_FP = FP_CP + N_CP
# ---------------------------------------------------------------------------- integer parameters
(IP_NIN, IP_NSUB, IP_N, IP_NW, IP_REFLEN, IP_ANYCOURSE, IP_CSPEED, IP_STIFF, IP_MFORCE, IP_MSTEER,
 IP_ACT, IP_ACT_N, IP_ACT_NRK, IP_DEFER) = range(14)
N_IP = 14
# ---------------------------------------------------------------------------- float state
(SF_STRAVEL, SF_POSE, _P1, _P2, SF_POSET, _FREE15, _FREE16, _FREE17, SF_UPREV, _U1, _FREE38, _FREE39,
 SF_PLANTU, _PU1, _FREE40, _FREE12, _G1, _G2, _G3, _G4, _CFREE1, _CFREE2, _CFREE3,
 _CFREE4, _CFREE5, _CFREE6, _CFREE7, _CFREE8, _CFREE9, _CFREE10, _CFREE11, _CFREE12, _CFREE13, _FREE18,
 _FREE1, _CFREE14,
 _FREE4, SF_SA, _SA1, _SA2, _SA3, _SA4, _SA5, SF_MX, _MX1, _MX2, SF_MF,
 SF_ARR, _AR1, _AR2,
 _MSMARGIN, SF_ACT, _AC1, _FREE41, _FREE9, _FREE10, _FREE11, _FREE2, _FREE3, _CFREE16,
 _CFREE17, _FREE13, _J1, _J2, _J3, _FREE14,
 _FREE19, _FREE20, _FREE21, _FREE22,
 _FREE23, _FREE24, _FREE25, _FREE26, _FREE27, _FREE28, _FREE29, _FREE30, _FREE31, _FREE32, _FREE33,
 _FREE34, _FREE35, _FREE36, _FREE37) = range(85)
SF_IB = 85  # the inner block's state (N_IB values, tsmpc.control.inner_block's IB_* slots)
assert SF_POSET == SF_POSE + PO_T  # the gate block's pose record (tsmpc.control.gates' PO_* slots)
SF_GS = SF_IB + N_IB  # the gate block's state (N_GS values, tsmpc.control.gates' GS_* slots)
SF_SENS = SF_GS + N_GS  # the sensor block's state (N_SS values, tsmpc.sensors.pack_state)
SF_OB = SF_SENS + N_SS  # the outer block's state (N_OB values, tsmpc.control.outer_block's OB_* slots)
SF_FB = SF_OB + N_OB  # the fusion block's state (N_FB values, tsmpc.control.fusion_block's FB_* slots)
SF_CMD = SF_FB + N_FB  # the command record (N_CM values, tsmpc.control._back's CM_* slots)
SF_CK = SF_CMD + N_CM  # the cascade's time's state (N_CK values, tsmpc.control._clock's CK_* slots)
N_SF = SF_CK + N_CK
SF_TOFF = SF_OB + OB_TOFF  # (the reference time offset, the governed rate: the caller reads them)
SF_GRATE = SF_OB + OB_RATE
# ---------------------------------------------------------------------------- integer state
(SI_M, SI_PHASE, _SFREE17, _SFREE18, _SFREE5, _SFREE6, _CFREE18, _SFREE0, _CFREE19,
 _CFREE20, _SFREE1, _SFREE2, _SFREE10, SI_NY, SI_NREJ, SI_NFAIL, SI_HASPREV,
 SI_FRESH, SI_SPOK, SI_POSEOK, _SFREE7, SI_MHEN, SI_MHEFULL, SI_MHEOK, SI_ESTSTAT,
 SI_PSTAT, SI_PIT, SI_PQPIT, SI_PCLIP, _SFREE19, SI_TICK0, SI_ACTHAS, _SFREE3, _SFREE4,
 _SFREE8, _SFREE9, SI_GWIN,
 _SFREE11, _SFREE12, _SFREE13, _SFREE14, _SFREE15, _SFREE16,
 _CFREE21) = range(44)
N_SI = 44
# the MHE's state slots are its records' (kernels.mhe: ms = [x̂, F̂, x̄_0], mi = [samples, rejected, failed])
assert SF_MF == SF_MX + MS_F and SF_ARR == SF_MX + MS_ARR and _MSMARGIN == SF_MX + MS_MARGIN
assert SF_SA + N_SA == SF_MX  # the stiffness block's record (stiffness_block.SA_*)
assert SI_NREJ == SI_NY + MI_NREJ and SI_NFAIL == SI_NY + MI_NFAIL
# ---------------------------------------------------------------------------- step scratch
(SC_Y, _Y1, _Y2, _Y3, _Y4, SC_EMEAS, _E1, _E2, SC_EST, _S1, _S2, SC_ESTF, SC_ESTFR, SC_VREF,
 SC_WREF, SC_UMHE, _UM1, SC_SAT, _SCF2, _SCF3, SC_COMP, SC_LOWF, SC_OF, SC_OD, SC_MU, SC_EY,
 SC_PU, _PU2, SC_UK, _UK1, _CFREE0, _CFREE1, _CFREE2, SC_GROW, _GR1, _GR2, _GR3, _GR4) = range(38)
N_SC = 38  # then the MPC's window's v and ω, N + 1 each, then the outer block's scratch
# (outer_block.scratch_size)
# course intervals: the fusion block's rows (tsmpc.control.fusion_block's IV_* slots, N_IV of them)
# the log's columns are the recorder block's (tsmpc.sim.record_block: LI_*, LO_*, LOI_*)

# friction programs (the profiles of tsmpc.scenarios / tsmpc.conditions as data)
FR_CONST, FR_PAPER, FR_PATCH = 0, 1, 2



# ============================================================================ primitives
def intrinsic(fn: Callable[..., Any]) -> Any:
    """numba's ``@intrinsic``, typed for the type checkers: numba's decorator is unannotated, so
    pyright takes the decorated function for the undecorated one and asks for the typing-context
    argument that numba supplies (the intrinsic is called without it)."""
    return _numba_intrinsic(fn)


@intrinsic
def _ticks(typingctx):
    """The CPU's cycle counter (rdtsc on x86): the block timings, converted to seconds by the
    caller against the call's wall time."""
    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                            "llvm.readcyclecounter")
        return builder.call(fn, [])
    return types.int64(), codegen


@intrinsic
def _fma(typingctx, a, b, c):
    """a·b + c with one rounding (llvm.fma)."""
    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(d, [d, d, d]),
                                            "llvm.fma.f64")
        return builder.call(fn, args)
    return types.float64(types.float64, types.float64, types.float64), codegen


@intrinsic
def _borrowed(typingctx, arr):
    """``arr`` as a view *without* a reference count (no meminfo, like numba.carray's arrays), for
    :func:`run_borrowed`: every view run() takes of its ~55 arrays (slices, records of arrays, the
    phases' arguments) would otherwise count references atomically, about a hundred times a step;
    the caller's arrays outlive the call."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        from numba.np.arrayobj import populate_array

        a = context.make_array(arr)(context, builder, args[0])
        out = context.make_array(arr)(context, builder)
        populate_array(out, data=a.data, shape=cgutils.unpack_tuple(builder, a.shape),
                       strides=cgutils.unpack_tuple(builder, a.strides), itemsize=a.itemsize, meminfo=None)
        return out._getvalue()
    return arr(arr), codegen


@njit(cache=True, fastmath=False)
def _pmax(a, b):
    """Python's ``max(a, b)`` (the first argument unless the second is greater)."""
    return b if b > a else a


@njit(cache=True, fastmath=False)
def _pmin(a, b):
    """Python's ``min(a, b)``."""
    return b if b < a else a


@njit(cache=True, fastmath=False)
def _clamp(x, lo, hi):
    """``min(max(x, lo), hi)`` with Python's min/max."""
    return _pmin(_pmax(x, lo), hi)


#: ``math.hypot`` of CPython ≤ 3.11 to the last bit, compiled (:func:`tsmpc.kernels.jit.cpython_hypot`;
#: not cached on its own: its cache entry would be keyed by kernels/jit.py, outside the engine's
#: entries that a broken cache's repair deletes)
hypot_py = njit(cache=False, fastmath=False)(cpython_hypot)


@njit(cache=True, fastmath=False)
def friction_mu(t, s, frb, patches, events):
    """μ(road) at time t and travelled distance s, a friction profile of :mod:`tsmpc.scenarios` as
    data: ``frb`` = [kind, …] the base profile (ConstantFriction [value], PaperFriction [dry,
    ripple, earth, ice, wet], PatchFriction [base, lap length] with ``patches`` its table), then the
    ``events`` table of an EventFriction. The profiles' own functions (one definition each)."""
    kind = int(frb[0])
    if kind == FR_CONST:
        m = frb[1]
    elif kind == FR_PAPER:
        m = paper_mu(t, frb[1], frb[2], frb[3], frb[4], frb[5])
    else:
        m = patch_mu(s, frb[1], frb[2], patches)
    return apply_events(m, t, s, events)


@njit(cache=True, fastmath=False)
def _sensor(m, n_in, Tc, Td, x, noise, u_drop, draws, sp, ss, fifo, y):
    """The sensor step (:func:`tsmpc.sensors.sensor_step`, one definition) at step m on the
    records of the slots: ``sp`` the parameters' (:func:`unpack_params`), ``ss`` the states'
    scalars, ``fifo`` the delay's rows. ``y`` (5,) in place."""
    bs, ms = unpack_state(ss, fifo)
    s, bs, ms = sensor_step(sp, SensorDraws(noise, u_drop, draws), bs, ms, m, n_in, Tc, Td, x)
    store_state(ss, bs, ms)
    y[0], y[1], y[2], y[3], y[4] = s


# ============================================================================ fusion
# The course fusion's state is the fusion block's (sf[SF_FB:], the ring ivs, the open interval
# cur: tsmpc.control.fusion_block's FB_* and IV_* slots, its course_load / course_store).
@njit(cache=True, fastmath=False)
def _delta_mass(sf, fp):
    """ΔM̂ of the inner block's mass fit (:func:`block_delta_mass` of its record, Cascade._ib)."""
    return block_delta_mass(unpack_inner_block(fp[FP_IBK:FP_IBK + N_IBK]), sf[SF_IB:SF_IB + N_IB])


# ============================================================================ outer block
@njit(cache=True, fastmath=False, inline="always")
def _outer_views(fp, sf, ev, sc, N):
    """The outer block's record (Cascade._ob_p), state, counters and scratch (after the MPC's
    window in ``sc``: v_d, ω_d, N + 1 each)."""
    return (unpack_outer(fp[FP_OB:FP_OB + N_OBP]), sf[SF_OB:SF_OB + N_OB], ev[EV_OUTER:EV_OUTER + N_OC],
            sc[N_SC + 2 * (N + 1):])


@njit(cache=True, fastmath=False, inline="always")
def _outer_log(k, t, x, op, refs, obs, ocnt, obuf, lo, fp, sc):
    """The simulator's outer-step log (the recorder block: :func:`record_outer` of the row
    :func:`logged_reference`); True when |e_y| is beyond the divergence bound (``sc[SC_EY]``)."""
    e_y = record_outer(lo, k, x, logged_reference(op, refs, obs, ocnt, k, t, obuf))
    if off_road(e_y, fp[FP_BOUND]):
        sc[SC_EY] = e_y
        return True
    return False


@njit(cache=True, fastmath=False, inline="always")
def _back_records(fp, sf, ev, gbp, fbp, sp0, ls, mass_v, Kv, zlo, zhi, bits, prm, cur):
    """The phase after the MHE's records (Cascade._back_p's inner block record Cascade._ib and the
    TS-LQR's law TSLQR._law, packed by their own: :func:`unpack_inner_block`, :func:`unpack_law`) and
    its state (the blocks' slots, the open interval ``cur``)."""
    ibp = unpack_inner_block(fp[FP_IBK:FP_IBK + N_IBK])
    law = unpack_law(fp[FP_LAW:FP_LAW + N_LAW], Kv, zlo, zhi, bits, prm)
    bs = BackState(sf[SF_POSE:SF_POSE + N_PO], sf[SF_FB:SF_FB + N_FB], cur, sf[SF_SA:SF_SA + N_SA],
                   sf[SF_CMD:SF_CMD + N_CM], ls, sf[SF_IB:SF_IB + N_IB], mass_v, ev[EV_INNER:EV_INNER + N_IC])
    return BackParams(gbp.gates, fbp, sp0, ibp), law, bs


@njit(cache=True, fastmath=False)
def _actuated(x, Fc, dc, mu, act, fp, ip, sf, si, cst):
    """``ActuatedPlant.step`` over T_d: per sub-step the actuators' block
    (:func:`~tsmpc.vehicle.actuators.actuator_substep`, one definition), then the plant's RK4 steps
    with their outputs; the mean input over the step (:func:`applied_mean`) is what a platform
    measures. The state is committed only when every sub-step is finite (else the caller's Python
    step words the error from the step's start)."""
    s = actuator_start(ActuatorState(sf[SF_ACT], sf[SF_ACT + 1]), si[SI_ACTHAS] != 0, Fc, dc)
    xn = x.copy()
    for _ in range(act.substeps):
        s = actuator_substep(act, s, Fc, dc)
        xn, ok = rk4_block(xn, s.F, wheel_steering(s.delta, act.steering_offset), mu, ip[IP_ACT_NRK],
                           fp[FP_H], cst)
        if not ok:
            return xn, False
    sf[SF_ACT], sf[SF_ACT + 1] = s.F, s.delta
    si[SI_ACTHAS] = 1
    sf[SF_PLANTU], sf[SF_PLANTU + 1] = applied_mean(act, s)
    return xn, True


# ============================================================================ the run
#: _start_phase's answers besides the next phase: the run diverged, the cascade went blind
_PH_DIVERGED, _PH_BLINDED = -1, -2


@njit(cache=True, fastmath=False, inline="always")
def _start_phase(m, k, j, t, x, fp, ip, sf, si, sc, ev, noise, u_drop, gnss, fifo, refs, gate, cur, ivs, mp,
                 prm, prevX, lo, gbp, fbp, cpar):
    """A step's start (simulate: the sensor step, the outer-step log and its divergence test), then
    Cascade.step's time (Cascade._clock: _clock.cascade_clock) and Cascade._step's phase before the
    outer loop (Cascade._front: the stamp and the recovery's watch, the gate block, the MPC's turn,
    the fusion block before the MPC and the MHE; the simulator's samples carry no stamp) and, at an
    MPC step, its part before the solve (Cascade._outer_block: the stiffness block, the errors the
    MPC sees, its window). Returns the phase that follows (PH_PLAN: the MPC's solve first, PH_MHE),
    _PH_DIVERGED, or _PH_BLINDED (the blind stop: the Python loop's, the caller's fallback)."""
    Td, Tc, n_in, N = fp[FP_TD], fp[FP_TC], ip[IP_NIN], ip[IP_N]
    y = sc[SC_Y:SC_Y + 5]
    _sensor(m, n_in, Tc, Td, x, noise, u_drop, gnss, unpack_params(fp[FP_SENS:FP_SENS + N_SP]),
            sf[SF_SENS:SF_SENS + N_SS], fifo, y)
    if j == 0:
        op, obs, ocnt, obuf = _outer_views(fp, sf, ev, sc, N)
        if _outer_log(k, t, x, op, refs, obs, ocnt, obuf, lo, fp, sc):
            return _PH_DIVERGED
    ckp = unpack_clock(fp[FP_CK:FP_CK + N_CKP])
    ck, cc = sf[SF_CK:SF_CK + N_CK], ev[EV_TIME_REJ:EV_TIME_REJ + N_CC]
    tc = cascade_clock(ckp, ck, cc, t)
    fbs = sf[SF_FB:SF_FB + N_FB]
    fst = FrontState(sf[SF_GS:SF_GS + N_GS], ev[EV_GATES:EV_GATES + N_GC], sf[SF_POSE:SF_POSE + N_PO], fbs,
                     ivs, cur, sf[SF_CMD:SF_CMD + N_CM], ck, cc)
    fo = cascade_front(FrontParams(gbp, fbp, n_in, ckp), fst, tc, False, y[0], y[1], y[2], y[3], y[4],
                       -math.inf, sf[SF_TOFF], refs.v, refs.omega)
    if not math.isnan(ck[CK_BLIND]):
        return _PH_BLINDED
    si[SI_FRESH] = 1 if fo.fresh else 0
    si[SI_SPOK] = 1 if fo.speeds_ok else 0
    si[SI_POSEOK] = 1 if fo.pose_ok else 0
    if not fo.mpc_step:
        return PH_MHE
    op, obs, ocnt, obuf = _outer_views(fp, sf, ev, sc, N)
    wv, ww = sc[N_SC:N_SC + N + 1], sc[N_SC + N + 1:N_SC + 2 * (N + 1)]
    v_last = sc[SC_EST] if sf[SF_CMD + CM_HASLAST] != 0.0 else math.nan  # (the last estimate's)
    ost = OuterState(fbs, ivs, sf[SF_SA:SF_SA + N_SA], mp, prm, obs, ocnt, gate, sf[SF_POSE:SF_POSE + N_PO],
                     sf[SF_CMD:SF_CMD + N_CM], ck, sf[SF_UPREV:SF_UPREV + 2])
    opp = OuterParams(ip[IP_ANYCOURSE] != 0 and ip[IP_STIFF] != 0, cpar, op, ckp)
    _k, _restarted, _give, governed = cascade_outer(
        opp, refs, ost, tc, fo.pose_ok, y[0], y[1], y[3], fo.omega, v_last, si[SI_HASPREV] != 0, prevX[1, 1],
        sc[SC_EMEAS:SC_EMEAS + 3], wv, ww, obuf)
    si[SI_GWIN] = 1 if governed else 0
    return PH_PLAN


@njit(cache=True, fastmath=False, inline="always")
def _mpc_fast(k, N, sf, si, sc, mints, mprm, mPS, prevX, prevU, pX, pU, lo):
    """TSMPC.step: its compiled step (checks, schedule, Riccati fast path) on the errors and window
    of the phase before; True when it decided the plan (else a constraint is active or an input is
    not finite: the caller's)."""
    has_prev = si[SI_HASPREV] != 0
    wv, ww = sc[N_SC:N_SC + N + 1], sc[N_SC + N + 1:N_SC + 2 * (N + 1)]
    tick = _ticks()
    code, U, _du, Xp, _cost, n_clip, _up = guarded_step(
        mints, mprm, mPS, sc[SC_EMEAS:SC_EMEAS + 3], sf[SF_UPREV:SF_UPREV + 2], wv, ww,
        prevX if has_prev else prevX[:0], prevU if has_prev else prevU[:0])  # (no previous plan: empty)
    if code == 0:
        for i in range(N):
            pU[i, 0], pU[i, 1] = U[i, 0], U[i, 1]
        for i in range(N + 1):
            pX[i, 0], pX[i, 1], pX[i, 2] = Xp[i, 0], Xp[i, 1], Xp[i, 2]
        sc[SC_PU], sc[SC_PU + 1] = U[0, 0], U[0, 1]
        si[SI_PSTAT], si[SI_PIT], si[SI_PQPIT], si[SI_PCLIP] = MPC_OPTIMAL, 0, 0, n_clip
    lo[k, LO_TMPC] = float(_ticks() - tick)
    return code == 0


@njit(cache=True, fastmath=False, inline="always")
def _plan_phase(k, t, N, pX, pU, prevX, prevU, fp, sf, si, sc, ev, refs, frb, patches, events, lo, loi, lxp):
    """The plan of MPC step ``k`` (the fast path's or the caller's): TSMPC's previous plan, the log
    (the recorder block); the plan's bookkeeping (Cascade._after_plan: _mid.cascade_after_plan, its
    input kept, the outer block after it: its events, the speed governor's rate)."""
    for i in range(N):
        prevU[i, 0], prevU[i, 1] = pU[i, 0], pU[i, 1]
    for i in range(N + 1):
        prevX[i, 0], prevX[i, 1], prevX[i, 2] = pX[i, 0], pX[i, 1], pX[i, 2]
    si[SI_HASPREV] = 1
    record_plan(lo, loi, lxp, k, sc[SC_EMEAS:SC_EMEAS + 3], sc[SC_PU], sc[SC_PU + 1], pX, si[SI_PSTAT],
                si[SI_PIT], si[SI_PQPIT], si[SI_PCLIP])  # (the recorder block)
    op, obs, ocnt, obuf = _outer_views(fp, sf, ev, sc, N)
    govp = unpack_govern(fp[FP_GB:FP_GB + N_GBP])
    oracle = op.governor and govp.grip.oracle  # (the oracle row reads the road's μ)
    road_mu = friction_mu(t, sf[SF_STRAVEL], frb, patches, events) if oracle else math.nan
    dm = _delta_mass(sf, fp) if op.governor and govp.mass_estimate else 0.0
    ck = sf[SF_CK:SF_CK + N_CK]
    ast = AfterState(obs, ocnt, sf[SF_CMD:SF_CMD + N_CM], ck, sf[SF_UPREV:SF_UPREV + 2])
    v_last = sc[SC_EST] if sf[SF_CMD + CM_HASLAST] != 0.0 else math.nan
    took = si[SI_FRESH] != 0 and si[SI_SPOK] != 0  # (the speed accepted)
    cascade_after_plan(op, govp, unpack_clock(fp[FP_CK:FP_CK + N_CKP]), refs, ast, sc[SC_PU], sc[SC_PU + 1],
                       took, sc[SC_Y + 3], si[SI_PSTAT], si[SI_PCLIP], ck[CK_TLAST], si[SI_ESTSTAT], v_last,
                       sc[SC_ESTF], road_mu, dm, obuf)


@njit(cache=True, fastmath=False, inline="always")
def _mhe_phase(m, fp, ip, sf, si, sc, mp, mY, mW, mU, mXS, mA, mB, mX, li):
    """The MHE block (Cascade._estimate: _mid.cascade_estimate; its inputs, the window's update and
    solve, the estimate); True when the estimator's dense QP must decide (the batch: its lanes'
    solve)."""
    sc[SC_VREF], sc[SC_WREF] = sf[SF_UPREV], sf[SF_UPREV + 1]
    si[SI_TICK0] = _ticks()
    ep = EstimateParams(MHEBlockParams(fp[FP_MHE_MASS], ip[IP_DEFER] != 0), ip[IP_CSPEED] != 0)
    est = EstimateState(mp, sf[SF_MX:SF_MX + N_MS], si[SI_NY:SI_NY + N_MI], sc[SC_UK:SC_UK + 2],
                        sc[SC_EST:SC_EST + N_EO], sf[SF_FB:SF_FB + N_FB], sf[SF_CMD:SF_CMD + N_CM])
    mst = cascade_estimate(ep, MHEWindow(mY, mW, mU, mXS, mA, mB, mX), est,
                           si[SI_FRESH] != 0 and si[SI_SPOK] != 0, sc[SC_Y + 3], ip[IP_MFORCE] != 0,
                           sf[SF_PLANTU], ip[IP_MSTEER] != 0, sf[SF_PLANTU + 1])
    sc[SC_UMHE], sc[SC_UMHE + 1] = mst.u0, mst.u1  # what the cascade gave (the course fusion's δ, F)
    si[SI_MHEN], si[SI_MHEOK] = mst.n, 1 if mst.ok else 0
    si[SI_MHEFULL] = 1 if mst.n == ip[IP_NW] else 0
    if mst.status == MHE_DENSE:
        return True
    si[SI_ESTSTAT] = mst.status
    li[m, LI_TMHE] = float(_ticks() - si[SI_TICK0])
    return False


@njit(cache=True, fastmath=False, inline="always")
def _plant_phase(m, t, x, fp, ip, sf, si, sc, frb, patches, events, cst, li, lstat, lsat):
    """The inner log (the recorder block; the true F_fr: VehiclePlant's), the plant over T_d
    (simulate): True when ``x`` holds the next state (else the caller's: the batch integrates its
    lanes at once, a non-finite step is worded by the plant's Python step)."""
    mu = friction_mu(t, sf[SF_STRAVEL], frb, patches, events)
    sc[SC_MU] = mu
    record_inner(li, lstat, lsat, m, x, sc[SC_EST:SC_EST + 3], sc[SC_Y + 3], sc[SC_Y + 4], sc[SC_ESTF],
                 sc[SC_ESTFR], friction_force(fp[FP_MU_NOM], fp[FP_MG], mu), mu, sc[SC_OF], sc[SC_OD],
                 si[SI_ESTSTAT], sf[SF_CMD + CM_SAT] != 0)
    if ip[IP_ACT] == 0:
        if ip[IP_DEFER] != 0:  # the batch integrates its lanes at once (kernels.batch)
            return False
        xn, ok = rk4_block(x, sc[SC_OF], sc[SC_OD], mu, ip[IP_NSUB], fp[FP_H], cst)
        if not ok:
            return False
        sf[SF_PLANTU], sf[SF_PLANTU + 1] = sc[SC_OF], sc[SC_OD]
    else:
        act = ActuatorParams(fp[FP_A_GF], fp[FP_A_GD], fp[FP_A_RMAX], fp[FP_A_DOFF], ip[IP_ACT_N])
        xn, ok = _actuated(x, sc[SC_OF], sc[SC_OD], mu, act, fp, ip, sf, si, cst)
        if not ok:
            return False
    for i in range(6):
        x[i] = xn[i]
    return True


@njit(cache=True, fastmath=False)
def run(m_end, x, fp, ip, sf, si, sc, ev,
        noise, u_drop, gnss, fifo, frb, patches, events,
        ref_x, ref_y, ref_th, ref_v, ref_w, th_tan, mv, mw,
        gate, cur, ivs, mass_v,
        mY, mW, mU, mXS, mA, mB, mX, mp,
        ls, Kv, zlo, zhi, bits, prm,
        mints, mprm, mPS, prevX, prevU, pX, pU,
        cst, lo, loi, lxp, li, lstat, lsat):
    """Run steps ``si[SI_M]`` … ``m_end − 1`` (see the module docstring). Returns DONE when
    ``m_end`` is reached, else the code of the block the caller must run (NEED_*), DIVERGED or
    BLINDED. ``x`` (6,) is the plant state at the start of step ``si[SI_M]``."""
    Td, n_in, N = fp[FP_TD], ip[IP_NIN], ip[IP_N]
    y = sc[SC_Y:SC_Y + 5]
    refs = RefArrays(ref_x, ref_y, ref_th, ref_v, ref_w, th_tan, mv, mw)  # (Cascade._refs)
    gbp = unpack_gate_block(fp[FP_GBK:FP_GBK + N_GBK])  # the gate block's (Cascade._gate_p)
    cpar = unpack_course(fp[FP_CP:FP_CP + N_CP])  # the course fusion's (Cascade._fb_p.cp)
    fbp, sp0 = unpack_fusion(fp[FP_FB:FP_FB + N_FBP], cpar)  # the fusion block's (Cascade._fb_p, steer_p)
    # (each phase makes its records and state views: the batch enters run() twice a step, at its phases)
    while si[SI_M] < m_end:
        m = si[SI_M]
        k = m // n_in
        t = m * Td
        phase = si[SI_PHASE]
        if phase == PH_START:  # the sensors, the log, the time, the phase before the outer loop
            phase = _start_phase(m, k, m - k * n_in, t, x, fp, ip, sf, si, sc, ev, noise, u_drop, gnss, fifo,
                                 refs, gate, cur, ivs, mp, prm, prevX, lo, gbp, fbp, cpar)
            if phase < 0:
                return DIVERGED if phase == _PH_DIVERGED else BLINDED
            if phase == PH_PLAN and not _mpc_fast(k, N, sf, si, sc, mints, mprm, mPS, prevX, prevU, pX, pU,
                                                  lo):
                si[SI_PHASE] = PH_PLAN
                return NEED_MPC
        if phase == PH_PLAN:  # the plan of this MPC step (the fast path's or the caller's), its bookkeeping
            _plan_phase(k, t, N, pX, pU, prevX, prevU, fp, sf, si, sc, ev, refs, frb, patches, events, lo,
                        loi, lxp)
            phase = PH_MHE
        if phase == PH_MHE:  # the MHE block; its dense QP is the caller's
            if _mhe_phase(m, fp, ip, sf, si, sc, mp, mY, mW, mU, mXS, mA, mB, mX, li):
                si[SI_PHASE] = PH_POST_MHE
                return NEED_MHE
            phase = PH_POST_MHE
        if phase == PH_POST_MHE:
            # the phase after the MHE (Cascade._back): dead reckoning, the fusion block after the
            # MHE, the inner block, the servo and the command record; the numpy law (a singular N̄)
            # is the caller's, with the block's compensation and residual
            tick = _ticks()
            bp, law, bs = _back_records(fp, sf, ev, gbp, fbp, sp0, ls, mass_v, Kv, zlo, zhi, bits, prm,
                                        cur)
            out = cascade_back(bp, law, bs, si[SI_FRESH] != 0 and si[SI_SPOK] != 0, si[SI_POSEOK] != 0, y[2],
                               y[3], sc[SC_EST], sc[SC_EST + 1], sc[SC_EST + 2], sc[SC_ESTF], sc[SC_ESTFR],
                               si[SI_ESTSTAT], sc[SC_UMHE + 1], sc[SC_UMHE], sc[SC_VREF], sc[SC_WREF])
            li[m, LI_TLQR] = float(_ticks() - tick)
            if out.status == LQR_NUMPY:
                sc[SC_COMP], sc[SC_LOWF] = out.F_comp, out.F_low_speed
                si[SI_PHASE] = PH_POST_LQR
                return NEED_LQR
            sc[SC_OF], sc[SC_OD] = out.F_xR, out.delta
            phase = PH_PLANT
        if phase == PH_POST_LQR:  # the numpy law decided (the caller's: F, δ, saturated, residual in sc)
            bp, law, bs = _back_records(fp, sf, ev, gbp, fbp, sp0, ls, mass_v, Kv, zlo, zhi, bits, prm,
                                        cur)
            sc[SC_OD] = cascade_command(bp, bs, sc[SC_OF], sc[SC_OD], sc[SC_SAT] != 0.0, sc[SC_LOWF],
                                        sc[SC_EST + 1])
            phase = PH_PLANT
        if phase == PH_PLANT:  # the inner log, the plant
            if not _plant_phase(m, t, x, fp, ip, sf, si, sc, frb, patches, events, cst, li, lstat, lsat):
                si[SI_PHASE] = PH_POST_PLANT
                return NEED_PLANT
            phase = PH_POST_PLANT
        # PH_POST_PLANT: the travelled distance, next step
        sf[SF_STRAVEL] = travelled(sf[SF_STRAVEL], x[3], Td)
        si[SI_M] = m + 1
        si[SI_PHASE] = PH_START
    return DONE


@njit(cache=True, fastmath=False)
def run_borrowed(m_end, x, fp, ip, sf, si, sc, ev, noise, u_drop, gnss, fifo, frb, patches, events,
                 ref_x, ref_y, ref_th, ref_v, ref_w, th_tan, mv, mw, gate, cur, ivs, mass_v,
                 mY, mW, mU, mXS, mA, mB, mX, mp, ls, Kv, zlo, zhi, bits, prm,
                 mints, mprm, mPS, prevX, prevU, pX, pU, cst, lo, loi, lxp, li, lstat, lsat):
    """:func:`run` on the caller's arrays as borrowed views (:func:`_borrowed`): the engine's entry
    from Python (the batch's lanes are borrowed views already)."""
    b = _borrowed
    return run(m_end, b(x), b(fp), b(ip), b(sf), b(si), b(sc), b(ev), b(noise), b(u_drop), b(gnss), b(fifo),
               b(frb), b(patches), b(events), b(ref_x), b(ref_y), b(ref_th), b(ref_v), b(ref_w), b(th_tan),
               b(mv), b(mw), b(gate), b(cur), b(ivs), b(mass_v), b(mY), b(mW), b(mU), b(mXS), b(mA), b(mB),
               b(mX), b(mp), b(ls), b(Kv), b(zlo), b(zhi), b(bits), b(prm), b(mints), b(mprm), b(mPS),
               b(prevX), b(prevU), b(pX), b(pU), b(cst), b(lo), b(loi), b(lxp), b(li), b(lstat), b(lsat))


@njit(cache=True, fastmath=False)
def ticks():
    """The cycle counter, for the caller's calibration of the block timings."""
    return _ticks()


def warm() -> None:
    """Compile (or load from the cache) the helpers the caller probes outside ``run`` (``run``
    itself compiles for the caller's arrays on its first, empty call)."""
    hypot_py(3.0, 4.0)
    ticks()
