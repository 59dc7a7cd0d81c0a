"""Comfort and effort metrics (issue 26, tsmpc.sim.comfort) against signals whose values are known
in closed form.

Tolerances: the metrics low-pass at 5 Hz before differentiating (gain 1/(1 + (f/5)⁴) > 0.99999 at
0.25–0.5 Hz) and use central differences at T_d = 0.01 s (relative error (ΩT_d)²/6 < 2e-4 at
0.5 Hz); the zero-phase filter's start-up at the two ends of a record distorts a few samples by up
to ~0.3 % of the amplitude (its derivative by ~9 %), so the signals below are chosen with their
derivative's zero at the ends and the maxima are checked to 0.5 %, the RMS (6000 samples, the ends
average out) to 0.1 %.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.config import Config, Method
from tsmpc.sim.comfort import (
    CUTOFF_HZ,
    SETTLING_BAND_M,
    body_accelerations,
    comfort_metrics,
    lowpass,
    rate,
    run_comfort,
    settling_time,
)

DT, T = 0.01, 60.0
t = np.arange(0.0, T, DT)
OM = 2 * math.pi * 0.5  # 0.5 Hz: 30 whole periods in 60 s


def _state(v: np.ndarray, theta: np.ndarray, alpha: np.ndarray, omega: np.ndarray) -> np.ndarray:
    st = np.zeros((t.size, 6))
    st[:, 2], st[:, 3], st[:, 4], st[:, 5] = theta, v, alpha, omega
    return st


def _metrics(state: np.ndarray, command: np.ndarray | None = None):
    cmd = np.zeros((t.size, 2)) if command is None else command
    return comfort_metrics(state, cmd, DT, t[::10], np.zeros(t[::10].size))


def test_sinusoidal_lateral_motion() -> None:
    """Slalom at constant speed: heading θ = θ0 sin Ωt, yaw rate ω = θ0 Ω cos Ωt, no slip:
    a_y = V ω = V θ0 Ω cos Ωt (max A, RMS A/√2) and lateral jerk −A Ω sin Ωt (max AΩ, RMS AΩ/√2)."""
    V, th0 = 12.0, 0.05
    c = _metrics(_state(np.full(t.size, V), th0 * np.sin(OM * t), np.zeros(t.size),
                        th0 * OM * np.cos(OM * t)))
    A = V * th0 * OM
    assert c.lat_accel_max == pytest.approx(A, rel=5e-3)
    assert c.lat_accel_rms == pytest.approx(A / math.sqrt(2), rel=1e-3)
    assert c.lat_jerk_max == pytest.approx(A * OM, rel=5e-3)
    assert c.lat_jerk_rms == pytest.approx(A * OM / math.sqrt(2), rel=1e-3)
    assert c.lon_jerk_max < 1e-9  # constant speed, no slip: no longitudinal acceleration


def test_slip_rate_enters_the_lateral_acceleration() -> None:
    """Body slip oscillating at constant speed and heading: a_y = V cos α α̇, max V α0 Ω (where
    α = 0); the RMS is the closed-form signal's (evaluated on the grid)."""
    V, a0 = 10.0, 0.02
    alpha = a0 * np.sin(OM * t)
    c = _metrics(_state(np.full(t.size, V), np.zeros(t.size), alpha, np.zeros(t.size)))
    exact = V * np.cos(alpha) * a0 * OM * np.cos(OM * t)
    assert c.lat_accel_max == pytest.approx(V * a0 * OM, rel=5e-3)
    assert c.lat_accel_rms == pytest.approx(float(np.sqrt(np.mean(exact**2))), rel=1e-3)


def test_longitudinal_jerk_of_a_sinusoidal_speed() -> None:
    """v = V0 + A sin Ωt (no slip, no yaw): a_x = AΩ cos Ωt, jerk −AΩ² sin Ωt."""
    A = 1.5
    c = _metrics(_state(8.0 + A * np.sin(OM * t), np.zeros(t.size), np.zeros(t.size), np.zeros(t.size)))
    assert c.lon_jerk_max == pytest.approx(A * OM**2, rel=5e-3)
    assert c.lon_jerk_rms == pytest.approx(A * OM**2 / math.sqrt(2), rel=1e-3)
    assert c.lat_accel_max < 1e-12


def test_steering_and_force_rates() -> None:
    """δ = δ0 cos Ωt and F = F0 + F1 cos Ωt: rates δ0Ω, F1Ω (max), over √2 (RMS)."""
    d0, F1 = 0.1, 800.0
    cmd = np.stack([2000.0 + F1 * np.cos(OM * t), d0 * np.cos(OM * t)], axis=1)
    st = _state(np.full(t.size, 5.0), np.zeros(t.size), np.zeros(t.size), np.zeros(t.size))
    c = _metrics(st, cmd)
    assert c.steering_rate_max == pytest.approx(d0 * OM, rel=5e-3)
    assert c.steering_rate_rms == pytest.approx(d0 * OM / math.sqrt(2), rel=1e-3)
    assert c.force_rate_max == pytest.approx(F1 * OM, rel=5e-3)
    assert c.force_rate_rms == pytest.approx(F1 * OM / math.sqrt(2), rel=1e-3)


def test_the_filter_removes_inner_loop_chatter_but_keeps_the_ride() -> None:
    """A 0.25 Hz signal passes (gain > 0.9999); a 25 Hz chatter of the same amplitude is attenuated
    by 1/(1 + 5⁴) ≈ 1.6e-3 — and its rate (50× the slow one's) with it."""
    slow, fast = np.sin(0.5 * math.pi * t), np.sin(50 * math.pi * t)
    f = lowpass(slow + fast, DT)
    inner = slice(200, -200)
    assert np.max(np.abs(f - slow)[inner]) < 3e-3
    r = rate(slow + fast, DT)
    assert np.max(np.abs(r - 0.5 * math.pi * np.cos(0.5 * math.pi * t))[inner]) < 0.3
    assert CUTOFF_HZ == 5.0


def test_body_accelerations_of_a_steady_circle() -> None:
    """Steady circle with constant slip: a_y = v ω = v²/R, a_x = −v sin α ω (the centripetal
    acceleration's body-x part)."""
    v, R, al = 10.0, 50.0, 0.03
    st = _state(np.full(t.size, v), v / R * t, np.full(t.size, al), np.full(t.size, v / R))
    ax, ay = body_accelerations(st, DT)
    np.testing.assert_allclose(ay, v * v / R * math.cos(al), rtol=1e-12)
    np.testing.assert_allclose(ax, -v * math.sin(al) * v / R, rtol=1e-12)


def test_settling_time_definition() -> None:
    """|e_y| = 2 e^(−t/τ): inside 0.10 m from t = τ ln 20 on; the first grid time at or after it."""
    tt = np.arange(0.0, 30.0, 0.1)
    tau = 1.5
    ts = settling_time(tt, 2.0 * np.exp(-tt / tau))
    exact = tau * math.log(2.0 / SETTLING_BAND_M)
    assert exact <= ts < exact + 0.1 + 1e-9
    assert settling_time(tt, np.full(tt.size, 0.05)) == 0.0  # never outside
    assert settling_time(tt, np.where(tt > 29.0, 0.2, 0.0)) == math.inf  # outside at the end
    late = np.where((tt > 10.0) & (tt < 12.0), 0.3, 0.0)  # a late excursion defines it
    assert settling_time(tt, late) == pytest.approx(12.0, abs=0.1 + 1e-9)
    assert settling_time(tt, np.where(tt > 5, np.nan, 0.0)) == math.inf  # NaN is not settled
    assert math.isnan(settling_time(tt[:0], tt[:0]))  # no samples: undefined


def test_every_run_reports_comfort(cfg: Config) -> None:
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.metrics import compute_metrics
    from tsmpc.sim.simulator import simulate

    log = simulate(cfg, Method.REF, load_scenario(cfg), max_steps=60)
    m = compute_metrics(log)
    c = run_comfort(log)
    assert m["comfort"] == c.as_dict()
    direct = comfort_metrics(log.state, log.command, log.Td, log.t_outer, log.errors[:, 1])
    assert direct == c
    for k, v in c.as_dict().items():
        assert math.isfinite(v) and v >= 0.0, k


def test_every_rate_metric_is_taken_after_the_low_pass() -> None:
    """25 Hz chatter (the inner loop's band) on the speed, yaw rate, steering and force: unfiltered,
    the speed's chatter alone would make a longitudinal jerk several times the ride's; after the
    5 Hz low-pass (gain 1.6e-3 at 25 Hz) every metric stays within 1 % of the smooth signal's."""
    chat = np.cos(50 * math.pi * t)
    A, V, th0, d0, F1 = 1.5, 12.0, 0.05, 0.1, 800.0
    smooth = _state(V + A * np.sin(OM * t), th0 * np.sin(OM * t), np.zeros(t.size), th0 * OM * np.cos(OM * t))
    noisy = smooth.copy()
    noisy[:, 3] += 1e-2 * chat
    noisy[:, 5] += 2e-3 * chat
    cmd = np.stack([2000.0 + F1 * np.cos(OM * t), d0 * np.cos(OM * t)], axis=1)
    cmd_noisy = cmd + np.stack([5.0 * chat, 1e-3 * chat], axis=1)
    a, b = _metrics(smooth, cmd).as_dict(), _metrics(noisy, cmd_noisy).as_dict()
    for k in ("lat_accel_rms", "lat_jerk_rms", "lon_jerk_rms", "steering_rate_rms", "force_rate_rms"):
        assert b[k] == pytest.approx(a[k], rel=1e-2), k
    raw = np.gradient(noisy[:, 3], DT)  # what an unfiltered difference would report as a_x
    assert np.sqrt(np.mean(np.gradient(raw, DT) ** 2)) > 5 * a["lon_jerk_rms"]
