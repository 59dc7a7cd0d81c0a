"""The simulator's recorder as one block (issue 34): what a run logs at each step, written once
for the Python loop (:func:`tsmpc.sim.simulator.simulate`), the run engine
(``tsmpc.kernels.engine.run``) and the batch (which runs the engine's step per lane).

The log lives in preallocated arrays (:class:`Records`), one row per outer step (``lo``: the
columns ``LO_*``; ``loi``: the plan's status and counts ``LOI_*``; ``lxp``: its prediction) and
one per inner step (``li``: the columns ``LI_*``; ``lstat``: the estimator's status code;
``lsat``: saturated). The per-step writes are ``@jitable`` (:mod:`tsmpc.kernels.jit`):

* :func:`logged_reference` — the reference row an outer step is logged and measured against: the
  governed one (the reference at the governed time, :func:`~tsmpc.control.outer_block.governed_sample`)
  once the speed governor has acted, else the reference's sample k;
* :func:`record_outer` — the outer row: the true state, that reference row and the true errors
  against it (:func:`~tsmpc.control.outer_block.pose_errors`); :func:`off_road` the divergence
  test on its e_y;
* :func:`record_plan` — the plan of an MPC step: the errors it saw, its command, its prediction,
  its status (``MPC_*`` of :mod:`tsmpc.control.outer_block`) and counts;
* :func:`record_inner` — the inner row: the true state, the estimate, the measured v and ω, the
  friction estimates and the true friction force, μ(road), the command, the estimator's status
  (``EST_*`` of :mod:`tsmpc.control.inner_block`) and saturation;
* :func:`travelled` — the distance the car has covered (the friction profiles' s).

The block times are each loop's own (the Python loop's seconds, the engine's cycle counts, scaled
by :func:`run_log`); :func:`run_log` turns the records into the :class:`~tsmpc.sim.log.RunLog`.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.outer_block import (
    OB_RATE,
    OB_TOFF,
    OC_GACT,
    OuterBlockParams,
    RefArrays,
    governed_sample,
    pose_errors,
)
from tsmpc.kernels.jit import jitable
from tsmpc.sim.log import RunLog

__all__ = ["LI_CMD", "LI_EST", "LI_FHAT", "LI_FRAW", "LI_FTRUE", "LI_MEAS", "LI_MU", "LI_TLQR", "LI_TMHE",
           "LI_X", "LOI_CLIP", "LOI_IT", "LOI_QPIT", "LOI_STATUS", "LO_EMEAS", "LO_ERR", "LO_REF", "LO_TMPC",
           "LO_UC", "LO_X", "N_LI", "N_LO", "N_LOI", "Records", "logged_reference", "new_records", "off_road",
           "record_inner", "record_outer", "record_plan", "run_log", "travelled"]

#: Inner log columns: state (6), estimate [v, α, ω], measured [v, ω], F̂_fr, F̂_fr raw, true F_fr,
#: μ(road), command [F_xR, δ], the MHE's and the TS-LQR's time.
(LI_X, _LX1, _LX2, _LX3, _LX4, _LX5, LI_EST, _LE1, _LE2, LI_MEAS, _LM1, LI_FHAT, LI_FRAW,
 LI_FTRUE, LI_MU, LI_CMD, _LC1, LI_TMHE, LI_TLQR) = range(19)
N_LI = 19
#: Outer log columns: state (6), true errors (3), measured errors (3), the plan's command (2), the
#: MPC's time, the reference row logged (5).
(LO_X, _OX1, _OX2, _OX3, _OX4, _OX5, LO_ERR, _OE1, _OE2, LO_EMEAS, _OM1, _OM2, LO_UC, _OU1,
 LO_TMPC, LO_REF, _OR1, _OR2, _OR3, _OR4) = range(20)
N_LO = 20
#: Integer outer log columns: the plan's status code, iterations, QP iterations, clipped inputs.
LOI_STATUS, LOI_IT, LOI_QPIT, LOI_CLIP = range(4)
N_LOI = 4

#: A reference row [x_d, y_d, θ_d, v_d, ω_d].
Row = tuple[float, float, float, float, float]


class Records(NamedTuple):
    """A run's log arrays: K outer rows, M = K·T_c/T_d inner rows."""

    lo: NDArray[np.float64]  #: (K, N_LO)
    loi: NDArray[np.int64]  #: (K, N_LOI)
    lxp: NDArray[np.float64]  #: (K, N + 1, 3) the plans' predictions
    li: NDArray[np.float64]  #: (M, N_LI)
    lstat: NDArray[np.int8]  #: (M,) the estimator's status code
    lsat: NDArray[np.bool_]  #: (M,)


def new_records(K: int, n_in: int, N: int) -> Records:
    """Zeroed records of a run of K outer steps, ``n_in`` inner steps each, horizon N."""
    M = K * n_in
    return Records(np.zeros((K, N_LO)), np.zeros((K, N_LOI), dtype=np.int64), np.zeros((K, N + 1, 3)),
                   np.zeros((M, N_LI)), np.zeros(M, dtype=np.int8), np.zeros(M, dtype=bool))


@jitable
def logged_reference(op: OuterBlockParams, refs: RefArrays, ob: NDArray[np.float64], oc: NDArray[np.int64],
                     k: int, t: float, buf: NDArray[np.float64]) -> Row:
    """The reference row outer step ``k`` at time ``t`` is logged against: the governed one once
    the speed governor has acted (``Cascade.governed``; the reference at the governed time,
    ``Cascade.reference_row``), else the reference's sample k. ``ob``, ``oc``: the outer block's
    state and counters; ``buf`` its scratch."""
    if op.governor and (oc[OC_GACT] > 0 or ob[OB_RATE] < 1.0):
        return governed_sample(op, refs, t - ob[OB_TOFF], ob[OB_RATE], buf)
    return refs.x[k], refs.y[k], refs.theta[k], refs.v[k], refs.omega[k]


@jitable
def record_outer(lo: NDArray[np.float64], k: int, x: NDArray[np.float64], r: Row) -> float:
    """Outer row ``k``: the true state ``x`` (6,), the reference row ``r`` and the true errors
    against it; returns the true lateral error e_y."""
    lo[k, LO_X:LO_X + 6] = x
    lo[k, LO_REF], lo[k, LO_REF + 1], lo[k, LO_REF + 2], lo[k, LO_REF + 3], lo[k, LO_REF + 4] = r
    pose_errors(x[0], x[1], x[2], r[0], r[1], r[2], lo[k, LO_ERR:LO_ERR + 3])
    return lo[k, LO_ERR + 1]


@jitable
def off_road(e_y: float, bound: float) -> bool:
    """Has the run diverged: |e_y| beyond ``bound`` [m] (∞: no bound)?"""
    return abs(e_y) > bound


@jitable
def record_plan(lo: NDArray[np.float64], loi: NDArray[np.int64], lxp: NDArray[np.float64], k: int,
                e_meas: NDArray[np.float64], u0: float, u1: float, x_pred: NDArray[np.float64], status: int,
                iterations: int, qp_iterations: int, clipped: int) -> None:
    """The plan of MPC step ``k``: the errors it saw ``e_meas`` (3,), its command (u0, u1), its
    prediction ``x_pred`` (its first N + 1 rows), its status code and counts."""
    lo[k, LO_EMEAS:LO_EMEAS + 3] = e_meas
    lo[k, LO_UC], lo[k, LO_UC + 1] = u0, u1
    n = min(x_pred.shape[0], lxp.shape[1])
    lxp[k, :n] = x_pred[:n, :3]
    loi[k, LOI_STATUS], loi[k, LOI_IT] = status, iterations
    loi[k, LOI_QPIT], loi[k, LOI_CLIP] = qp_iterations, clipped


@jitable
def record_inner(li: NDArray[np.float64], lstat: NDArray[np.int8], lsat: NDArray[np.bool_], m: int,
                 x: NDArray[np.float64], est: NDArray[np.float64], v_meas: float, w_meas: float,
                 F_hat: float, F_raw: float, F_true: float, mu: float, F_xR: float, delta: float,
                 status: int, saturated: bool) -> None:
    """Inner row ``m``: the true state ``x`` (6,), the estimate ``est`` [v, α, ω], the measured v
    and ω, the friction estimates (filtered, raw), the true friction force (NaN: unknown), μ(road),
    the command [F_xR, δ], the estimator's status code and whether the command saturated."""
    for i in range(6):  # (element by element: every step of the engine; a slice copy costs it ≈ 1 %)
        li[m, LI_X + i] = x[i]
    for i in range(3):
        li[m, LI_EST + i] = est[i]
    li[m, LI_MEAS], li[m, LI_MEAS + 1] = v_meas, w_meas
    li[m, LI_FHAT], li[m, LI_FRAW], li[m, LI_FTRUE], li[m, LI_MU] = F_hat, F_raw, F_true, mu
    li[m, LI_CMD], li[m, LI_CMD + 1] = F_xR, delta
    lstat[m] = status
    lsat[m] = saturated


@jitable
def travelled(s: float, v: float, Td: float) -> float:
    """The distance [m] after a step of ``Td`` [s] at speed ``v`` [m/s] from ``s`` (reversing does
    not count)."""
    return s + max(v, 0.0) * Td


def _texts() -> tuple[NDArray[np.str_], NDArray[np.str_]]:
    """The statuses' words by code (the MPC's, the estimator's): the cascade's code tables."""
    from tsmpc.control.cascade import _MPC_STATUS_CODE, STATUS_CODE

    mpc, est = [""] * (max(_MPC_STATUS_CODE.values()) + 1), [""] * (max(STATUS_CODE.values()) + 1)
    for status, code in _MPC_STATUS_CODE.items():
        mpc[code] = str(status)
    for st, code in STATUS_CODE.items():
        est[code] = str(st)
    return np.array(mpc, dtype="<U16"), np.array(est, dtype="<U16")


def _col(a: NDArray[Any]) -> NDArray[Any]:
    return np.ascontiguousarray(a)


Times = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def run_log(rec: Records, *, method: str, scenario: str, Tc: float, Td: float, t0: float, done: int,
            rows: int, times: Times | None = None, **facts: Any) -> RunLog:
    """The :class:`RunLog` of the records' first ``done`` outer and ``rows`` inner rows (the
    reference started at ``t0``). ``times``: the MPC's, MHE's and TS-LQR's times [s] of those rows
    (None: the records' columns, in seconds); ``facts``: the log's other fields."""
    o, i = slice(0, done), slice(0, rows)
    lo, li, loi = rec.lo[o], rec.li[i], rec.loi[o]
    mpc_t, mhe_t, lqr_t = times if times is not None else (lo[:, LO_TMPC], li[:, LI_TMHE], li[:, LI_TLQR])
    mpc_text, est_text = _texts()
    return RunLog(
        method=method, scenario=scenario, Tc=Tc, Td=Td,
        t_outer=np.arange(done, dtype=np.float64) * Tc + t0, ref=_col(lo[:, LO_REF:LO_REF + 5]),
        state_outer=_col(lo[:, LO_X:LO_X + 6]), errors=_col(lo[:, LO_ERR:LO_ERR + 3]),
        errors_measured=_col(lo[:, LO_EMEAS:LO_EMEAS + 3]), u_c=_col(lo[:, LO_UC:LO_UC + 2]),
        x_pred=rec.lxp[o].copy(), mpc_time_s=_col(mpc_t), mpc_status=mpc_text[loi[:, LOI_STATUS]],
        mpc_iterations=loi[:, LOI_IT].copy(), mpc_qp_iterations=loi[:, LOI_QPIT].copy(),
        mpc_clipped=loi[:, LOI_CLIP].copy(),
        t_inner=np.arange(rows, dtype=np.float64) * Td + t0, state=_col(li[:, LI_X:LI_X + 6]),
        estimate=_col(li[:, LI_EST:LI_EST + 3]), measurement=_col(li[:, LI_MEAS:LI_MEAS + 2]),
        F_fr_hat=_col(li[:, LI_FHAT]), F_fr_raw=_col(li[:, LI_FRAW]), F_fr_true=_col(li[:, LI_FTRUE]),
        mu_road=_col(li[:, LI_MU]), command=_col(li[:, LI_CMD:LI_CMD + 2]), saturated=rec.lsat[i].copy(),
        mhe_time_s=_col(mhe_t), lqr_time_s=_col(lqr_t), mhe_status=est_text[rec.lstat[i]], **facts)
