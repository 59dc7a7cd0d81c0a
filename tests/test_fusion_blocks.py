"""The fusion estimators' blocks (tsmpc.estimation.fusion, issue 34 item 1): the repeat guard, the
course fusion (sample, close, chord fits, outputs) and the mass estimator, each one ``@jitable``
definition that the Python cascade calls as Python and the run engine and the batch compile.

Every by-hand test runs twice — the block as Python (the Python loop's) and compiled by numba (the
engine's, skipped without numba) — on numbers chosen so that the expected values are simple: a
mutation of a block's arithmetic fails the test in both loops. The last test runs a random drive
through both and asks for the same records to the bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _blocks import Blocks
from tsmpc import kernels
from tsmpc.estimation import fusion as fu
from tsmpc.estimation.fusion import (
    BASELINE,
    MASS_HIGHPASS_S,
    MASS_MEMORY_S,
    NO_INTERVAL,
    REPEAT_START,
    RING,
    SLIP_PRIOR,
    STIFF_CORRELATION,
    STIFF_MEMORY_S,
    STIFF_PRIOR_REL,
    CourseState,
    Interval,
    MassParams,
    MassState,
    SlipFit,
)

#: The blocks the tests call (their names in tsmpc.estimation.fusion).
BLOCKS = ("repeat_check", "course_params", "course_sample", "course_close", "course_chord",
          "slip_correction", "noise_scale", "speed_offset", "speed_sensor", "stiffness", "model_changed",
          "stiffness_update", "mass_update", "delta_mass", "inertia_force", "_lateral_fit", "lateral_model")
_Blocks = Blocks


@pytest.fixture(params=["python", "compiled"])
def b(request) -> _Blocks:
    if request.param == "compiled" and kernels.load("mpc") is None:
        pytest.skip("compiled kernels unavailable")
    return Blocks(fu, BLOCKS, request.param == "compiled")


def _params(b: _Blocks, Tc: float = 0.1, sigma: float = 0.01, C: tuple[float, float] = (50000.0, 50000.0)):
    """A car with round numbers: M 1000 kg, I_z 1500 kg m², a = 1, b = 1.5 m, g = 10 m/s²; 10
    calls of T_c / 10 per MPC period."""
    return b.course_params(Tc, sigma, True, C[0], C[1], 1000.0, 1500.0, 1.0, 1.5, 10.0, Tc / 10, 10)


def _records(x):
    """A record's numbers, flattened (NaN as the string "nan": equal to itself)."""
    if isinstance(x, tuple):
        return [v for item in x for v in _records(item)]
    return ["nan" if isinstance(x, float) and math.isnan(x) else x]


def _drive_arc(b: _Blocks, p, v: float, w: float, seconds: float, v_sensor: float = 0.0,
               Td: float = 0.01):
    """Exact samples of a circular arc at speed v and yaw rate ω (α = 0: the course is the
    heading), the speed sensor reading v + ``v_sensor``: (state, open interval) after it."""
    s, cur = fu.course_start(p), NO_INTERVAL
    n_in = round(p.Tc / Td)
    R = v / w
    for k in range(round(seconds / Td) + 1):
        th = w * k * Td
        if k % n_in == 0:
            s, cur = b.course_close(p, s, cur, True, True, R * math.sin(th), R * (1.0 - math.cos(th)), th,
                                    v + v_sensor, w, v * w)
        cur = b.course_sample(p, cur, True, True, th, v + v_sensor, 0.0, v * w, w, 0.0, 0.0)
    return s, cur


# ------------------------------------------------------------------------------------ repeat guard
def test_repeat_guard_by_hand(b: _Blocks) -> None:
    s = REPEAT_START
    same, s = b.repeat_check(s, 1.0, 2.0, 0.1, 10.0, 0.01, -math.inf)
    assert not same and s.has
    same, s = b.repeat_check(s, 1.0, 2.0, 0.1, 10.0, 0.01, -math.inf)
    assert same
    for i in range(6):  # any one of the six numbers differing: a new sample
        x = [1.0, 2.0, 0.1, 10.0, 0.01, -math.inf]
        x[i] = 5.0
        assert not b.repeat_check(s, *x)[0]
    same, s2 = b.repeat_check(s, 1.0, math.nan, 0.1, 10.0, 0.01, -math.inf)
    assert not same and tuple(s2) == tuple(s)  # a NaN sample: not a repeat, not remembered
    assert b.repeat_check(s, -0.0 + 1.0, 2.0, 0.1, 10.0, 0.01, -math.inf)[0]


# ------------------------------------------------------------------------------------ course fusion
def test_an_interval_sums_by_the_trapezoid(b: _Blocks) -> None:
    """Opening pose, samples at v = 10 and 12 m/s, closing at 14 m/s: Σ v = 10/2 + 12 + 14/2 =
    24 (the opening and closing samples count half), Σ v in full 22; the first sample's ω and v
    are kept; a missing speed sample spoils the interval, a missing pose does not end it."""
    p = _params(b)
    s, cur = b.course_close(p, fu.course_start(p), NO_INTERVAL, True, True, 0.0, 0.0, 0.0, 10.0, 0.0, 0.3)
    assert cur.open and cur.ok and cur.n == 0 and cur.ay_ref == 0.3 and math.isnan(cur.v_first)
    cur = b.course_sample(p, cur, True, True, 0.0, 10.0, 0.01, 1.0, 0.1, 0.02, 500.0)
    cur = b.course_sample(p, cur, True, True, 0.2, 12.0, 0.03, 2.0, 0.2, 0.04, 700.0)
    assert cur.n == 2 and cur.w_first == 0.1 and cur.v_first == 10.0
    assert cur.sv == pytest.approx(5.0 + 12.0) and cur.sv_full == pytest.approx(22.0)
    assert cur.sv_dth == pytest.approx(12.0 * 0.2)  # v (θ − θ_start), the first counting half
    assert cur.sv_alpha == pytest.approx(10.0 * 0.01 + 12.0 * 0.03)
    assert cur.sv_ay == pytest.approx(10.0 * 1.0 + 12.0 * 2.0)
    assert cur.s_delta == pytest.approx(0.06) and cur.s_F == pytest.approx(1200.0)
    assert cur.s_w_v == pytest.approx(0.1 / 10.0 + 0.2 / 12.0) and cur.s_vw == pytest.approx(1.0 + 2.4)
    s, nxt = b.course_close(p, s, cur, True, True, 2.2, 0.0, 0.4, 14.0, 0.0, -0.2)
    last = s.ring[-1]
    assert s.n_iv == 1 and last.ok and last.ay_ref == 0.2  # the smaller |v_d ω_d| of both ends
    assert last.sv == pytest.approx(24.0) and last.sv_dth == pytest.approx(12.0 * 0.2 + 7.0 * 0.4)
    assert nxt.open and (nxt.sx, nxt.sy, nxt.sth) == (2.2, 0.0, 0.4) and s.since == 0
    spoilt = b.course_sample(p, nxt, False, True, 0.4, 14.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert not spoilt.ok and spoilt.n == 0
    assert b.course_sample(p, NO_INTERVAL, True, True, 0.4, 14.0, 0.0, 0.0, 0.0, 0.0, 0.0) == NO_INTERVAL
    # no pose, even at an MPC step: nothing ends (the interval goes on, the calls are counted)
    s, same = b.course_close(p, s, spoilt, True, False, math.nan, math.nan, math.nan, 14.0, 0.0, 0.0)
    assert _records(same) == _records(spoilt) and s.n_iv == 1 and s.since == 1
    # a pose between MPC steps ends nothing before the interval has lasted a T_c (10 calls) ...
    s, same = b.course_close(p, s, spoilt, False, True, 3.0, 0.0, 0.4, 14.0, 0.0, 0.0)
    assert _records(same) == _records(spoilt) and s.n_iv == 1 and s.since == 2
    s = s._replace(since=9)
    # ... then it does; a pose without a speed closes the interval spoilt and opens none
    s, none = b.course_close(p, s, spoilt, False, True, 4.0, 0.0, 0.4, math.nan, 0.0, 0.0)
    assert not none.open and not s.ring[-1].ok and s.n_iv == 2 and s.since == 0


def test_between_poses_the_heading_is_the_gyros_integral(b: _Blocks) -> None:
    """A sample without a pose takes the last sample's heading plus the trapezoid integral of ω
    over T_d (0.01 s here); a pose's heading replaces it. The opening sample is the pose's own."""
    p = _params(b)
    _, cur = b.course_close(p, fu.course_start(p), NO_INTERVAL, True, True, 0.0, 0.0, 0.1, 10.0, 0.2, 0.0)
    cur = b.course_sample(p, cur, True, False, math.nan, 10.0, 0.0, 0.0, 0.2, 0.0, 0.0)
    assert cur.ok and cur.th_last == 0.1 and cur.w_last == 0.2 and cur.sv_dth == 0.0
    cur = b.course_sample(p, cur, True, False, math.nan, 10.0, 0.0, 0.0, 0.4, 0.0, 0.0)
    assert cur.th_last == pytest.approx(0.1 + 0.5 * (0.2 + 0.4) * 0.01, rel=1e-15)
    assert cur.sv_dth == pytest.approx(10.0 * 0.003, rel=1e-12)
    cur = b.course_sample(p, cur, True, True, 0.5, 10.0, 0.0, 0.0, 0.4, 0.0, 0.0)  # a pose: its θ
    assert cur.ok and cur.th_last == 0.5 and cur.sv_dth == pytest.approx(10.0 * (0.003 + 0.4), rel=1e-12)
    # a missing yaw rate between poses spoils the interval (no heading to integrate)
    assert not b.course_sample(p, cur, True, False, math.nan, 10.0, 0.0, 0.0, math.nan, 0.0, 0.0).ok


def test_the_speed_over_ground_is_the_arc_not_the_chord(b: _Blocks) -> None:
    """On an exact arc (10 m/s, 2 rad/s: 0.2 rad of turn per interval of T_c) the arc's length
    over the interval's time is the speed itself: the fitted sensor offset is 0, or the sensor's
    0.3 m/s at that speed. The chord alone is shorter by v Δθ²/24 (0.017 m/s here)."""
    p = _params(b)
    s, _ = _drive_arc(b, p, 10.0, 2.0, 3.0)
    assert s.n_chords == 30 - BASELINE + 1
    assert abs(b.speed_offset(s.speed, 10.0)) < 1e-9
    s, _ = _drive_arc(b, p, 10.0, 2.0, 3.0, v_sensor=0.3)
    # (3 s of 1 cm positions over 0.1 s intervals: 0.2 % of the 0.3 m/s is still the prior's)
    assert b.speed_offset(s.speed, 10.3) == pytest.approx(0.3, rel=0.005)
    # at one speed the fit's (c, k) of v_measured − v = c + k v_measured (c = o / (1 + e),
    # k = e / (1 + e)) explain 0.3 m/s as the priors split it: c/σ_o² = k/(v_measured σ_e²)
    o, e = b.speed_sensor(s.speed)
    c, k = o / (1.0 + e), e / (1.0 + e)
    so, se = fu.SPEED_PRIOR
    assert c + 10.3 * k == pytest.approx(0.3, rel=0.005)
    assert c / so**2 == pytest.approx(k / (10.3 * se**2), rel=0.01)
    # the fit's information: per interval 1 / (2 (σ/T_c)² + SPEED_MODEL_SIGMA²), forgetting
    # 1 − T_c / SPEED_MEMORY_S towards the prior, one interval per T_c (30 of them)
    w = 1.0 / (2.0 * (0.01 / 0.1) ** 2 + fu.SPEED_MODEL_SIGMA**2)
    g = 1.0 - 0.1 / fu.SPEED_MEMORY_S
    assert s.speed.l00 == pytest.approx(1.0 / so**2 + w * sum(g**k for k in range(30)), rel=1e-9)
    assert s.speed.l11 == pytest.approx(1.0 / se**2 + 10.3**2 * w * sum(g**k for k in range(30)), rel=1e-9)
    big = fu.SpeedFit(1.0, 0.0, 1.0, 5.0, -0.5, 1.0, 1.0)  # (c, k) = (5, −0.5): bounded
    assert b.speed_offset(big, 0.0) == fu.SPEED_OFFSET_MAX
    assert b.speed_offset(big, 1.0) == pytest.approx(fu.SPEED_OFFSET_MAX - fu.SPEED_SCALE_MAX, rel=1e-12)
    assert b.speed_sensor(fu.SpeedFit(0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0)) == (0.0, 0.0)  # no information


def _corner_ring(p, alpha_hat: float = -0.01, ay_ref: float = 5.0, v_first: float = 10.0) -> CourseState:
    """Five measured intervals of 10 samples at v = 10 m/s, ω = 0.5 rad/s (a_y = 5 m/s²), δ = 0.11
    rad, no force, heading 0, the model's α̂ = ``alpha_hat``, from the pose (0, 0, 0); the fits at
    their start, but the noise measured at half the configured level (the configured σ stays the
    floor: the noise scale is 1)."""
    iv = Interval(True, True, 0.0, 0.0, 0.0, 10, 100.0, 0.0, 100.0 * alpha_hat, 500.0, 100.0, 1.1, 0.5,
                  50.0, 0.0, 0.5, ay_ref, v_first, 0.0, 0.5)
    s = fu.course_start(p)
    slip = s.slip._replace(n2=0.25 * fu.NOISE_PRIOR_CHORDS)
    return CourseState((NO_INTERVAL,) * (RING - BASELINE) + (iv,) * BASELINE, BASELINE, 0.5, 10.0, 0, slip,
                       s.speed, s.stiff, 0, fu.FIT_SETTLE_S, s.lat)


K0 = RING - BASELINE  #: the ring index of :func:`_corner_ring`'s first interval


def _transient_ring(p) -> CourseState:
    """:func:`_corner_ring` with α̂ = −0.02 on average, changing along the chord: its first
    interval's mean −0.01, its last's −0.03 rad (centres 0.4 s apart: α̇ = −0.05 rad/s)."""
    r = _corner_ring(p, -0.02)
    return r._replace(ring=(*r.ring[:K0], r.ring[K0]._replace(sv_alpha=100.0 * -0.01), *r.ring[K0 + 1:-1],
                            r.ring[-1]._replace(sv_alpha=100.0 * -0.03)))


def test_one_cornering_chord_in_the_slip_and_stiffness_fits(b: _Blocks) -> None:
    """The chord of :func:`_corner_ring` to (5, 0, 0): course 0, so the slip error z = 0.01 rad at
    ā_y = 5, one recursive least-squares step from the prior; the axle forces of S = M v ω =
    5000 N, F_yF = b S / L = 3000 N, F_yR = a S / L = 2000 N, the slips α_F = δ − a ω/v = 0.06,
    α_R = b ω/v = 0.075 rad, each weighed against the model's prior (relative σ STIFF_PRIOR_REL):
    Ĉ = (C / REL)² + w F²) / ((C / REL)² / C + w F α)."""
    p = _params(b)
    s = b.course_chord(p, _corner_ring(p), K0, 5.0, 0.0, 0.0)
    assert s.n_chords == 1
    sig = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4  # the chord's slip noise (noise scale 1)
    lam = 1.0 - 0.1 / fu.SLIP_MEMORY_S
    P = np.diag(np.square(SLIP_PRIOR)) / lam
    phi = np.array([5.0, 1.0])
    k = P @ phi / (sig ** 2 + phi @ P @ phi)
    assert (s.slip.kappa, s.slip.beta) == pytest.approx(tuple(k * 0.01), rel=1e-12)
    P1 = P - np.outer(k, phi @ P)
    assert (s.slip.P00, s.slip.P01, s.slip.P10, s.slip.P11) == pytest.approx(tuple(P1.ravel()), rel=1e-12)
    assert (s.slip.n2, s.slip.n1) == (0.25 * fu.NOISE_PRIOR_CHORDS, fu.NOISE_PRIOR_CHORDS)  # a corner
    w = 1.0 / (STIFF_CORRELATION * sig * sig)
    prior = (50000.0 / STIFF_PRIOR_REL) ** 2
    C_f = (prior + w * 3000.0 ** 2) / (prior / 50000.0 + w * 3000.0 * 0.06)
    C_r = (prior + w * 2000.0 ** 2) / (prior / 50000.0 + w * 2000.0 * 0.075)
    assert b.stiffness(p, s.stiff) == pytest.approx((C_f, C_r), rel=1e-12)
    assert 30000.0 < C_r < 40000.0  # between the prior (50000) and the chord's own (26667)
    assert s.stiff.has_prev and s.stiff.alpha_prev == pytest.approx(-0.01)
    # the next chord: α̇ from the α̂ of consecutive chords, forgetting towards the prior
    s2 = b.course_chord(p, CourseState(_corner_ring(p, -0.02).ring, BASELINE, 0.5, 10.0, 1, s.slip, s.speed,
                                       s.stiff, 0, s.age, s.lat), K0, 5.0, 0.0, 0.0)
    g2 = 1.0 - 0.1 / STIFF_MEMORY_S
    S = 1000.0 * (5.0 + 10.0 * (-0.01 / 0.1))  # M (v ω + v α̇), α̇ = −0.01 rad / T_c: 4000 N
    F_f = 1.5 * S / 2.5  # 2400 N on α_F = 0.06: 40000 N/rad, plausible; the rear's 1600 N on
    num_f = g2 * s.stiff.num_f + (1.0 - g2) * prior / 50000.0 + w * F_f * 0.06  # 0.075 is not (21333)
    assert s2.stiff.num_f == pytest.approx(num_f, rel=1e-12)
    assert s2.stiff.den_f == pytest.approx(g2 * s.stiff.den_f + (1.0 - g2) * prior + w * F_f ** 2, rel=1e-12)
    assert s2.stiff.den_r == pytest.approx(g2 * s.stiff.den_r + (1.0 - g2) * prior, rel=1e-12)
    assert s2.stiff.alpha_prev == pytest.approx(-0.02)


def test_a_chord_after_a_long_step_weighs_its_lagging_alpha_dot_as_noise(b: _Blocks) -> None:
    """After a step of 20 calls (a 5 Hz pose) the chord's α̇ = Δᾱ̂ / 0.2 s lags it by the 0.1 s
    beyond T_c: half of M v α̇ counts as force noise, F / C of slip on each axle, beside the
    chord's own slip noise (correlated over STIFF_CORRELATION T_c: 2.5 chords of 0.2 s). The
    chord of :func:`_corner_ring` after the first, its last interval lasting 20 calls (the sums
    unchanged: 60 calls in all): ā_y's means over 60 calls, α̇ = −0.01 / 0.2 = −0.05 rad/s,
    S = M (v ω + v α̇) = 3750 N, F_yF = b S / L = 2250 N on α_F = 0.05 rad (45000 N/rad) and the
    rear's 1500 N on 0.0625 rad (24000 N/rad: 0.48× the model's, below the band of 0.5–2×, but its
    slip within one σ of the band's 0.06 rad, STIFF_BAND_SIGMAS, so it counts)."""
    p = _params(b)
    s = b.course_chord(p, _corner_ring(p), K0, 5.0, 0.0, 0.0)
    r = _corner_ring(p, -0.02)
    ring = (*r.ring[:-1], r.ring[-1]._replace(n=20))
    s2 = b.course_chord(p, CourseState(ring, BASELINE, 0.5, 10.0, 1, s.slip, s.speed, s.stiff, 0, s.age,
                                       s.lat), K0, 5.0, 0.0, 0.0)
    sig = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4
    v = 500.0 / 60.0
    e_f = (1.5 / 2.5) * (1000.0 * v * 0.05 * 0.5) / 50000.0  # 2.5 mrad
    w_f = 1.0 / (2.5 * sig * sig + 2.5 * e_f * e_f)
    g2 = 1.0 - 0.2 / STIFF_MEMORY_S
    prior = (50000.0 / STIFF_PRIOR_REL) ** 2
    assert s2.stiff.den_f == pytest.approx(g2 * s.stiff.den_f + (1.0 - g2) * prior + w_f * 2250.0 ** 2,
                                           rel=1e-12)
    assert s2.stiff.num_f == pytest.approx(g2 * s.stiff.num_f + (1.0 - g2) * prior / 50000.0
                                           + w_f * 2250.0 * 0.05, rel=1e-12)
    e_r = (1.0 / 2.5) * (1000.0 * v * 0.05 * 0.5) / 50000.0
    w_r = 1.0 / (2.5 * sig * sig + 2.5 * e_r * e_r)
    assert s2.stiff.den_r == pytest.approx(g2 * s.stiff.den_r + (1.0 - g2) * prior + w_r * 1500.0 ** 2,
                                           rel=1e-12)
    assert s2.stiff.num_r == pytest.approx(g2 * s.stiff.num_r + (1.0 - g2) * prior / 50000.0
                                           + w_r * 1500.0 * 0.0625, rel=1e-12)


def test_a_chord_through_a_transient_counts_its_alpha_rate_as_slip_error(b: _Blocks) -> None:
    """α̂ changing along the chord — its five intervals' means −0.01, −0.02, −0.02, −0.02, −0.03
    rad (mean −0.02, so z = 0.02 at ā_y = 5), the first's and the last's centres 40 calls = 0.4 s
    apart: α̇ = −0.05 rad/s, and SLIP_TRANSIENT_S |α̇| = 15 mrad of slip error beside the
    chord's 5.9 mrad of position noise in the recursive least-squares step (a steady chord, the
    test above, has none)."""
    p = _params(b)
    r = _transient_ring(p)
    s = b.course_chord(p, r, K0, 5.0, 0.0, 0.0)
    sig = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4
    e_tr = fu.SLIP_TRANSIENT_S * 0.05
    lam = 1.0 - 0.1 / fu.SLIP_MEMORY_S
    P = np.diag(np.square(SLIP_PRIOR)) / lam
    phi = np.array([5.0, 1.0])
    k = P @ phi / (sig ** 2 + e_tr ** 2 + phi @ P @ phi)
    assert (s.slip.kappa, s.slip.beta) == pytest.approx(tuple(k * 0.02), rel=1e-12)
    P1 = P - np.outer(k, phi @ P)
    assert (s.slip.P00, s.slip.P01, s.slip.P10, s.slip.P11) == pytest.approx(tuple(P1.ravel()), rel=1e-12)
    steady = b.course_chord(p, _corner_ring(p, -0.02), K0, 5.0, 0.0, 0.0)  # same z, no transient
    assert 0.0 < s.slip.kappa < 0.9 * steady.slip.kappa  # the transient weighs less


def test_the_lateral_fits_wait_out_the_start_transient(b: _Blocks) -> None:
    """For the first FIT_SETTLE_S seconds of chords the slip fit takes the chord as an offset β
    alone (φ = [0, 1]: κ and its variance hold their prior) and the stiffness fits hold theirs,
    while the speed fit learns; each chord adds its last interval's T_c to the age; from
    FIT_SETTLE_S on the same chord moves them all."""
    p = _params(b)
    young = _corner_ring(p, -0.02)._replace(age=fu.FIT_SETTLE_S - 0.05)
    s = b.course_chord(p, young, K0, 5.0, 0.0, 0.0)
    assert s.age == pytest.approx(fu.FIT_SETTLE_S + 0.05, rel=1e-12)
    assert s.stiff == young.stiff and s.slip.kappa == 0.0
    lam = 1.0 - 0.1 / fu.SLIP_MEMORY_S
    P00, P11 = SLIP_PRIOR[0] ** 2 / lam, SLIP_PRIOR[1] ** 2 / lam
    sig = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4
    assert s.slip.P00 == pytest.approx(P00, rel=1e-12)  # κ's variance: forgetting only
    assert s.slip.beta == pytest.approx(P11 / (sig ** 2 + P11) * 0.02, rel=1e-12)  # z = 0.02, all β
    assert s.speed == young.speed  # (the speed fit takes intervals, as course_close closes them)
    settled = b.course_chord(p, young._replace(age=fu.FIT_SETTLE_S), K0, 5.0, 0.0, 0.0)
    assert settled.slip.kappa > 0.0 and settled.stiff != young.stiff
    assert settled.speed == s.speed  # the speed fit does not wait


def test_the_first_cornering_chord_counts_its_alpha_change_as_force_noise(b: _Blocks) -> None:
    """The first cornering chord has no previous one to take α̇ from: α̇ is 0 and α̂'s change
    within the chord (its intervals' means −0.01 … −0.03 rad, centres 0.4 s apart: 0.05 rad/s) is
    the error of M v α̇ = 1000 · 10 · 0.05 = 500 N, 6 mrad of front slip (F / C, b / L of it) beside
    the chord's noise; a later chord with α̇ from its predecessor has none (no lag at T_c)."""
    p = _params(b)
    r = _transient_ring(p)
    first = b.course_chord(p, r, K0, 5.0, 0.0, 0.0)
    sig = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4
    e_f = (1.5 / 2.5) * 500.0 / 50000.0
    prior = (50000.0 / STIFF_PRIOR_REL) ** 2
    w_f = 1.0 / (STIFF_CORRELATION * (sig * sig + e_f * e_f))
    assert first.stiff.den_f == pytest.approx(prior + w_f * 3000.0 ** 2, rel=1e-12)
    later = b.course_chord(p, r._replace(stiff=r.stiff._replace(alpha_prev=-0.02, has_prev=True)),
                           K0, 5.0, 0.0, 0.0)
    w = 1.0 / (STIFF_CORRELATION * sig * sig)
    assert later.stiff.den_f == pytest.approx(prior + w * 3000.0 ** 2, rel=1e-12)
    assert first.stiff.den_f - prior < 0.6 * (later.stiff.den_f - prior)  # the first counts for half


def test_the_stiffness_fit_takes_only_steady_corners(b: _Blocks) -> None:
    """No stiffness update where the reference runs straight (min |v_d ω_d| < CORNER_ACCEL), where
    the car accelerates (|Δv| / span > STIFF_MAX_ACCEL g) or for an implausible F / α; on the
    straight the slip fit's innovation measures the chords' noise instead."""
    p = _params(b)
    start = fu.course_start(p).stiff
    straight = b.course_chord(p, _corner_ring(p, alpha_hat=-0.05, ay_ref=0.1), K0, 5.0, 0.0, 0.0)
    assert straight.stiff == start and straight.n_chords == 1
    sig0 = 2.0 * math.sqrt(2.0) * 0.01 / 5.0 + 2e-4
    g_n = 1.0 - 0.1 / fu.NOISE_MEMORY_S
    assert straight.slip.n2 == pytest.approx(g_n * 2.5 + (0.05 / sig0) ** 2, rel=1e-12)
    assert straight.slip.n1 == pytest.approx(g_n * 10.0 + 1.0, rel=1e-12)
    scale = math.sqrt(straight.slip.n2 / straight.slip.n1)  # 0.05 rad of innovation: 2.6× the σ
    assert b.noise_scale(straight.slip) == pytest.approx(scale) and scale > 2.0
    # 0.1 g over the chord's 0.5 s is 0.5 m/s: 0.49 passes, 0.51 does not
    assert b.course_chord(p, _corner_ring(p, v_first=10.0 - 0.49), K0, 5.0, 0.0, 0.0).stiff != start
    assert b.course_chord(p, _corner_ring(p, v_first=10.0 - 0.51), K0, 5.0, 0.0, 0.0).stiff == start
    stiff_car = _params(b, C=(200000.0, 200000.0))  # the chord's F / α is below 0.5 C: out
    s = b.course_chord(stiff_car, _corner_ring(stiff_car), K0, 5.0, 0.0, 0.0)
    assert b.stiffness(stiff_car, s.stiff) == pytest.approx((200000.0, 200000.0), rel=1e-12)
    assert b.course_chord(p, _corner_ring(p), K0, 1.9, 0.0, 0.0) == _corner_ring(p)  # < MIN_CHORD_M
    r = _corner_ring(p)
    still = CourseState(tuple(iv._replace(sv=0.0) for iv in r.ring), *r[1:])  # no speed: no chord
    assert b.course_chord(p, still, K0, 5.0, 0.0, 0.0) == still


def test_stiffness_bounds_prior_and_application(b: _Blocks) -> None:
    """The prior is the model (Ĉ = C); the fit is bounded to STIFF_RANGE × C; the stiffnesses are
    given when they moved by over 1 % (or were never given), and replacing given ones restarts κ."""
    p = _params(b, C=(40000.0, 60000.0))
    s0 = fu.course_start(p)
    assert p.prior_den_f == pytest.approx((40000.0 / STIFF_PRIOR_REL) ** 2, rel=1e-15)
    assert p.prior_num_r == pytest.approx((60000.0 / STIFF_PRIOR_REL) ** 2 / 60000.0, rel=1e-15)
    assert b.stiffness(p, s0.stiff) == pytest.approx((40000.0, 60000.0), rel=1e-15)
    far = fu.StiffFit(1.0, -1.0, 1e6, 1.0, 0.0, False)  # 1e6 N/rad and a negative compliance
    assert b.stiffness(p, far) == (2.0 * 40000.0, 2.0 * 60000.0)
    assert b.stiffness(p, fu.StiffFit(1.0, 1.0, 1.0, 1.0, 0.0, False)) == (0.5 * 40000.0, 0.5 * 60000.0)
    slip = SlipFit(0.003, 0.002, 1e-5, 2e-6, 2e-6, 3e-4, 12.0, 11.0)
    s = CourseState(s0.ring, 0, 0.0, math.nan, 0, slip, s0.speed, s0.stiff, 0, 0.0, s0.lat)
    give, cf, cr, ii, aa, bb, s1 = b.stiffness_update(p, s, False, 0.0, 0.0, 0.0, 0.0)  # none given: κ kept
    assert give and (cf, cr) == pytest.approx((40000.0, 60000.0)) and s1.slip == slip
    assert (ii, aa, bb) == (1500.0, 1.0, 1.5)  # the joint fit not ready: the model's I_z and CoG
    give, *_, s1 = b.stiffness_update(p, s, True, 40000.0 * 1.0099, 60000.0 / 1.0099, 1500.0, 1.0)
    assert not give and s1.slip == slip  # within 1 %
    # a move of exactly 1 % is not "over 1 %" (|40400 − 40000| = 0.01 × 40000 = 400 in doubles)
    p_move = _params(b, C=(40400.0, 60000.0))
    s_move = s._replace(stiff=fu.course_start(p_move).stiff)  # (the fit at its prior: Ĉ_f = 40400)
    cf_move, cr_move = b.stiffness(p_move, s_move.stiff)
    assert cf_move == 40400.0
    give, *_, s1 = b.stiffness_update(p_move, s_move, True, 40000.0, cr_move, 1500.0, 1.0)
    assert not give and s1.slip == slip
    p_move = _params(b, C=(40000.0, 64640.0))  # the same on the rear axle (1 % above 64000)
    s_move = s._replace(stiff=fu.course_start(p_move).stiff)
    cf_move, cr_move = b.stiffness(p_move, s_move.stiff)
    assert cr_move == 64640.0
    give, *_, s1 = b.stiffness_update(p_move, s_move, True, cf_move, 64000.0, 1500.0, 1.0)
    assert not give and s1.slip == slip
    give, *_, s1 = b.stiffness_update(p, s, True, 40000.0, 60000.0, 1500.0 * 1.0102, 1.0)  # I_z moved
    assert give and s1.slip == b.model_changed(slip)
    give, *_, s1 = b.stiffness_update(p, s, True, 40000.0, 60000.0 * 1.0102, 1500.0, 1.0)
    assert give and s1.slip == b.model_changed(slip)
    assert tuple(s1.slip) == (0.0, 0.002, SLIP_PRIOR[0] ** 2, 0.0, 0.0, 3e-4, 12.0, 11.0)


def test_the_joint_fit_takes_over_on_a_straight_and_keeps_its_model_in_corners(b: _Blocks) -> None:
    """stiffness_update with the joint lateral fit: on a straight (the last interval's |v_d ω_d|
    below CORNER_ACCEL) once the fit has a chord, its (C_f, C_r, I_z, a, b) are given (κ restarts)
    and the fit is in force; in a corner then nothing is given, whatever the compliance fit says;
    before the fit has a chord (or in a corner before it took over) the compliance fit gives, with
    the model's I_z and CoG."""
    p = _params(b, C=(40000.0, 60000.0))
    s0 = fu.course_start(p)
    slip = SlipFit(0.003, 0.002, 1e-5, 2e-6, 2e-6, 3e-4, 12.0, 11.0)
    sd2 = 0.01 ** 2  # a fit of σ 1 % in each parameter
    lat = s0.lat._replace(x=(0.44, 0.8, 0.8, 1.25, 0.001), fitted=True,
                          P=(sd2, 0.0, 0.0, 0.0, 0.0, sd2, 0.0, 0.0, 0.0, sd2, 0.0, 0.0, sd2, 0.0, sd2))
    model = (40000.0, 60000.0, 1500.0, 1.0)  # the model, given at the first MPC step

    def at(ay_ref: float, lat=lat, stiff=s0.stiff):
        ring = (*s0.ring[:-1], NO_INTERVAL._replace(ay_ref=ay_ref))
        return CourseState(ring, 1, 0.0, 10.0, 0, slip, s0.speed, stiff, 0, 10.0, lat)

    give, cf, cr, ii, aa, bb, s1 = b.stiffness_update(p, at(0.1), True, *model)
    assert give and (cf, cr, ii, aa, bb) == pytest.approx((50000.0, 48000.0, 1200.0, 1.1, 1.4), rel=1e-12)
    assert s1.lat.given and s1.slip == b.model_changed(slip) and s1.lat.x == lat.x
    # the same estimate at the prior's σ departs from the model by under LATERAL_SIGNIFICANCE σ in
    # every parameter (0.8, 0.67, 0.67, 0.83): not given (the compliance fit, asked instead, is at
    # its prior: the model's own stiffnesses)
    give, *out, s1p = b.stiffness_update(p, at(0.1, lat._replace(P=s0.lat.P)), True, *model)
    assert not give and not s1p.lat.given
    # fusion.lateral_fit off: never the joint fit's, the compliance fit's (here the model's own)
    p_off = b.course_params(0.1, 0.01, True, 40000.0, 60000.0, 1000.0, 1500.0, 1.0, 1.5, 10.0, 0.01, 10,
                            False)
    give, *out, s1o = b.stiffness_update(p_off, at(0.1), True, *model)
    assert not give and not s1o.lat.given
    # one parameter beyond it (a / L 0.46: 1.2 σ) is enough
    beyond = lat._replace(P=s0.lat.P, x=(0.46, *lat.x[1:]))
    give, *out, _ = b.stiffness_update(p, at(0.1, beyond), True, *model)
    assert give and out[3] == pytest.approx(1.15, rel=1e-12)
    given = (cf, cr, ii, aa)
    soft = fu.StiffFit(1.0, 1.0, 0.7 * 40000.0, 0.7 * 60000.0, 0.0, False)  # the compliance fit: 0.7×
    for ay in (fu.CORNER_ACCEL, 3.0):  # a corner: the joint fit's model stays, nothing given
        give, *out, s2 = b.stiffness_update(p, at(ay, s1.lat, soft), True, *given)
        assert not give and s2 is not None and tuple(out) == pytest.approx((*given, 1.4), rel=1e-12)
    give, *_ = b.stiffness_update(p, at(0.1, s1.lat), True, cf * 1.009, cr, ii, aa)  # within 1 %
    assert not give
    # not taken over yet: in a corner, or before its first chord, the compliance fit gives
    give, *out, s3 = b.stiffness_update(p, at(3.0, stiff=soft), True, *model)
    assert give and tuple(out) == pytest.approx((0.7 * 40000.0, 0.7 * 60000.0, 1500.0, 1.0, 1.5), rel=1e-12)
    assert not s3.lat.given
    give, *out, _ = b.stiffness_update(p, at(0.1, s0.lat, soft), True, *model)
    assert give and tuple(out)[2:] == (1500.0, 1.0, 1.5)


def _pacejka_slip(F: float, C_x: float, D: float) -> float:
    """The slip [rad] at which a magic-formula tyre (shape C 1.3, curvature E −0.5, the plant's
    defaults; small-slip stiffness ``C_x``, peak ``D``) carries the force F (bisection)."""
    c, e = 1.3, -0.5
    B = C_x / (c * D)
    lo, hi = 0.0, 1.0 / B
    while math.sin(c * math.atan(B * hi - e * (B * hi - math.atan(B * hi)))) < abs(F) / D:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if math.sin(c * math.atan(B * mid - e * (B * mid - math.atan(B * mid)))) < abs(F) / D:
            lo = mid
        else:
            hi = mid
    return math.copysign(0.5 * (lo + hi), F)


def _lateral_chords(rng: np.random.Generator, n: int, car: tuple[float, float, float, float],
                    yaw_accel: bool = True, slip_rate: float = 0.0, mu: float = 0.0,
                    a_y: tuple[float, float] = (1.0, 3.0)) -> list[tuple[float, ...]]:
    """``n`` cornering chords of :func:`_params`' single track (M 1000 kg, L 2.5 m, g 10 m/s²) with
    the true (a, I_z, C_f, C_r) = ``car``, no steering residual, no force: (α, v ω, v, ω̇ D, ω / v,
    δ, α̇) for a chord of D = 0.5 s, |v ω| within ``a_y``, α̇ within ±``slip_rate``. Slips from the
    forces (S = M v (ω + α̇)): linear tyres, or with ``mu`` > 0 magic-formula ones of peak
    μ F_z: α = b ω / v − α_R(F_yR), δ = α + a ω / v + α_F(F_yF)."""
    a, inertia, C_f, C_r = car
    L = 2.5
    out = []
    for _ in range(n):
        v = rng.uniform(8.0, 20.0)
        w = rng.choice([-1.0, 1.0]) * rng.uniform(*a_y) / v
        wd = rng.uniform(-0.5, 0.5) if yaw_accel else 0.0
        ald = rng.uniform(-slip_rate, slip_rate)
        S = 1000.0 * v * (w + ald)
        F_f, F_r = ((L - a) * S + inertia * wd) / L, (a * S - inertia * wd) / L
        if mu > 0.0:
            s_f = _pacejka_slip(F_f, C_f, mu * 1000.0 * 10.0 * (L - a) / L)
            s_r = _pacejka_slip(F_r, C_r, mu * 1000.0 * 10.0 * a / L)
        else:
            s_f, s_r = F_f / C_f, F_r / C_r
        alpha = (L - a) * w / v - s_r
        out.append((alpha, v * w, v, wd * 0.5, w / v, alpha + a * w / v + s_f, ald))
    return out


def _feed(b: _Blocks, p, f, chords):
    for alpha, vw, v, d_omega, w_v, delta, ald in chords:
        f = b._lateral_fit(p, f, alpha, vw, v, 0.0, d_omega, w_v, delta, 1e-3, 0.5, 50, ald)
    return f


def test_the_joint_lateral_fit_recovers_the_car_from_its_chords(b: _Blocks) -> None:
    """The joint fit (fu._lateral_fit, an extended Kalman filter over x = (a / L, I_z / I_z,0,
    C_f,0 / C_f, C_r,0 / C_r, δ_r)) on 200 noiseless chords of a car far from the model (CoG 10 %
    of L backward, I_z −20 %, C_f −20 %, C_r +30 %) finds it: the data (σ 1 mrad a chord) outweigh
    the prior, whose pull is the error left (below 1 %), and its standard deviations shrink far
    below the prior's (a / L 0.05, I_z 0.3)."""
    p = _params(b)
    car = (1.25, 1200.0, 40000.0, 65000.0)
    f0 = fu.lateral_start(p)
    assert f0.x == (0.4, 1.0, 1.0, 1.0, 0.0) and not f0.fitted and not f0.given
    f = _feed(b, p, f0, _lateral_chords(np.random.default_rng(3), 200, car))
    assert math.sqrt(f.P[0]) < 0.005 and math.sqrt(f.P[5]) < 0.03  # a tenth of the prior's
    cf, cr, inertia, a, b_ = b.lateral_model(p, f)
    assert (a, inertia, cf, cr) == pytest.approx(car, rel=0.01)
    assert a + b_ == pytest.approx(2.5, rel=1e-15) and abs(f.x[4]) < 1e-4
    # the covariance stays a covariance: symmetric by construction, positive on its diagonal
    assert all(f.P[i] > 0.0 for i in (0, 5, 9, 12, 14))
    assert f.fitted


def test_the_joint_lateral_fit_takes_the_slip_rate_into_the_lateral_force(b: _Blocks) -> None:
    """Chords through transients (α̇ up to ±0.01 rad/s, S = M v (ω + α̇)) with their α̂ rate:
    the car is found as from steady chords (within 1 %); without the term in S its M v α̇ (up to
    5 % of the force) would be unexplained slip."""
    p = _params(b)
    car = (1.25, 1200.0, 40000.0, 65000.0)
    f = _feed(b, p, fu.lateral_start(p), _lateral_chords(np.random.default_rng(5), 400, car, slip_rate=0.01))
    cf, cr, inertia, a, _ = b.lateral_model(p, f)
    assert (a, inertia, cf, cr) == pytest.approx(car, rel=0.01)


def test_the_joint_lateral_fit_discounts_the_tyres_nonlinearity(b: _Blocks) -> None:
    """Magic-formula tyres (μ 0.9, the plant's shape) at 1–4 m/s²: a fit linear in the slip reads
    the high-load chords' extra slip as compliance. With the chords at every load weighted alike
    (``LATERAL_NONLINEAR`` = 0, checked once) C_f came out 3.7 % below the small-slip stiffness;
    with the nonlinearity as the chord's noise 1.8 % (the low-load chords' own secant share)."""
    p = _params(b)
    car = (1.0, 1500.0, 50000.0, 50000.0)
    chords = _lateral_chords(np.random.default_rng(6), 400, car, mu=0.9, a_y=(1.0, 4.0))
    cf, cr, _, a, _ = b.lateral_model(p, _feed(b, p, fu.lateral_start(p), chords))
    assert a == pytest.approx(1.0, rel=0.01)
    assert (cf, cr) == pytest.approx((50000.0, 50000.0), rel=0.025)


def test_the_joint_lateral_fit_skips_an_axle_outside_the_compliance_band(b: _Blocks) -> None:
    """A chord whose rear slip is three times what the model's stiffness gives its force (a
    saturated tyre, beyond STIFF_RANGE's 2× and the noise) updates the front equation only: the
    rear compliance's estimate and variance stay at the prior; the same chord with a plausible rear
    slip moves them."""
    p = _params(b)
    f0 = fu.lateral_start(p)
    v, w = 12.0, 2.0 / 12.0
    S = 1000.0 * v * w
    F_f, F_r = 1.5 * S / 2.5, 1.0 * S / 2.5
    for scale, moved in ((3.0, False), (1.2, True)):
        alpha = 1.5 * w / v - scale * F_r / 50000.0
        delta = alpha + 1.0 * w / v + F_f / 50000.0
        f = b._lateral_fit(p, f0, alpha, v * w, v, 0.0, 0.0, w / v, delta, 1e-3, 0.5, 50, 0.0)
        assert bool(f.x[3] != 1.0 and f.P[12] < f0.P[12]) is moved
        assert f.P[9] < f0.P[9]  # the front equation counted either way


def test_the_joint_lateral_fit_holds_what_its_chords_do_not_inform(b: _Blocks) -> None:
    """Steady corners (ω̇ = 0) carry no information on I_z: its estimate and variance stay exactly at
    the prior (no drift), however many chords; the compliances and the CoG are still learnt."""
    p = _params(b)
    car = (1.25, 1200.0, 40000.0, 65000.0)
    f = _feed(b, p, fu.lateral_start(p), _lateral_chords(np.random.default_rng(4), 200, car, yaw_accel=False))
    assert f.x[1] == 1.0 and f.P[5] == fu.LATERAL_PRIOR[1] ** 2
    assert (f.P[1], f.P[6], f.P[7], f.P[8]) == (0.0, 0.0, 0.0, 0.0)  # I_z's row of P untouched
    assert f.x[0] * 2.5 == pytest.approx(1.25, rel=0.01)
    assert (50000.0 / f.x[2], 50000.0 / f.x[3]) == pytest.approx((40000.0, 65000.0), rel=0.01)


def test_slip_correction_by_hand(b: _Blocks) -> None:
    f = SlipFit(0.002, -0.001, 0.0, 0.0, 0.0, 0.0, 10.0, 10.0)
    assert b.slip_correction(f, 3.0) == pytest.approx(0.005)
    assert b.slip_correction(f, math.nan) == -0.001  # no a_y: β alone
    assert b.slip_correction(f, 1000.0) == fu.SLIP_CORRECTION_MAX
    assert b.slip_correction(f, -1000.0) == -fu.SLIP_CORRECTION_MAX
    assert b.noise_scale(SlipFit(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 8.0)) == 1.0  # σ is a floor


# ------------------------------------------------------------------------------------ mass estimator
def test_the_mass_fit_high_passes_force_and_acceleration(b: _Blocks) -> None:
    """Window N = 2 at T_d = 0.1 s: ā = (v_k − v_(k−2)) / 0.2 = 1.0, 1.5, 2.5 m/s² over the speeds
    below, F̂ = 1000 + 100 ā (a mass error of 100 kg on a constant resistance). The fit opens on
    the first full window (filters started there: x = y = 0), then x = ā − low-pass(ā), y likewise,
    with gain T_d / MASS_HIGHPASS_S; Σ x² forgets by 1 − T_d / MASS_MEMORY_S."""
    p = MassParams(683.0, 0.1, 2, 2.0, True)
    ring = np.zeros(3)
    s = MassState(0, 0, 0.0, 0.0, 0.0, False, 0.0, 0.0)
    accels = []
    for v, F in ((4.0, 1000.0), (4.1, 1000.0), (4.2, 1100.0), (4.4, 1150.0), (4.7, 1250.0)):
        s = b.mass_update(p, s, ring, v, F)
        accels.append(s.accel)
    assert accels[2:] == pytest.approx([1.0, 1.5, 2.5], rel=1e-12)
    g, lam = 0.1 / MASS_HIGHPASS_S, 1.0 - 0.1 / MASS_MEMORY_S
    la1 = 1.0 + g * (1.5 - 1.0)
    la2 = la1 + g * (2.5 - la1)
    x1, x2 = 1.5 - la1, 2.5 - la2
    assert s.open and s.la == pytest.approx(la2, rel=1e-12)
    assert s.sxx == pytest.approx(lam * x1 * x1 + x2 * x2, rel=1e-12)
    assert s.sxy / s.sxx == pytest.approx(100.0, rel=1e-9)  # ΔM, the constant resistance gone
    assert b.delta_mass(p, s) == 0.0  # not excited yet (Σ x² < MASS_EXCITATION)
    # a NaN sample changes nothing but closes the fit (its filters restart)
    s2 = b.mass_update(p, s, ring, math.nan, 1000.0)
    assert not s2.open and s2[:5] == s[:5] and s2[6:] == s[6:]


def test_the_mass_fit_waits_for_a_full_window_above_the_speed_floor(b: _Blocks) -> None:
    """One sample at or below MASS_MIN_SPEED anywhere in the window keeps the fit closed until
    N + 1 samples above it have come."""
    p = MassParams(683.0, 0.1, 2, 2.0, True)
    ring, s = np.zeros(3), MassState(0, 0, 0.0, 0.0, 0.0, False, 0.0, 0.0)
    opened = []
    for v in (4.0, 4.1, 4.2, 3.0, 4.4, 4.5, 4.6, 4.7):
        s = b.mass_update(p, s, ring, v, 1000.0)
        opened.append(s.open)
    assert opened == [False, False, True, False, False, False, True, True]


def test_the_mass_terms_by_hand(b: _Blocks) -> None:
    """ΔM̂ = Σxy / Σx² (50 kg) within MASS_RANGE × M; the force added to F̂ is −ΔM̂ ā plus, with the
    speed feedback, ΔM̂ (v_ref − v̂)/τ."""
    p = MassParams(683.0, 0.01, 30, 2.0, True)
    s = MassState(40, 40, 0.5, 0.0, 0.0, True, 5000.0, 100.0)
    assert b.delta_mass(p, s) == pytest.approx(50.0)
    assert b.inertia_force(p, s, 10.0, 12.0) == pytest.approx(-25.0 + 50.0)
    assert b.inertia_force(MassParams(683.0, 0.01, 30, 2.0, False), s, 10.0, 12.0) == pytest.approx(-25.0)
    assert b.inertia_force(p, s, 10.0, math.nan) == 0.0
    assert b.delta_mass(p, MassState(40, 40, 0.5, 0.0, 0.0, True, 1e6, 100.0)) == pytest.approx(0.6 * 683.0)
    assert b.delta_mass(p, MassState(40, 40, 0.5, 0.0, 0.0, True, -1e6, 100.0)) == pytest.approx(-0.4 * 683.0)
    assert b.delta_mass(p, MassState(40, 40, 0.5, 0.0, 0.0, True, 5000.0, 49.9)) == 0.0


# ------------------------------------------------------------------------------------ both ways alike
def test_compiled_blocks_equal_python_to_the_bit_on_a_random_drive() -> None:
    """A noisy drive with dropouts and missing poses through the blocks as Python and compiled:
    the same records after every call (the engine's bit-identity with the Python loop rests on it)."""
    if kernels.load("mpc") is None:
        pytest.skip("compiled kernels unavailable")
    py, nb = Blocks(fu, BLOCKS, False), Blocks(fu, BLOCKS, True)
    rng = np.random.default_rng(34)
    p = _params(py, sigma=0.005, C=(60000.0, 70000.0))
    states = [fu.course_start(p)] * 2
    curs = [NO_INTERVAL] * 2
    mp = MassParams(683.0, 0.01, 30, 2.0, True)
    ms = [fu.MASS_START] * 2
    rings = [np.zeros(31), np.zeros(31)]
    gs = [REPEAT_START] * 2
    applied = [(False, 0.0, 0.0, 0.0, 0.0)] * 2
    X = Y = th = 0.0
    v = 6.0
    for k in range(3000):
        w = 0.3 * math.sin(0.004 * k) + rng.normal(0, 0.02)
        v = max(2.5, v + rng.normal(0, 0.03))
        alpha = 0.03 * w + rng.normal(0, 5e-4)
        sample = (X + rng.normal(0, 0.005), Y, th, v, w, -math.inf)
        if rng.random() < 0.003:
            sample = tuple(math.nan if i == 1 else c for i, c in enumerate(sample))
        for i, blk in enumerate((py, nb)):
            _, gs[i] = blk.repeat_check(gs[i], *sample)
            # every call: a pose ends an interval at MPC steps (and, at the low rate of the second
            # half, a T_c after the last end); the heading is integrated between poses
            low = k >= 1500
            has_pose = k % 470 != 0 and (not low or k % 37 == 0)
            states[i], curs[i] = blk.course_close(p, states[i], curs[i], k % 10 == 0, has_pose,
                                                  sample[0], sample[1], th, v, w, v * w)
            if k % 10 == 0:
                give, cf, cr, ii, aa, _bb, states[i] = blk.stiffness_update(p, states[i], *applied[i])
                if give:
                    applied[i] = (True, cf, cr, ii, aa)
            curs[i] = blk.course_sample(p, curs[i], k % 397 != 0, has_pose, th, v, alpha, v * w, w, 0.05 * w,
                                        300.0)
            ms[i] = blk.mass_update(mp, ms[i], rings[i], v if k % 53 else math.nan, 800.0 + 90.0 * v)
        assert _records(states[0]) == _records(states[1]), k
        assert _records(curs[0]) == _records(curs[1]) and _records(gs[0]) == _records(gs[1]), k
        assert _records(ms[0]) == _records(ms[1]) and np.array_equal(rings[0], rings[1]), k
        assert applied[0] == applied[1]
        assert py.inertia_force(mp, ms[0], v, v + 1.0) == nb.inertia_force(mp, ms[1], v, v + 1.0)
        assert py.slip_correction(states[0].slip, v * w) == nb.slip_correction(states[1].slip, v * w)
        th += w * 0.01
        X += v * math.cos(th + alpha) * 0.01
        Y += v * math.sin(th + alpha) * 0.01
    assert states[0].n_chords > 150 and applied[0][0] and ms[0].sxx > 0.0


def test_the_band_of_plausible_stiffnesses_allows_for_the_slips_noise() -> None:
    """A chord counts when its slip is one a stiffness within STIFF_RANGE × the model's gives its
    force, up to STIFF_BAND_SIGMAS of the slip's noise (a hard cut at the band's edges would censor
    the noisy response and bias the fit into the band): 1000 N on a 50000 N/rad model, band
    slips 0.01–0.04 rad, σ = 2 mrad: 0.009 and 0.041 count, 0.0075 and 0.043 do not; a slip of the
    other sign (a transient, noise at a tiny slip beyond its σ) does not; a negative force mirrors."""
    assert fu.STIFF_RANGE == (0.5, 2.0) and fu.STIFF_BAND_SIGMAS == 1.0
    for slip, counts in ((0.009, True), (0.041, True), (0.02, True), (0.0075, False), (0.043, False),
                         (-0.02, False)):
        assert fu._axle_pair(50000.0, 1000.0, slip, 0.002) == ((1000.0, slip) if counts else (0.0, 0.0))
        assert fu._axle_pair(50000.0, -1000.0, -slip, 0.002) == ((-1000.0, -slip) if counts else (0.0, 0.0))
