"""The simulator's recorder as one block (sim/record_block.py, issue 34): each per-step write by
hand, as Python and compiled (the engine's way). tests/test_engine.py compares whole runs of the
engine with the Python loop, both of which write their logs through these functions."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from tsmpc.config import Config, Method, replace
from tsmpc.control.cascade import Cascade
from tsmpc.control.outer_block import OB_RATE, OB_TOFF
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.sim import record_block as rb
from tsmpc.sim.record_block import (
    LI_CMD,
    LI_EST,
    LI_FHAT,
    LI_FRAW,
    LI_FTRUE,
    LI_MEAS,
    LI_MU,
    LI_TLQR,
    LI_TMHE,
    LI_X,
    LO_EMEAS,
    LO_ERR,
    LO_REF,
    LO_TMPC,
    LO_UC,
    LO_X,
    LOI_CLIP,
    LOI_IT,
    LOI_QPIT,
    LOI_STATUS,
    N_LI,
    N_LO,
    new_records,
    run_log,
)

X = np.array([3.0, 4.0, 0.5, 12.0, 0.02, 0.1])


def test_an_outer_row_holds_the_state_the_reference_and_the_errors_against_it(way) -> None:
    record_outer = way(rb.record_outer)
    lo = np.full((3, N_LO), -7.0)
    r = (5.0, 2.0, 0.75, 13.0, 0.2)
    e_y = record_outer(lo, 1, X, r)
    c, s = math.cos(0.5), math.sin(0.5)  # the errors in the car's frame: d = (2, -2)
    e = (c * 2.0 + s * -2.0, -s * 2.0 + c * -2.0, 0.25)
    np.testing.assert_array_equal(lo[1, LO_X:LO_X + 6], X)
    np.testing.assert_array_equal(lo[1, LO_REF:LO_REF + 5], r)
    assert tuple(lo[1, LO_ERR:LO_ERR + 3]) == pytest.approx(e, abs=1e-15)
    assert e_y == lo[1, LO_ERR + 1] and e_y < 0.0
    assert lo[1, LO_EMEAS] == lo[1, LO_TMPC] == -7.0  # the plan's columns are the plan's
    assert np.all(lo[[0, 2]] == -7.0)  # only its row


def test_off_road_is_beyond_the_bound_either_side(way) -> None:
    off_road = way(rb.off_road)
    assert off_road(-2.5, 2.0) and off_road(2.5, 2.0)
    assert not off_road(2.0, 2.0) and not off_road(-1.9, 2.0)
    assert not off_road(1e6, math.inf) and not off_road(math.nan, 2.0)


def test_the_travelled_distance_counts_forward_speed_only(way) -> None:
    travelled = way(rb.travelled)
    assert travelled(100.0, 12.0, 0.01) == 100.0 + 12.0 * 0.01
    assert travelled(100.0, -3.0, 0.01) == 100.0


def test_a_plan_row_holds_what_the_plan_said(way) -> None:
    record_plan = way(rb.record_plan)
    rec = new_records(4, 10, 3)  # N = 3: 4 predicted poses
    xp = np.arange(15.0).reshape(5, 3)  # one pose more than the log keeps
    record_plan(rec.lo, rec.loi, rec.lxp, 2, np.array([0.1, -0.2, 0.03]), 11.5, 0.04, xp, 2, 7, 31, 1)
    np.testing.assert_array_equal(rec.lo[2, LO_EMEAS:LO_EMEAS + 3], [0.1, -0.2, 0.03])
    np.testing.assert_array_equal(rec.lo[2, LO_UC:LO_UC + 2], [11.5, 0.04])
    np.testing.assert_array_equal(rec.lxp[2], xp[:4])
    assert list(rec.loi[2, [LOI_STATUS, LOI_IT, LOI_QPIT, LOI_CLIP]]) == [2, 7, 31, 1]
    record_plan(rec.lo, rec.loi, rec.lxp, 3, np.zeros(3), 0.0, 0.0, xp[:2], 1, 0, 0, 0)  # a shorter one
    np.testing.assert_array_equal(rec.lxp[3], np.vstack([xp[:2], np.zeros((2, 3))]))
    assert not rec.lo[[0, 1]].any() and not rec.lxp[[0, 1]].any() and not rec.loi[[0, 1]].any()


def test_an_inner_row_holds_each_value_in_its_column(way) -> None:
    record_inner = way(rb.record_inner)
    rec = new_records(2, 10, 3)
    record_inner(rec.li, rec.lstat, rec.lsat, 13, X, np.array([11.9, 0.015, 0.11]), 12.05, 0.099, 410.0,
                 430.0, 405.0, 0.68, 1500.0, -0.03, 4, True)
    row = rec.li[13]
    np.testing.assert_array_equal(row[LI_X:LI_X + 6], X)
    np.testing.assert_array_equal(row[LI_EST:LI_EST + 3], [11.9, 0.015, 0.11])
    assert (row[LI_MEAS], row[LI_MEAS + 1]) == (12.05, 0.099)
    assert (row[LI_FHAT], row[LI_FRAW], row[LI_FTRUE], row[LI_MU]) == (410.0, 430.0, 405.0, 0.68)
    assert (row[LI_CMD], row[LI_CMD + 1]) == (1500.0, -0.03)
    assert row[LI_TMHE] == row[LI_TLQR] == 0.0  # the block times are each loop's own
    assert rec.lstat[13] == 4 and rec.lsat[13] and rec.li.shape == (20, N_LI)
    assert not np.delete(rec.li, 13, axis=0).any() and rec.lstat.sum() == 4 and rec.lsat.sum() == 1


def _cascade(governor: bool) -> Cascade:
    cfg = Config()
    cfg = replace(cfg, governor=replace(cfg.governor, enabled=governor))
    return Cascade(cfg, Method.REF, builtin_circuit(), x0=np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]))


@pytest.mark.parametrize("governor", [False, True])
def test_the_logged_reference_is_the_sample_until_the_governor_acts(governor: bool, way) -> None:
    logged_reference = way(rb.logged_reference)
    c = _cascade(governor)
    ref = c.reference

    def row(k: int, t: float) -> Any:
        return logged_reference(c._ob_p, c._ref_rec, c._ob, c._oc, k, t, c._ob_buf)

    k = 37
    sample = (ref.x[k], ref.y[k], ref.theta[k], ref.v[k], ref.omega[k])
    assert row(k, k * c.Tc) == sample
    c._ob[OB_RATE], c._ob[OB_TOFF] = 0.5, 0.35  # slowed down: the reference at τ = t − 0.35 s
    if not governor:  # (no governor: its slots mean nothing)
        assert row(k, k * c.Tc) == sample
        return
    got = row(k, k * c.Tc)
    assert got == tuple(c.reference_row(k * c.Tc))
    tau = k * c.Tc - 0.35  # between samples 33 and 34, half-way
    assert got[0] == pytest.approx(0.5 * (ref.x[33] + ref.x[34]), rel=1e-12)
    assert got[3] == pytest.approx(0.5 * 0.5 * (ref.v[33] + ref.v[34]), rel=1e-12)
    assert tau == pytest.approx(33.5 * c.Tc)


def test_the_run_log_reads_the_records() -> None:
    rec = new_records(3, 2, 1)
    rec.lo[:, LO_X] = [1.0, 2.0, 3.0]
    rec.lo[:, LO_REF + 3] = [9.0, 8.0, 7.0]
    rec.lo[:, LO_TMPC] = [0.5, 0.25, 0.125]
    rec.loi[:, LOI_STATUS] = [1, 3, 2]
    rec.li[:, LI_MU] = np.arange(6.0)
    rec.lstat[:] = [4, 4, 1, 2, 3, 1]
    log = run_log(rec, method="REF", scenario="s", Tc=0.1, Td=0.05, t0=2.0, done=2, rows=3, wall_s=1.0,
                  termination="completed", events={}, meta={})
    assert list(log.mpc_status) == ["optimal", "fallback"]
    assert list(log.mhe_status) == ["warmup", "warmup", "ok"]
    np.testing.assert_array_equal(log.state_outer[:, 0], [1.0, 2.0])
    np.testing.assert_array_equal(log.ref[:, 3], [9.0, 8.0])
    np.testing.assert_array_equal(log.mpc_time_s, [0.5, 0.25])
    np.testing.assert_array_equal(log.mu_road, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(log.t_outer, [2.0, 2.1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(log.t_inner, [2.0, 2.05, 2.1], rtol=0, atol=1e-15)
    times = (np.array([1.0, 2.0]), np.zeros(3), np.zeros(3))
    assert list(run_log(rec, method="REF", scenario="s", Tc=0.1, Td=0.05, t0=0.0, done=2, rows=3, times=times,
                        wall_s=1.0, termination="completed", events={}, meta={}).mpc_time_s) == [1.0, 2.0]
