"""The sensor blocks (tsmpc.sensors, one definition for the Python loop and the engine) and the
sensor class of ``[scenario.sensors]`` (issue 35): each field changes what the controller sees as
it should, in both loops; bad values end the CLI with one line and exit 2."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.conditions import apply_conditions
from tsmpc.config import Config, SensorFaults, replace
from tsmpc.sensors import (
    FAULT_HOLD_BURST,
    FAULT_NAN_BURST,
    BurstParams,
    BurstState,
    SensorBlockParams,
    SensorDraws,
    SensorModel,
    SensorParams,
    SensorState,
    burst_sample,
    fault_time,
    sensor_sample,
    sensor_step,
)
from tsmpc.sim import engine as eng
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.simulator import simulate
from tsmpc.vehicle.actuators import ActuatedPlant
from tsmpc.vehicle.plant import VehiclePlant

TD = 0.01


def _model(**faults) -> SensorModel:
    return SensorModel(SensorFaults(**faults), TD, 0.001, seed=3)


def _feed(model: SensorModel, y, n: int) -> np.ndarray:
    """``n`` calls at t = m T_d with the constant sample ``y``."""
    return np.array([model(m * TD, np.array(y, dtype=float)) for m in range(n)])


def test_bias_drift_scale_by_hand() -> None:
    y = (10.0, -4.0, 0.5, 8.0, 0.2)
    out = _feed(_model(x_bias=0.3, y_bias=-0.2, theta_bias=0.01, theta_drift=0.002, v_bias=-0.3,
                       v_drift=0.01, omega_bias=0.02, omega_drift=-0.001, position_scale=1.01,
                       v_scale=0.97, omega_scale=1.1), y, 201)
    t = np.arange(201) * TD
    np.testing.assert_allclose(out[:, 0], 1.01 * 10.0 + 0.3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 1], 1.01 * -4.0 - 0.2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 2], 0.5 + 0.01 + 0.002 * t, rtol=0, atol=1e-12)  # no scale
    np.testing.assert_allclose(out[:, 3], 0.97 * 8.0 - 0.3 + 0.01 * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 4], 1.1 * 0.2 + 0.02 - 0.001 * t, rtol=0, atol=1e-12)


def test_extra_gnss_noise_by_hand() -> None:
    """gnss_noise_scale 3: X and Y get σ_pos √(3² − 1) more noise, from the model's own stream."""
    out = _feed(_model(gnss_noise_scale=3.0), (10.0, -4.0, 0.5, 8.0, 0.2), 100)
    g = np.random.default_rng([3, 21, 2]).standard_normal((100, 2))
    np.testing.assert_allclose(out[:, 0], 10.0 + 0.001 * math.sqrt(8.0) * g[:, 0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[:, 1], -4.0 + 0.001 * math.sqrt(8.0) * g[:, 1], rtol=0, atol=1e-15)
    assert np.all(out[:, 2:] == (0.5, 8.0, 0.2))


def test_delay_and_dropouts_by_hand() -> None:
    ramp = [np.array([m, m, m, m, m], dtype=float) for m in range(300)]
    model = _model(delay_s=0.05)
    out = np.array([model(m * TD, y) for m, y in enumerate(ramp)])
    np.testing.assert_array_equal(out[5:, 3], np.arange(295))  # 5 samples late
    np.testing.assert_array_equal(out[:5, 3], 0.0)  # the oldest until the FIFO is full
    for hold in (False, True):
        model = _model(dropout_probability=0.3, dropout_hold=hold)
        out = np.array([model(m * TD, y) for m, y in enumerate(ramp)])
        u = np.random.default_rng([3, 21, 1]).random(300)  # the model's own stream
        lost = u < 0.3
        assert 60 < lost.sum() < 120
        if hold:  # a lost sample repeats the one delivered before it
            assert np.all(np.isfinite(out[1:])) and np.all(out[1:][lost[1:], 3] == out[:-1][lost[1:], 3])
        else:
            np.testing.assert_array_equal(np.isnan(out[:, 3]), lost)
        np.testing.assert_array_equal(out[~lost, 3], np.arange(300)[~lost])


def test_random_walk_grows_as_sqrt_t() -> None:
    """omega_walk σ: the offset after t seconds has σ·sqrt(t) spread (200 seeds, 4 s); it starts at
    0 at the first sample."""
    ends = []
    for seed in range(200):
        m = SensorModel(SensorFaults(omega_walk=0.002), TD, 0.0, seed)
        out = np.array([m(k * TD, np.zeros(5)) for k in range(401)])
        assert out[0, 4] == 0.0 and np.all(out[:, :4] == 0.0)
        ends.append(out[-1, 4])
    sd = float(np.std(ends))
    assert 0.8 * 0.002 * 2.0 < sd < 1.2 * 0.002 * 2.0, sd  # σ √4 s; 200 draws: ±10 % (2σ)


def test_sample_rates_and_heading() -> None:
    """A 2 Hz pose delivers 2 poses per second (the others missing, NaN), the speed and yaw rate at
    their own rates; a pose without heading never has θ."""
    out = _feed(_model(pose_rate_hz=2.0, v_rate_hz=25.0), (1.0, 2.0, 0.3, 5.0, 0.1), 1000)  # 10 s
    poses = np.isfinite(out[:, 0])
    assert poses.sum() == 20 and np.array_equal(np.flatnonzero(poses), np.arange(0, 1000, 50))
    assert np.array_equal(np.isfinite(out[:, 1]), poses) and np.array_equal(np.isfinite(out[:, 2]), poses)
    assert np.isfinite(out[:, 3]).sum() == 250 and np.isfinite(out[:, 4]).all()
    out = _feed(_model(omega_rate_hz=3.0), (1.0, 2.0, 0.3, 5.0, 0.1), 1000)  # 1/3 s is no whole T_d
    assert np.array_equal(np.flatnonzero(np.isfinite(out[:, 4])), [0, 34, 67, 100, 134, 167, 200, 234, 267,
                                                                   300, 334, 367, 400, 434, 467, 500, 534,
                                                                   567, 600, 634, 667, 700, 734, 767, 800,
                                                                   834, 867, 900, 934, 967])
    assert np.isfinite(out[:, :4]).all()
    out = _feed(_model(pose_heading=False), (1.0, 2.0, 0.3, 5.0, 0.1), 50)
    assert np.isnan(out[:, 2]).all() and np.isfinite(out[:, [0, 1, 3, 4]]).all()


def test_burst_block_by_hand() -> None:
    p = BurstParams(FAULT_HOLD_BURST, 5.0, 0.2, 2.0)
    s = BurstState()
    y1, s = burst_sample(p, s, 1.99, (1.0, 2.0, 3.0, 4.0, 5.0))
    y2, s = burst_sample(p, s, 2.05, (9.0, 9.0, 9.0, 9.0, 9.0))
    assert y1 == (1.0, 2.0, 3.0, 4.0, 5.0) and y2 == y1  # held through the burst
    y3, s = burst_sample(p, s, 2.21, (7.0, 7.0, 7.0, 7.0, 7.0))
    assert y3 == (7.0,) * 5
    first, _ = burst_sample(BurstParams(FAULT_HOLD_BURST, 5.0, 0.2, 0.0), BurstState(), 0.0, y3)
    assert first == y3  # a burst from the first sample on: nothing to hold yet, the sample passes
    nan = BurstParams(FAULT_NAN_BURST, 7.0, 0.05, 3.0)
    assert all(math.isnan(v) for v in burst_sample(nan, s, 3.01, y3)[0])
    assert burst_sample(nan, s, 3.06, y3)[0] == y3 and burst_sample(BurstParams(), s, 2.05, y3) == (y3, s)


def test_the_sensor_step_by_hand(way) -> None:
    """The simulator's sensor step (one definition for both loops): known plant state, noise and
    faults give a known sample — the true [X, Y, θ, v, ω] (ω the state's yaw rate) plus the noise
    row; faults at the fault's time (an outer step's sample at k·T_c); the burst before the sensor
    model (a held sample gets the model's drift at the time it is delivered); the model's delay
    and dropouts on their own stream."""
    step, ft = way(sensor_step), way(fault_time)
    n_in, Tc, Td = 10, 0.1, 0.01
    assert ft(30, n_in, Tc, Td) == 3 * Tc != 30 * Td and ft(31, n_in, Tc, Td) == 31 * Td
    x = np.array([3.0, 4.0, 0.5, 12.0, 0.02, 0.1])
    noise = np.outer(np.arange(40.0), [1e-3, -2e-3, 1e-4, 5e-3, -1e-5])
    d = SensorDraws(noise, np.ones(1), np.zeros((1, 7)))

    def true(m: int) -> tuple[float, ...]:
        n = noise[m]
        return (x[0] + n[0], x[1] + n[1], x[2] + n[2], x[3] + n[3], x[5] + n[4])

    def run(p: SensorBlockParams, d: SensorDraws, upto: int, delay_n: int = 0) -> list[tuple[float, ...]]:
        bs, ms, out = BurstState(), SensorState(np.zeros((delay_n + 1, 5))), []
        for m in range(upto):
            s, bs, ms = step(p, d, bs, ms, m, n_in, Tc, Td, x)
            out.append(tuple(s))
        return out

    assert run(SensorBlockParams(), d, 8) == [true(m) for m in range(8)]  # no fault
    # NaN for 0.05 s each second from 0.2 s: samples 20 … 24 lost
    out = run(SensorBlockParams(BurstParams(FAULT_NAN_BURST, 1.0, 0.05, 0.2)), d, 26)
    assert [m for m in range(26) if all(math.isnan(v) for v in out[m])] == [20, 21, 22, 23, 24]
    assert out[19] == true(19) and out[25] == true(25)
    # held from 0.2 s (sample 19 kept), then the model's speed drift at the time of delivery
    p = SensorBlockParams(BurstParams(FAULT_HOLD_BURST, 1.0, 0.05, 0.2), True,
                          SensorParams(drift=(0.0, 0.0, 0.0, 0.5, 0.0)))
    out = run(p, SensorDraws(noise, np.ones(40), np.zeros((40, 7))), 26)
    assert out[21] == (*true(19)[:3], true(19)[3] + (0.0 + 0.5 * (21 * Td) + 0.0), true(19)[4])
    assert out[25][3] == true(25)[3] + (0.0 + 0.5 * (25 * Td) + 0.0)
    # two samples late (sample 0 while the FIFO fills), samples 6 and 9 dropped (their U(0, 1) < 0.3)
    u = np.full(12, 0.9)
    u[[6, 9]] = 0.1
    out = run(SensorBlockParams(has_model=True, model=SensorParams(p_drop=0.3, delay_n=2)),
              SensorDraws(noise, u, np.zeros((12, 7))), 12, delay_n=2)
    lost = [m for m in range(12) if all(math.isnan(v) for v in out[m])]
    assert lost == [6, 9]
    assert out[:3] == [true(0)] * 3 and [out[m] for m in (3, 4, 5, 7, 8, 10, 11)] == [
        true(m - 2) for m in (3, 4, 5, 7, 8, 10, 11)]


def test_blocks_compiled_equal_python() -> None:
    if kernels.load("mpc") is None:
        pytest.skip("compiled kernels unavailable")
    from numba import njit

    nb = njit(cache=False)(sensor_sample)
    p = SensorParams(scale=(1.01, 0.99, 1.0, 1.03, 0.95), bias=(0.1, -0.2, 0.01, 0.3, -0.02),
                     drift=(0.0, 0.0, 1e-3, -2e-3, 1e-4), walk=(1e-3, 1e-3, 1e-4, 1e-3, 1e-4),
                     extra_sigma=0.02, p_drop=0.1, hold=True, delay_n=3, heading=True, rate_pose=0.07,
                     rate_v=0.5, rate_omega=1.0)
    rng = np.random.default_rng(11)
    a = SensorState(np.zeros((4, 5)))
    b = SensorState(np.zeros((4, 5)))
    for m in range(500):
        y = tuple(float(v) for v in rng.normal(0, 10, 5))
        w = tuple(float(v) for v in rng.normal(0, 1, 5))
        u, gx, gy = float(rng.random()), float(rng.normal()), float(rng.normal())
        oa, a = sensor_sample(p, a, m * TD, y, u, gx, gy, w)
        ob, b = nb(p, b, m * TD, y, u, gx, gy, w)
        assert np.array_equal(np.array(oa), np.array(ob), equal_nan=True)
        assert (a.head, a.n, a.calls, a.walk) == (b.head, b.n, b.calls, b.walk)
        b = SensorState(*b)


def _run_cfg(sensors: dict, **plant) -> tuple[Config, object]:
    cfg = Config()
    cfg = replace(cfg, noise=replace(cfg.noise, scale=0.0), scenario=replace(
        cfg.scenario, sensors=replace(cfg.scenario.sensors, **sensors),
        plant=replace(cfg.scenario.plant, **plant)))
    case = apply_conditions(cfg, load_scenario(cfg))
    return case.config, case.scenario


@pytest.mark.parametrize("engine", [False, True])
def test_the_controller_sees_each_field(engine: bool) -> None:
    """What the cascade is given, in each loop (noise off): 1.1 x the yaw rate, the speed with its
    bias and drift, 5 samples late, lost where the dropout stream says; a 2 Hz pose is 2 poses per
    second (the cascade counts the others as missing poses)."""
    cfg, sc = _run_cfg({"omega_scale": 1.1, "v_bias": -0.3, "v_drift": 0.01, "delay_s": 0.05,
                        "pose_rate_hz": 2.0, "dropout_probability": 0.1})
    assert eng.applicability(cfg, "REF", sc) is None
    eng.LAST_RUN.clear()
    log = simulate(cfg, "REF", sc, engine=engine, max_steps=400)  # 40 s
    assert bool(eng.LAST_RUN) == engine
    x, meas, t = log.state, log.measurement, log.t_inner
    M = len(t)
    tf = np.where(np.arange(M) % 10 == 0, np.round(t / 0.1) * 0.1, t)  # the fault's time (k T_c)
    lost = np.random.default_rng([cfg.seed, 21, 1]).random(M) < 0.1  # the dropouts' own stream
    assert 300 < lost.sum() < 500
    np.testing.assert_array_equal(np.isnan(meas[:, 0]), lost)
    np.testing.assert_array_equal(np.isnan(meas[:, 1]), lost)
    ok = ~lost[5:]
    np.testing.assert_allclose(meas[5:, 1][ok], 1.1 * x[:-5, 5][ok], rtol=0, atol=1e-12)
    np.testing.assert_allclose(meas[5:, 0][ok], (x[:-5, 3] - 0.3 + 0.01 * tf[:-5])[ok], rtol=0, atol=1e-12)
    # 2 poses per second: 80 in 40 s, at m = 5 + 50 k (5 samples late), and sample 0 repeated while
    # the delay's FIFO fills (m = 0 ... 4); every other sample's pose is missing, as is every lost one
    m = np.arange(M)
    due = (m < 5) | ((m - 5) % 50 == 0)
    assert due.sum() == 80 + 5
    assert log.events["pose_nan"] == int(np.sum(lost | ~due))


def test_both_loops_agree_on_the_sensor_class() -> None:
    """Every new field at once (rates, walks, scales, biases, the steering offset): the engine runs
    it and equals the Python loop."""
    cfg, sc = _run_cfg({"omega_scale": 1.05, "v_scale": 0.98, "x_bias": 0.2, "y_bias": -0.1,
                        "position_scale": 1.001, "position_walk": 0.01, "theta_walk": 1e-3,
                        "v_walk": 0.01, "omega_walk": 1e-3, "pose_rate_hz": 5.0, "v_rate_hz": 50.0,
                        "gnss_noise_scale": 2.0, "dropout_probability": 0.02}, steering_offset_rad=0.01)
    cfg = replace(cfg, noise=replace(cfg.noise, scale=1.0))
    assert eng.applicability(cfg, "REF", sc) is None
    eng.LAST_RUN.clear()
    le = simulate(cfg, "REF", sc, engine=True, max_steps=300)
    assert eng.LAST_RUN
    lp = simulate(cfg, "REF", sc, engine=False, max_steps=300)
    assert le.events == lp.events
    for name, a in le.arrays().items():
        if a.dtype.kind == "f" and not name.endswith("time_s"):
            np.testing.assert_allclose(a, lp.arrays()[name], rtol=0, atol=1e-8, equal_nan=True, err_msg=name)


def test_a_slow_speed_sensor_makes_the_engine_step_aside() -> None:
    cfg, sc = _run_cfg({"v_rate_hz": 1.0})
    assert "v_rate_hz" in (eng.applicability(cfg, "REF", sc) or "")


def test_steering_offset_moves_the_steady_state_yaw_rate() -> None:
    """The plant steers commanded + offset: its steady-state yaw rate is the one of the larger
    command, and clearly not the one without offset (a constant command from 10 m/s; 6 kN about
    holds the speed against the plant's friction: 9.6 m/s after 3 s)."""
    cfg = Config()

    def omega_ss(cmd: float, offset: float) -> float:
        p = ActuatedPlant(VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h), None, None,
                          cfg.rates.plant_per_inner, steering_offset=offset)
        p.reset(np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]))
        for _ in range(300):  # 3 s: the yaw rate settles in well under 1 s
            x = p.step((6000.0, cmd), TD, 0.9)
        return float(x[5])

    w0, w1 = omega_ss(0.02, 0.0), omega_ss(0.02, 0.01)
    assert w1 == pytest.approx(omega_ss(0.03, 0.0), rel=1e-9)
    assert 1.3 < w1 / w0 < 1.6  # 0.03 / 0.02 rad, slightly understeering
    assert omega_ss(0.0, -0.01) < -0.04 and omega_ss(0.0, 0.0) == 0.0


@pytest.mark.parametrize(("setting", "field"), [
    ("scenario.sensors.pose_rate_hz=-1", "pose_rate_hz"),
    ("scenario.sensors.v_rate_hz=200", "v_rate_hz"),
    ("scenario.sensors.omega_scale=nan", "omega_scale"),
    ("scenario.sensors.gyro_bias=0.1", "gyro_bias"),
    ("scenario.plant.steering_offset_rad=0.2", "steering_offset_rad"),
])
def test_bad_values_exit_2_naming_the_field(setting: str, field: str, tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "tsmpc", "run", "--set", setting, "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = [ln for ln in r.stderr.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.stderr, r.stderr


def test_defaults_change_nothing() -> None:
    assert SensorFaults() == SensorFaults(x_bias=0.0, v_scale=1.0, pose_rate_hz=None, pose_heading=True)
    cfg = Config()
    assert apply_conditions(cfg, load_scenario(cfg)).scenario.sensor_fault is None
    assert math.isfinite(cfg.scenario.plant.steering_offset_rad)


def test_the_records_cross_into_the_engine_unchanged() -> None:
    """pack_params / unpack_params and pack_state / unpack_state / store_state (the engine's flat
    slots) give back the records."""
    from tsmpc.sensors import N_SS, pack_params, pack_state, store_state, unpack_params, unpack_state

    burst = BurstParams(FAULT_HOLD_BURST, 5.0, 0.2, 2.0)
    p = SensorParams(scale=(1.01, 0.99, 1.0, 1.03, 0.95), bias=(0.1, -0.2, 0.01, 0.3, -0.02),
                     drift=(0.0, 0.0, 1e-3, -2e-3, 1e-4), walk=(1e-3, 2e-3, 1e-4, 1e-3, 3e-4),
                     extra_sigma=0.02, p_drop=0.1, hold=True, delay_n=3, heading=False, rate_pose=0.07,
                     rate_v=0.5, rate_omega=0.25)
    assert unpack_params(pack_params(burst, p)) == (burst, True, p)
    assert unpack_params(pack_params(BurstParams(), None))[:2] == (BurstParams(), False)
    fifo = np.zeros((4, 5))
    bs = BurstState((1.0, 2.0, 3.0, 4.0, 5.0), True)
    ms = SensorState(fifo, 2, 3, (6.0, 7.0, 8.0, 9.0, 10.0), True, (0.1, 0.2, 0.3, 0.4, 0.5), 17)
    a = np.zeros(N_SS)
    store_state(a, bs, ms)
    bs2, ms2 = unpack_state(a, fifo)
    assert bs2 == bs and ms2[1:] == ms[1:] and ms2.fifo is fifo
    assert np.array_equal(pack_state(bs, ms), a)


def test_noise_draws_are_the_sensor_noise_sequence() -> None:
    """The engine's pre-drawn noise (one draw of whole blocks) is the sequence SensorNoise draws
    block by block: the run engine and the Python loop see the same noise."""
    from tsmpc.config import Config
    from tsmpc.sensors import SensorNoise, noise_draws

    cfg = Config()
    n = 9000  # three blocks, the last one partly used
    pre = noise_draws(cfg.noise, 7, n)
    live = SensorNoise(cfg.noise, 7)
    seq = np.array([live.sample().copy() for _ in range(n)])
    assert pre.shape[0] >= n and pre.shape[0] % 4096 == 0
    np.testing.assert_array_equal(pre[:n], seq)
