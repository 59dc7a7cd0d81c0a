"""The fusion's glue as one block (control/fusion_block.py, issue 34): the gyro's sample and the
bias-free ω, the course interval's close at an accepted pose with the reference's a_y, the course
and steering-offset samples after the MHE, and the servo — by hand, on numbers chosen so that the
expected values are simple, as Python (the cascade's) and compiled (the engine's, skipped without
numba). The engine calls the same functions on its state vector: tests/test_engine.py and
tests/test_gyro_bias.py compare its runs with the Python loop's (every fusion switch is on by
default)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.config import Config, Method
from tsmpc.control import fusion_block as fb
from tsmpc.control.cascade import Cascade
from tsmpc.control.fusion_block import (
    FB_OFF,
    FB_OMEGA,
    FB_SENT,
    N_FB,
    N_IV,
    FusionParams,
    course_load,
    fusion_state,
    gyro_load,
    iv_load,
    pack_fusion,
    slip_load,
    steer_load,
)
from tsmpc.control.inner_block import EST_FAILED, EST_OK, EST_REJECTED
from tsmpc.control.stiffness_block import N_SA
from tsmpc.estimation import fusion as fu
from tsmpc.estimation.fusion import NO_INTERVAL, SteerState
from tsmpc.planning.circuit import builtin_circuit

TD, TC = 0.01, 0.1


def _params(gyro: bool = True, course: bool = True, steer: bool = True) -> FusionParams:
    """Gyro noise σ_θ 1 mrad, σ_ω 0.01 rad/s; the course fusion of a round car; limits ±0.4 rad."""
    gp = fu.gyro_params(TD, 1e-3, 1e-2)
    cp = fu.course_params(TC, 0.01, True, 50000.0, 50000.0, 1000.0, 1500.0, 1.0, 1.5, 10.0, TD, 10)
    return FusionParams(gyro, course, steer, course, -0.4, 0.4, gp, cp)


def _steer_p() -> fu.SteerParams:
    return fu.steer_params(TD, 50000.0, 50000.0, 1.0, 1.5, 1000.0, 1500.0)


def _offset_state(d0: float) -> SteerState:
    """A fit that says δ₀ = ``d0`` (information 1e6 on δ₀, none shared with ΔK)."""
    return SteerState(True, 0.0, 0.0, 0.0, 1e6, 0.0, 1e4, 1e6 * d0, 0.0, 100)


def test_the_reference_lateral_acceleration_at_the_call(way) -> None:
    ay = way(fb.ay_ref_at)
    vd, wd = np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.5, 0.25, -0.5, 2.0])
    assert ay(TC, 0.35, 0.1, vd, wd) == 3.0 * -0.5  # reference time 0.25 s: sample 2
    assert ay(TC, 0.3, 0.0, vd, wd) == 4.0 * 2.0  # 0.3 / 0.1 = 2.9999…: +1e-6 makes it sample 3
    assert ay(TC, 9.0, 0.0, vd, wd) == 8.0  # past the end: the last sample
    assert ay(TC, 0.05, 0.2, vd, wd) == 0.5  # before the start: the first


def test_a_gyro_bias_is_learnt_against_a_heading_drift() -> None:
    """The car turns at 0.1 rad/s, the gyro reads 0.13 rad/s (bias 0.03): within 2 s the bias-free
    ω is the turn rate; without headings the bias holds; switched off, ω is the raw one."""
    p = _params(course=False, steer=False)
    g, cs = fu.gyro_start(p.gp), fu.course_start(p.cp)
    w, b = 0.1, 0.03
    om = math.nan
    for k in range(200):
        om, g, _, cur = fb.fusion_before(p, g, cs, NO_INTERVAL, True, 0.0, 0.0, w * k * TD, True, 5.0, w + b,
                                         k % 10 == 0, k * TD, 0.0, [1.0], [0.0])
        assert om == w + b - fu.gyro_bias(g) and cur is NO_INTERVAL  # (no course fusion: untouched)
    assert om == pytest.approx(w, abs=1e-4) and g.n_chords > 3
    held = fu.gyro_bias(g)
    for k in range(200, 300):  # no pose: no chord ends, the bias holds
        om, g2, _, _ = fb.fusion_before(p, g, cs, NO_INTERVAL, False, 0.0, 0.0, math.nan, True, 5.0, w + b,
                                        False, k * TD, 0.0, [1.0], [0.0])
        assert fu.gyro_bias(g2) == held
        g = g2
    off = p._replace(gyro=False)
    g0 = fu.gyro_start(p.gp)
    om, g1, _, _ = fb.fusion_before(off, g0, cs, NO_INTERVAL, True, 0.0, 0.0, 0.0, True, 5.0, 0.13, True, 0.0,
                                    0.0, [1.0], [0.0])
    assert om == 0.13 and g1 is g0


def test_the_course_interval_closes_at_an_accepted_pose_with_the_reference_a_y() -> None:
    p = _params(gyro=False, steer=False)
    g, cs = fu.gyro_start(p.gp), fu.course_start(p.cp)
    vd, wd = [10.0, 10.0, 12.0], [0.0, 0.2, -0.25]
    # an accepted pose at an MPC step opens the interval there, with |v_d ω_d| of the call's sample
    _, _, cs1, cur = fb.fusion_before(p, g, cs, NO_INTERVAL, True, 3.0, 4.0, 0.5, True, 10.0, 0.2, True, 0.2,
                                      0.0, vd, wd)
    assert cur.open and (cur.sx, cur.sy, cur.sth) == (3.0, 4.0, 0.5) and cur.ay_ref == 3.0
    assert cs1.since == 0 and cs1.v_now == 10.0 and cs1.omega_now == 0.2
    # a rejected pose ends nothing (the calls since the last end count on)
    _, _, cs2, cur2 = fb.fusion_before(p, g, cs1, cur, False, 3.0, 4.0, 0.5, True, 10.0, 0.2, True, 0.3, 0.0,
                                       vd, wd)
    assert cur2 is cur and cs2.since == 1
    # the speed refused: the interval it ends is spoilt and none opens (v and ω are NaN to the fusion)
    _, _, cs3, cur3 = fb.fusion_before(p, g, cs1, cur, True, 4.0, 4.0, 0.5, False, 10.0, 0.2, True, 0.3, 0.0,
                                       vd, wd)
    assert cur3 == NO_INTERVAL and math.isnan(cs3.v_now) and math.isnan(cs3.omega_now)
    # switched off: the records come back as they came
    off = p._replace(course=False)
    _, _, cs4, cur4 = fb.fusion_before(off, g, cs, NO_INTERVAL, True, 3.0, 4.0, 0.5, True, 10.0, 0.2, True,
                                       0.2, 0.0, vd, wd)
    assert cs4 is cs and cur4 is NO_INTERVAL


def test_the_angle_sent_takes_the_offset_off_within_the_limits(way) -> None:
    servo = way(fb.servo)
    p, sp = _params(), _steer_p()
    st = _offset_state(0.02)  # δ₀ 0.02 rad: d³ / (d² + b²), 0.019999955 taken off (dead band b 3e-4)
    corr = 0.02 ** 3 / (0.02 ** 2 + fu.STEER_DEADBAND ** 2)
    sent, wheels, off = servo(p, sp, st, 0.1)
    assert off == pytest.approx(corr, abs=1e-15) and sent == 0.1 - off and wheels == 0.1
    sent, wheels, off = servo(p, sp, st, -0.39)  # −0.39 − 0.0197 beyond −0.4: clipped
    assert sent == -0.4 and wheels == pytest.approx(-0.4 + corr, abs=1e-15)
    sent, wheels, off = servo(p, sp, _offset_state(-0.02), 0.395)  # the other side
    assert sent == 0.4 and wheels == pytest.approx(0.4 - corr, abs=1e-15)
    assert servo(p._replace(steer=False), sp, st, 0.9) == (0.9, 0.9, 0.0)  # off: unclipped, no offset


def test_the_steering_fit_refuses_a_sample_when_the_mhe_failed(way) -> None:
    after = way(fb.fusion_after)
    p, sp = _params(), _steer_p()
    st = fu.steer_start(sp)._replace(init=True, om_f=0.1, de_f=0.02)  # filters running
    cur = NO_INTERVAL._replace(open=True, ok=True, n=1, sth=0.0, th_last=0.0)
    args = (True, True, 0.01, 10.0, 10.0, 0.001, 0.1, 0.1, 0.02, 500.0)
    cur1, st1 = after(p, sp, st, cur, *args, EST_OK, False, False, 0.03)
    assert st1.n == st.n + 1 and st1.de_f == st.de_f + sp.beta * (0.03 - st.de_f)  # the angle sent
    assert cur1.n == 2 and cur1.s_delta == 0.02 and cur1.s_F == 500.0 and cur1.sv_ay == 10.0 * (10.0 * 0.1)
    frozen = ((EST_FAILED, False, False), (EST_REJECTED, False, False), (EST_OK, True, False),
              (EST_OK, False, True))
    for status, blind, sat in frozen:
        _, st2 = after(p, sp, st, cur, *args, status, blind, sat, 0.03)
        assert st2 == st, (status, blind, sat)  # frozen: nothing moves, nothing is forgotten
    _, st3 = after(p, sp, st, cur, False, *args[1:], EST_OK, False, False, 0.03)  # the sample refused
    assert st3 == st
    cur4, st4 = after(p._replace(course=False, steer=False), sp, st, cur, *args, EST_OK, False, False, 0.03)
    assert cur4 == cur and st4 == st


def _flat(x: object) -> list[object]:
    """A record's numbers, flattened (NaN as the string "nan": equal to itself)."""
    if isinstance(x, tuple):
        return [v for item in x for v in _flat(item)]
    return ["nan" if isinstance(x, float) and math.isnan(x) else x]


def test_the_state_vector_forms_are_the_record_forms() -> None:
    """before_at / after_at / servo_at (the engine's) on the vector give the record forms' answers
    and keep the records, the call's bias-free ω, the offset and the angle sent in their slots."""
    p, sp = _params(), _steer_p()
    g = fu.gyro_start(p.gp)._replace(open=True, th0=0.1, n=3, integ=0.004, w_last=0.13, sb=1.0, sw=500.0)
    st = _offset_state(0.01)
    cs = fu.course_start(p.cp)._replace(n_chords=4, since=3, v_now=7.0)
    cs = cs._replace(slip=cs.slip._replace(kappa=0.002, beta=-0.01))
    cur0 = NO_INTERVAL._replace(open=True, ok=True, n=2, sx=1.0, sth=0.1, sv=3.0, th_last=0.1)
    v, ivs, row = fusion_state(g, st, 0.007, 0.05, cs, cur0)
    assert v.shape == (N_FB,) and ivs.shape == (fu.RING, N_IV) and row.shape == (N_IV,)
    assert gyro_load(v) == g and steer_load(v) == st and (v[FB_OFF], v[FB_SENT]) == (0.007, 0.05)
    assert course_load(v, ivs) == cs and iv_load(row) == cur0 and slip_load(v) == cs.slip
    om, g1, cs1, cur1 = fb.fusion_before(p, g, cs, cur0, True, 1.0, 2.0, 0.11, True, 8.0, 0.14, True,
                                         0.0, 0.0, [2.0], [0.1])
    om_v = fb.before_at(p, v, ivs, row, True, 1.0, 2.0, 0.11, True, 8.0, 0.14, True, 0.0, 0.0,
                        np.array([2.0]), np.array([0.1]))
    assert om_v == om and v[FB_OMEGA] == om and gyro_load(v) == g1
    assert _flat(course_load(v, ivs)) == _flat(cs1) and _flat(iv_load(row)) == _flat(cur1)
    assert cur1 != cur0 and cs1.since == 0  # (an interval ended: a new one opened)
    cur2, st2 = fb.fusion_after(p, sp, st, cur1, True, True, 0.11, 8.0, 8.0, 0.0, 0.14, om, 0.01, 100.0,
                                EST_OK, False, False, 0.05)
    fb.after_at(p, v, sp, row, True, True, 0.11, 8.0, 8.0, 0.0, 0.14, 0.01, 100.0, EST_OK, False, False)
    assert _flat(iv_load(row)) == _flat(cur2) and steer_load(v) == st2 and st2 != st
    off_p = p._replace(gyro=False, course=False, steer=False)  # all off: the records stay as they were
    before = (v.copy(), ivs.copy(), row.copy())
    assert fb.before_at(off_p, v, ivs, row, True, 1.0, 2.0, 0.2, True, 9.0, 0.3, True, 0.1, 0.0,
                        np.array([2.0]), np.array([0.1])) == 0.3 and v[FB_OMEGA] == 0.3
    fb.after_at(off_p, v, sp, row, True, True, 0.2, 9.0, 9.0, 0.0, 0.3, 0.01, 100.0, EST_OK, False, False)
    v[FB_OMEGA] = before[0][FB_OMEGA]
    for x, y in zip(before, (v, ivs, row), strict=True):
        np.testing.assert_array_equal(x, y)
    sent, wheels, off = fb.servo(p, sp, st2, 0.2)
    assert fb.servo_at(p, v, sp, 0.2) == (sent, wheels) and (v[FB_OFF], v[FB_SENT]) == (off, sent)
    # the parameters cross as one vector; the stiffnesses given reach the steering fit's balance
    pk = pack_fusion(p, sp)
    assert len(pk) == fb.N_FBP and fb.unpack_fusion(pk, p.cp) == (p, sp)
    sa = np.zeros(N_SA)
    assert fb.given_steer(sp, sa) is sp
    sa[:] = 1.0, 40000.0, 60000.0, 600.0, 0.8, 1.0
    assert fb.given_steer(sp, sa) == fu.steer_stiffness(sp, 40000.0, 60000.0, 600.0, 0.8, 1.0)


def test_the_cascade_composes_the_block_from_its_config() -> None:
    cfg = Config()
    x0 = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    cas = Cascade(cfg, Method.REF, builtin_circuit(), x0=x0)
    f = cfg.fusion
    p = cas._fb_p
    assert (p.gyro, p.course, p.steer) == (f.gyro_bias, cas._fusion.any_course, f.steering_offset)
    assert p.gyro and p.course and p.steer  # (the defaults)
    assert (p.d_min, p.d_max) == (-cfg.lqr.delta_max, cfg.lqr.delta_max)
    assert p.gp == cas._fusion.gyro.params and p.cp == cas._fusion.course.params
