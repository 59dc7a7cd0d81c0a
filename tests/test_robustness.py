"""Named robustness scenarios (issue 8): the sensor faults, what each scenario changes, and that a
shortened run meets its surface patch."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config
from tsmpc.robustness import (
    ROBUSTNESS_SCENARIOS,
    DropoutFault,
    NaNBurstFault,
    apply_robustness,
    robustness_scenario,
)
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.simulator import Method, simulate


def test_dropout_holds_the_last_measurement_for_its_duration() -> None:
    f = DropoutFault(period_s=5.0, duration_s=0.2, start_s=2.0)
    ts = np.round(np.arange(0.0, 8.0, 0.01), 2)
    out = np.array([f(t, np.array([t, -t]))[0] for t in ts])
    frozen = (ts >= 2.0) & ((ts - 2.0) % 5.0 < 0.2 - 1e-9)
    assert frozen.sum() == 2 * 20  # two dropouts of 20 samples in 8 s
    np.testing.assert_array_equal(out[~frozen], ts[~frozen])
    assert np.all(out[(ts >= 2.0) & (ts < 2.2)] == 1.99)  # the value just before the dropout


def test_nan_bursts_blank_every_channel() -> None:
    f = NaNBurstFault(period_s=7.0, duration_s=0.05, start_s=3.0)
    ts = np.round(np.arange(0.0, 15.0, 0.01), 2)
    bad = np.array([np.isnan(f(t, np.ones(5))).all() for t in ts])
    assert bad.sum() == 2 * 5 and set(ts[bad]) == {3.0, 3.01, 3.02, 3.03, 3.04, 10.0, 10.01, 10.02,
                                                   10.03, 10.04}


def test_each_scenario_changes_what_it_names(cfg: Config) -> None:
    sc = load_scenario(cfg)
    assert set(ROBUSTNESS_SCENARIOS) >= {"ice_patch", "wet_section", "noise_x10", "sensor_dropout",
                                         "nan_bursts", "mass_stiffness_mismatch"}
    c, s = apply_robustness("noise_x10", cfg, sc)
    assert c.noise.scale == pytest.approx(10 * cfg.noise.scale) and s.reference is sc.reference
    c, s = apply_robustness("mass_stiffness_mismatch", cfg, sc)
    assert s.plant_vehicle.mass == pytest.approx(1.2 * cfg.vehicle.mass)
    assert s.plant_vehicle.cornering_stiffness == pytest.approx(0.8 * cfg.vehicle.cornering_stiffness)
    assert c.vehicle == cfg.vehicle  # the controllers keep the nominal model
    c, s = apply_robustness("stiffness_mismatch", cfg, sc)
    assert s.plant_vehicle.mass == cfg.vehicle.mass and c.vehicle == cfg.vehicle
    assert s.plant_vehicle.C_f == pytest.approx(0.8 * cfg.vehicle.C_f)
    assert s.plant_vehicle.C_r == pytest.approx(0.8 * cfg.vehicle.C_r)
    c, s = apply_robustness("ice_patch", cfg, sc, until_s=20.0)
    assert s.plant_tyre.scale_grip_with_road and min(s.friction.mu(0.0, d) for d in range(400)) == 0.1
    c, s = apply_robustness("wet_section", cfg, sc)
    assert s.friction.mu(0.0, 640.0) == pytest.approx(0.6) and s.friction.mu(0.0, 10.0) == 0.9
    with pytest.raises(ValueError, match="allowed: nominal"):
        apply_robustness("hail", cfg, sc)


def test_robustness_scenario_builds_a_typed_case_on_a_reference(cfg: Config) -> None:
    ref = load_scenario(cfg).reference
    case = robustness_scenario("noise_x10", cfg, ref)
    assert case.config.noise.scale == pytest.approx(10 * cfg.noise.scale)
    assert case.scenario.name == "noise_x10" and case.scenario.reference is ref
    case = robustness_scenario("sensor_dropout", cfg, ref)
    assert case.config == cfg and isinstance(case.scenario.sensor_fault, DropoutFault)
    # The fault is per run: two cases never share a stateful fault object.
    other = robustness_scenario("sensor_dropout", cfg, ref)
    assert other.scenario.sensor_fault is not case.scenario.sensor_fault


def test_a_shortened_ice_patch_run_meets_the_ice(cfg: Config) -> None:
    c, sc = apply_robustness("ice_patch", cfg, load_scenario(cfg), until_s=15.0)
    log = simulate(c, Method.REF, sc, max_steps=150)
    assert log.termination == "completed"
    assert log.mu_road.min() == pytest.approx(0.1)
    assert np.max(np.abs(log.errors[:, 1])) < 0.1


def test_cli_run_takes_a_scenario(tmp_path) -> None:
    res = CliRunner().invoke(app, ["run", "--scenario", "nan_bursts", "--duration", "4", "--no-plots",
                                   "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    import json

    m = json.loads((tmp_path / "metrics.json").read_text())["methods"]["REF"]
    # One burst in 4 s (at 3.00 s, 50 ms): 5 inner samples (T_d = 10 ms) reach the MHE as NaN and
    # are rejected; exactly one outer sample (t = 3.0 s, T_c = 100 ms) has a NaN pose, which the
    # MPC replaces by the last good one.
    assert m["events"]["mhe_rejected"] == 5 and m["events"]["pose_rejected"] == 1
    assert m["termination"] == "completed"
    ts = np.load(tmp_path / "timeseries.npz")
    assert np.all(np.isfinite(ts["REF_errors_measured"]))  # the MPC never saw a NaN
    bad = CliRunner().invoke(app, ["run", "--scenario", "hail", "--duration", "1"])
    assert bad.exit_code == 2 and "unknown robustness scenario 'hail'" in bad.output
