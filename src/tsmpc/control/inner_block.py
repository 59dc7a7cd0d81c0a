"""The inner part of a step after the MHE, as one block (issue 34): the friction-step detection and
the force it compensates, the mass error's inertia terms, the estimate handed to the TS-LQR, the
TS-LQR's step and the step's events.

One definition, three callers: the cascade's phase after the MHE
(:func:`tsmpc.control._back.cascade_back`) runs it, and :class:`~tsmpc.control.cascade.Cascade` calls
that phase through one compiled call (``tsmpc.kernels.blocks.back_call``; as Python with
``TSMPC_NO_JIT``), the run engine (``tsmpc.kernels.engine.run``) and the batch compile it into their
step. Its parts are
the blocks of their own modules: :func:`~tsmpc.estimation.friction_step.friction_step_update`,
:func:`~tsmpc.estimation.fusion.mass_update` / :func:`~tsmpc.estimation.fusion.inertia_force` and
:func:`~tsmpc.control.ts_lqr.inner_step` around the compiled law.

Records: the parameters are :class:`InnerBlockParams` (the TS-LQR's :class:`LQRLaw` beside it);
the state is a float vector of named slots (``IB_*``: the friction-step detector's
:class:`~tsmpc.estimation.friction_step.FrictionStepState` and the mass fit's
:class:`~tsmpc.estimation.fusion.MassState`, loaded and stored by :func:`fstep_load` /
:func:`mass_load`), the window's speeds a ring beside it, the events an integer vector of named
counters (``IC_*``). The estimator's status arrives as a code (``EST_*``, the MHE kernel's).

The configurations the block does not express — the oracle, the published run's true-state
feedback and its law, the blind stop — take :func:`compensated_force` (the same friction and mass
terms) and :func:`count_step` (the same events) around their own law in the cascade.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.ts_lqr import LQR_NUMPY, InnerParams, InnerStep, LQRLaw, inner_step
from tsmpc.estimation.friction_step import FrictionStepParams, FrictionStepState, friction_step_update
from tsmpc.estimation.fusion import MassParams, MassState, delta_mass, inertia_force, mass_update
from tsmpc.kernels.jit import jitable, jitable_inline

__all__ = ["EST_FAILED", "EST_OK", "EST_REJECTED", "EST_WARMUP", "IC_FAILED", "IC_FSTEPS", "IC_REJECTED",
           "IC_SATURATED", "N_IB", "N_IBK", "N_IC", "InnerBlockParams", "block_delta_mass",
           "compensated_force", "count_step", "fstep_load", "inner_block", "mass_load", "pack_inner_block",
           "start_state", "unpack_inner_block"]

#: The estimator's status codes (tsmpc.kernels.mhe's MHE_OK … MHE_WARMUP).
EST_OK, EST_REJECTED, EST_FAILED, EST_WARMUP = 1, 2, 3, 4

#: The state's slots: the friction-step detector's, then the mass fit's.
(IB_FS_VAR, IB_FS_N, IB_FS_GP, IB_FS_GM, IB_FS_SINCE,
 IB_M_N, IB_M_RUN, IB_M_ACCEL, IB_M_LF, IB_M_LA, IB_M_OPEN, IB_M_SXY, IB_M_SXX) = range(13)
N_IB = 13

#: The event counters: estimator samples rejected, failed; inner-loop saturations; friction steps.
IC_REJECTED, IC_FAILED, IC_SATURATED, IC_FSTEPS = range(4)
N_IC = 4


class InnerBlockParams(NamedTuple):
    """The block's switches and its parts' parameters.

    Attributes:
        friction_step: the friction-step detector runs (``lqr.friction_step``).
        fstep: its parameters.
        mass_estimate: the mass error's inertia terms are added (``fusion.mass_estimate``).
        mass: the mass fit's parameters.
        inner: the TS-LQR step's parameters around its law.
    """

    friction_step: bool
    fstep: FrictionStepParams
    mass_estimate: bool
    mass: MassParams
    inner: InnerParams


#: Length of :func:`pack_inner_block`'s vector: friction_step, FrictionStepParams' 2 fields,
#: mass_estimate, MassParams' 5, InnerParams' 5.
N_IBK = 14


def pack_inner_block(p: InnerBlockParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_inner_block` reads (compiled callers rebuild it:
    the cascade's compiled calls, the run engine's parameter slots)."""
    fs, m, q = p.fstep, p.mass, p.inner
    return np.array([p.friction_step, fs.window, fs.threshold, p.mass_estimate, m.mass, m.Td, m.window,
                     m.tau, m.speed_feedback, q.compensation, q.raw_estimate, q.low_speed, q.v_min,
                     q.resistance], dtype=np.float64)


@jitable
def unpack_inner_block(a: NDArray[np.float64]) -> InnerBlockParams:
    """The record of :func:`pack_inner_block`'s vector."""
    return InnerBlockParams(
        a[0] != 0.0, FrictionStepParams(int(a[1]), a[2]), a[3] != 0.0,
        MassParams(a[4], a[5], int(a[6]), a[7], a[8] != 0.0),
        InnerParams(a[9] != 0.0, a[10] != 0.0, a[11] != 0.0, a[12], a[13]))


def start_state(window: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """(state, ring of the window's speeds, counters) at the start: all zero."""
    return np.zeros(N_IB), np.zeros(window + 1), np.zeros(N_IC, dtype=np.int64)


@jitable
def fstep_load(st: NDArray[np.float64]) -> FrictionStepState:
    """The friction-step detector's record of the state's slots."""
    return FrictionStepState(st[IB_FS_VAR], int(st[IB_FS_N]), st[IB_FS_GP], st[IB_FS_GM],
                             int(st[IB_FS_SINCE]))


@jitable
def mass_load(st: NDArray[np.float64]) -> MassState:
    """The mass fit's record of the state's slots."""
    return MassState(int(st[IB_M_N]), int(st[IB_M_RUN]), st[IB_M_ACCEL], st[IB_M_LF], st[IB_M_LA],
                     st[IB_M_OPEN] != 0.0, st[IB_M_SXY], st[IB_M_SXX])


@jitable
def block_delta_mass(p: InnerBlockParams, st: NDArray[np.float64]) -> float:
    """ΔM̂ of the mass fit [kg] (:func:`~tsmpc.estimation.fusion.delta_mass`; the speed governor's)."""
    return delta_mass(p.mass, mass_load(st))


@jitable_inline
def compensated_force(p: InnerBlockParams, st: NDArray[np.float64], ring: NDArray[np.float64],
                      cnt: NDArray[np.int64], v_hat: float, F_window: float, F_raw: float, ok: bool,
                      v_ref: float, with_mass: bool) -> tuple[float, float]:
    """The friction forces handed to the inner loop (window fit, one-step UIO): the window fit
    stepped by the friction-step detector (a declared step counted), plus — ``with_mass`` (the
    estimate is the MHE's) — the mass error's inertia terms. ``ok``: the estimator's sample was
    accepted."""
    F_c = F_window
    if p.friction_step:
        s = fstep_load(st)
        F_c, s, declared = friction_step_update(p.fstep, s, F_window, F_raw, ok)
        st[IB_FS_VAR], st[IB_FS_N], st[IB_FS_GP], st[IB_FS_GM], st[IB_FS_SINCE] = \
            s.var, s.n_var, s.g_plus, s.g_minus, s.since
        if declared:
            cnt[IC_FSTEPS] += 1
    F_r = F_raw
    if with_mass and p.mass_estimate:  # the mass error's inertia is not friction (fusion.py)
        m = mass_update(p.mass, mass_load(st), ring, v_hat, F_window)
        st[IB_M_N], st[IB_M_RUN], st[IB_M_ACCEL], st[IB_M_LF], st[IB_M_LA] = \
            m.n_samples, m.run, m.accel, m.lf, m.la
        st[IB_M_OPEN], st[IB_M_SXY], st[IB_M_SXX] = 1.0 if m.open else 0.0, m.sxy, m.sxx
        dF = inertia_force(p.mass, m, v_hat, v_ref)
        if dF != 0.0:
            F_c, F_r = F_c + dF, F_r + dF
    return F_c, F_r


@jitable
def count_step(cnt: NDArray[np.int64], status: int, saturated: bool) -> None:
    """The step's events: the estimator's rejected and failed samples, the inner loop's saturation."""
    if status == EST_REJECTED:
        cnt[IC_REJECTED] += 1
    elif status == EST_FAILED:
        cnt[IC_FAILED] += 1
    if saturated:
        cnt[IC_SATURATED] += 1


@jitable_inline
def inner_block(p: InnerBlockParams, law: LQRLaw | None, s: NDArray[np.float64], st: NDArray[np.float64],
                ring: NDArray[np.float64], cnt: NDArray[np.int64], v: float, alpha: float, omega: float,
                F_window: float, F_raw: float, status: int, v_ref: float, w_ref: float) -> InnerStep:
    """One T_d after the MHE from its estimate (v̂, α̂, ω̂, F̂ window, F̂ one-step, status code) and
    the outer loop's references: the compensated friction (:func:`compensated_force`), the TS-LQR's
    step (:func:`~tsmpc.control.ts_lqr.inner_step` on its state ``s``) and the events
    (:func:`count_step`). With :data:`~tsmpc.control.ts_lqr.LQR_NUMPY` the numpy law must decide
    (its compensation and low-speed terms returned) and its caller counts the step."""
    F_c, F_r = compensated_force(p, st, ring, cnt, v, F_window, F_raw, status == EST_OK, v_ref, True)
    out = inner_step(p.inner, law, s, v, alpha, omega, F_c, F_r, v_ref, w_ref)
    if out.status != LQR_NUMPY:
        count_step(cnt, status, out.saturated)
    return out
