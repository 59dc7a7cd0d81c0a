"""The scenario vocabulary (issue 21; tsmpc.conditions, cfg.scenario): friction events, sensor
faults, plant scales, actuators, oracle-tuned controllers — each against a hand computation, and
every field validated with a message naming it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.conditions import (
    EventFriction,
    SensorModel,
    apply_conditions,
    corner_apexes,
    plant_vehicle,
    resolve_events,
)
from tsmpc.config import Config, FrictionEvent, SensorFaults, load_config, validate
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference
from tsmpc.scenarios import ConstantFriction
from tsmpc.sim.simulator import Scenario


def _ref(n: int = 400, dt: float = 0.1) -> Reference:
    """10 m/s, two left corners: ω_d = 0.1 for samples 100–149 and 0.3 for 250–299."""
    t = np.arange(n) * dt
    w = np.zeros(n)
    w[100:150], w[250:300] = 0.1, 0.3
    th = np.cumsum(w) * dt
    v = np.full(n, 10.0)
    x = np.cumsum(v * np.cos(th)) * dt
    y = np.cumsum(v * np.sin(th)) * dt
    return Reference(t, x, y, th, v, w, w / v)


def _cfg(**scenario: object) -> Config:
    return validate(Config, {"scenario": scenario})


# -- friction events ------------------------------------------------------------------------
def test_a_mu_step_at_a_time_takes_effect_at_that_time() -> None:
    ev = resolve_events([FrictionEvent(mu=0.3, at_s=12.0)], _ref())
    f = EventFriction(ConstantFriction(0.9), ev)
    assert f.mu(12.0 - 1e-9) == 0.9
    assert f.mu(12.0) == 0.3
    assert f.mu(500.0) == 0.3  # no duration: to the end


def test_ramps_durations_and_distance_triggers() -> None:
    ref = _ref()
    ev = resolve_events([FrictionEvent(mu=0.5, at_s=10.0, ramp_s=2.0, duration_s=5.0),
                         FrictionEvent(mu=0.1, at_m=100.0, ramp_m=10.0, length_m=20.0)], ref)
    f = EventFriction(ConstantFriction(0.9), ev)
    assert f.mu(11.0) == pytest.approx(0.7)  # half-way through the ramp 0.9 → 0.5
    assert f.mu(13.0) == pytest.approx(0.5)
    assert f.mu(16.0) == pytest.approx(0.7)  # ramping back after 15 s
    assert f.mu(18.0) == pytest.approx(0.9)
    assert f.mu(0.0, 105.0) == pytest.approx(0.5)  # by distance: half-way 0.9 → 0.1
    assert f.mu(0.0, 115.0) == pytest.approx(0.1)
    assert f.mu(0.0, 135.0) == pytest.approx(0.9)
    # events apply in order: the distance patch during the time patch blends from 0.5
    assert f.mu(13.0, 115.0) == pytest.approx(0.1)


def test_at_corner_is_the_apex_of_the_kth_corner() -> None:
    ref = _ref()
    assert corner_apexes(ref) == [250]  # only the 0.3 rad/s corner is above half the largest
    w = np.array(ref.omega)
    w[120] = 0.25  # a peak inside the first corner lifts it above half of 0.3
    ref2 = Reference(ref.t, ref.x, ref.y, ref.theta, ref.v, w, ref.kappa)
    assert corner_apexes(ref2) == [120, 250]
    (e,) = resolve_events([FrictionEvent(mu=0.3, at_corner=2, duration_s=1.0)], ref2)
    assert (e.by_time, e.start, e.end) == (True, pytest.approx(25.0), pytest.approx(26.0))
    with pytest.raises(ConfigError, match="at_corner = 3: the reference has 2 corner"):
        resolve_events([FrictionEvent(mu=0.3, at_corner=3)], ref2)


@pytest.mark.parametrize(("table", "field"), [
    ({"mu": 0.3}, "exactly one of at_s, at_m, at_corner"),
    ({"mu": 0.3, "at_s": 1.0, "at_m": 5.0}, "exactly one of"),
    ({"mu": 0.3, "at_s": 1.0, "ramp_m": 5.0}, "ramp_m does not fit the trigger at_s"),
    ({"mu": 0.3, "at_m": 1.0, "duration_s": 5.0}, "duration_s does not fit the trigger at_m"),
    ({"mu": 2.0, "at_s": 1.0}, "scenario.friction.0.mu"),
    ({"mu": 0.3, "at_s": -1.0}, "scenario.friction.0.at_s"),
])
def test_bad_friction_events_are_refused_naming_the_field(table: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        validate(Config, {"scenario": {"friction": [table]}}, source="case.toml")


@pytest.mark.parametrize(("section", "table", "field"), [
    ("plant", {"mass_scale": 5.0}, "scenario.plant.mass_scale"),
    ("plant", {"cornering_rear_scale": 0.0}, "scenario.plant.cornering_rear_scale"),
    ("plant", {"mass_sacle": 1.2}, "scenario.plant.mass_sacle: unknown field"),
    ("sensors", {"dropout_probability": 1.0}, "scenario.sensors.dropout_probability"),
    ("sensors", {"v_bias": float("nan")}, "scenario.sensors.v_bias"),
    ("sensors", {"gnss_noise_scale": 0.5}, "scenario.sensors.gnss_noise_scale"),
    ("actuators", {"steering_time_constant_s": -0.1}, "scenario.actuators.steering_time_constant_s"),
])
def test_bad_scenario_fields_are_refused_naming_them(section: str, table: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        validate(Config, {"scenario": {section: table}}, source="case.toml")


def test_a_toml_case_loads_and_round_trips(tmp_path) -> None:
    p = tmp_path / "case.toml"
    p.write_text('[scenario.plant]\nmass_scale = 1.2\n[scenario.sensors]\nv_bias = 0.2\n'
                 '[[scenario.friction]]\nat_corner = 1\nmu = 0.3\nduration_s = 5.0\n')
    cfg = load_config(p)
    assert cfg.scenario.plant.mass_scale == 1.2 and cfg.scenario.friction[0].at_corner == 1
    p2 = tmp_path / "again.toml"
    p2.write_text(cfg.to_toml())
    assert load_config(p2) == cfg


# -- plant scales ---------------------------------------------------------------------------
def test_plant_scales_act_on_the_config_vehicle(cfg: Config) -> None:
    c = _cfg(plant={"mass_scale": 1.2, "inertia_scale": 0.8, "cornering_front_scale": 0.7,
                    "cornering_rear_scale": 1.3, "cog_to_front_scale": 1.1})
    v, p = plant_vehicle(c), cfg.vehicle
    assert v.mass == pytest.approx(1.2 * p.mass) and v.inertia == pytest.approx(0.8 * p.inertia)
    assert v.C_f == pytest.approx(0.7 * p.C_f) and v.C_r == pytest.approx(1.3 * p.C_r)
    assert v.a == pytest.approx(1.1 * p.a) and v.a + v.b == pytest.approx(p.a + p.b)  # wheelbase kept
    with pytest.raises(ConfigError, match="cog_to_front_scale"):
        plant_vehicle(_cfg(plant={"cog_to_front_scale": 1.5}).model_copy(
            update={"vehicle": p.model_copy(update={"a": 1.5, "b": 0.3})}))


def test_default_scenario_changes_nothing(cfg: Config) -> None:
    sc = Scenario("s", _ref())
    out_cfg, out = apply_conditions(cfg, sc)
    assert out_cfg is cfg and out is sc


def test_apply_conditions_builds_the_plant_road_sensors_and_actuators(cfg: Config) -> None:
    c = _cfg(plant={"mass_scale": 1.2, "combined_slip": True, "grip_scales_with_road": True},
             base_mu=0.9, friction=[{"at_s": 5.0, "mu": 0.3}], sensors={"v_bias": 0.2},
             actuators={"steering_time_constant_s": 0.05, "measured_steering": True})
    c2, sc = apply_conditions(c, Scenario("s", _ref()))
    assert c2.vehicle == cfg.vehicle  # the controllers keep the model's vehicle
    assert sc.plant_vehicle.mass == pytest.approx(1.2 * cfg.vehicle.mass)
    assert sc.plant_tyre.combined_slip and sc.plant_tyre.scale_grip_with_road
    assert sc.friction.mu(4.9) == 0.9 and sc.friction.mu(5.0) == 0.3
    assert sc.actuators.steering.time_constant_s == 0.05 and sc.actuators.force is None
    assert sc.measured_steering
    assert sc.sensor_fault(0.0, np.zeros(5))[3] == pytest.approx(0.2)
    assert sc.meta["conditions"]["plant"]["mass_scale"] == 1.2


def test_oracle_tuned_gives_the_controllers_the_plant_and_calibrated_sensors(cfg: Config) -> None:
    c = _cfg(plant={"mass_scale": 1.2, "cornering_rear_scale": 0.7}, oracle_tuned=True,
             sensors={"v_bias": 0.2, "dropout_probability": 0.05})
    c2, sc = apply_conditions(c, Scenario("s", _ref()))
    assert c2.vehicle == sc.plant_vehicle  # models and designs from the truth
    assert c2.vehicle.mass == pytest.approx(1.2 * cfg.vehicle.mass)
    fault = sc.sensor_fault
    assert fault.faults.v_bias == 0.0 and fault.faults.dropout_probability == 0.05
    # idempotent: the config it returns describes the same run again (scales folded in)
    c3, sc3 = apply_conditions(c2, Scenario("s", _ref()))
    assert c3.vehicle == c2.vehicle and (sc3.plant_vehicle or c3.vehicle) == sc.plant_vehicle


_PLANT = {"mass_scale": 1.2, "inertia_scale": 0.8, "cornering_front_scale": 0.7, "cornering_rear_scale": 1.3,
          "cog_to_front_scale": 1.05, "steering_offset_rad": 0.01}


@pytest.mark.parametrize("part", ["mass", "inertia", "cornering_stiffness", "cog"])
def test_known_tells_the_controllers_one_part_of_the_plant_and_leaves_the_plant_alone(
        cfg: Config, part: str) -> None:
    c = _cfg(plant=_PLANT, known=[part], sensors={"v_bias": 0.2})
    plant = plant_vehicle(c)
    c2, sc = apply_conditions(c, Scenario("s", _ref()))
    fields = {"mass": ("mass",), "inertia": ("inertia",), "cornering_stiffness": ("C_f", "C_r"),
              "cog": ("a", "b")}[part]
    for f in ("mass", "inertia", "C_f", "C_r", "a", "b"):  # the told part the plant's, the rest the config's
        assert getattr(c2.vehicle, f) == pytest.approx(getattr(plant if f in fields else cfg.vehicle, f)), f
    assert sc.plant_vehicle == plant
    assert sc.sensor_fault.faults.v_bias == 0.2  # the sensors are not calibrated
    assert sc.actuators.steering_offset_rad == 0.01  # nor the steering
    # the car's engine: the force limits stay the config vehicle's, in newtons
    assert c2.lqr.force_limits(c2.vehicle) == pytest.approx(cfg.lqr.force_limits(cfg.vehicle))
    c3, sc3 = apply_conditions(c2, Scenario("s", _ref()))  # the config it returns runs alike
    assert c3.vehicle == c2.vehicle and sc3.plant_vehicle == plant


def test_known_sensor_biases_and_steering_offset_calibrate_only_those(cfg: Config) -> None:
    c = _cfg(plant=_PLANT, known=["sensor_biases"], sensors={"v_bias": 0.2, "omega_scale": 1.1})
    c2, sc = apply_conditions(c, Scenario("s", _ref()))
    assert c2.vehicle == cfg.vehicle and sc.actuators.steering_offset_rad == 0.01
    assert sc.sensor_fault is None or (sc.sensor_fault.faults.v_bias == 0.0
                                       and sc.sensor_fault.faults.omega_scale == 1.0)
    _, sc = apply_conditions(_cfg(plant=_PLANT, known=["steering_offset"], sensors={"v_bias": 0.2}),
                             Scenario("s", _ref()))
    assert sc.sensor_fault.faults.v_bias == 0.2
    assert sc.actuators is None or sc.actuators.steering_offset_rad == 0.0


def test_every_part_known_is_the_oracle_tuned_run() -> None:
    over = {"plant": _PLANT, "sensors": {"v_bias": 0.2, "omega_bias": 0.01, "dropout_probability": 0.05}}
    every = ["mass", "inertia", "cornering_stiffness", "cog", "sensor_biases", "steering_offset"]
    a_cfg, a = apply_conditions(_cfg(**over, known=every), Scenario("s", _ref()))
    b_cfg, b = apply_conditions(_cfg(**over, oracle_tuned=True), Scenario("s", _ref()))
    assert a_cfg.vehicle == b_cfg.vehicle and a_cfg.lqr == b_cfg.lqr
    assert a.plant_vehicle == b.plant_vehicle and a.sensor_fault.faults == b.sensor_fault.faults
    assert (a.actuators is None) == (b.actuators is None)


def test_an_unknown_part_is_refused_naming_the_field() -> None:
    with pytest.raises(ConfigError, match=r"scenario\.known"):
        _cfg(known=["weight"])


# -- sensor faults ----------------------------------------------------------------------------
def _truth(k: int) -> np.ndarray:
    return np.array([1.0 * k, 2.0 * k, 0.01 * k, 10.0 + 0.1 * k, 0.001 * k])


def test_biases_and_drifts_add_to_v_omega_theta() -> None:
    f = SensorFaults(v_bias=0.2, omega_bias=0.01, theta_bias=-0.02, v_drift=0.01,
                     omega_drift=0.001, theta_drift=0.002)
    m = SensorModel(f, 0.01, 0.001, 0)
    y = m(3.0, _truth(0))
    np.testing.assert_allclose(y, [0.0, 0.0, -0.02 + 0.006, 10.0 + 0.2 + 0.03, 0.01 + 0.003])


def test_delay_delivers_the_sample_of_delay_s_ago() -> None:
    m = SensorModel(SensorFaults(delay_s=0.05), 0.01, 0.001, 0)
    out = [m(k * 0.01, _truth(k)) for k in range(20)]
    np.testing.assert_allclose(out[12], _truth(7))
    np.testing.assert_allclose(out[2], _truth(0))  # before 5 samples exist: the oldest


def test_dropouts_are_nan_with_the_probability_and_repeat_with_hold() -> None:
    n = 20000
    m = SensorModel(SensorFaults(dropout_probability=0.05), 0.01, 0.001, 7)
    lost = sum(bool(np.isnan(m(k * 0.01, _truth(k))).all()) for k in range(n))
    assert abs(lost / n - 0.05) < 4 * math.sqrt(0.05 * 0.95 / n)  # 4 σ of a binomial
    h = SensorModel(SensorFaults(dropout_probability=0.05, dropout_hold=True), 0.01, 0.001, 7)
    out = [h(k * 0.01, _truth(k)) for k in range(n)]
    held = [k for k in range(1, n) if np.array_equal(out[k], out[k - 1])]
    assert len(held) == lost  # the same draws (same seed): every lost sample repeats the last one
    assert not any(np.isnan(o).any() for o in out)


def test_gnss_noise_scale_multiplies_the_position_sigma() -> None:
    m = SensorModel(SensorFaults(gnss_noise_scale=10.0), 0.01, 0.001, 3)
    e = np.array([m(k * 0.01, np.zeros(5))[:2] for k in range(20000)])
    # extra σ = 0.001 sqrt(10² − 1): with the configured σ the total is 10 × 0.001
    assert np.std(e) == pytest.approx(0.001 * math.sqrt(99.0), rel=0.03)
    assert np.all(e[:, :0] == 0.0)


def test_a_run_starting_again_gets_the_same_draws() -> None:
    m = SensorModel(SensorFaults(dropout_probability=0.3, gnss_noise_scale=5.0), 0.01, 0.001, 1)
    a = [m(k * 0.01, _truth(k)) for k in range(200)]
    b = [m(k * 0.01, _truth(k)) for k in range(200)]  # time went back to 0: a new run
    for u, w in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, w)


# -- the command line: --set KEY=VALUE ----------------------------------------------------------
def test_set_assignments_reach_the_config_and_bad_ones_are_refused(cfg: Config) -> None:
    from tsmpc.config import apply_overrides

    c = apply_overrides(cfg, ["scenario.plant.mass_scale=1.2", "lqr.friction_estimate=uio",
                              "scenario.friction=[{at_s = 60, mu = 0.3}]", "fusion.predict_pose=false"])
    assert c.scenario.plant.mass_scale == 1.2 and c.lqr.friction_estimate == "uio"
    assert c.scenario.friction[0].at_s == 60.0 and not c.fusion.predict_pose
    for bad, msg in [("scenario.plant.mass_scale=9", "scenario.plant.mass_scale"),
                     ("scenario.plant.mas=1", "scenario.plant.mas: unknown field"),
                     ("scenario.plnt.mass_scale=1", "unknown field 'plnt'"),
                     ("mass_scale", "expected KEY=VALUE"),
                     ("fusion.predict_pose=yes", "fusion.predict_pose")]:
        with pytest.raises(ConfigError, match=msg):
            apply_overrides(cfg, [bad])


def test_cli_set_exits_2_naming_the_field(tmp_path) -> None:
    from typer.testing import CliRunner

    from tsmpc.cli import app

    res = CliRunner().invoke(app, ["run", "--set", "scenario.sensors.dropout_probability=0.9",
                                   "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "scenario.sensors.dropout_probability" in res.output
    assert not (tmp_path / "o").exists()  # refused before any work


def test_a_sweep_solves_the_designs_of_a_controller_told_part_of_the_plant_once(cfg: Config) -> None:
    from tsmpc.sweep import RunParams, RunTask, _solve_run_designs

    told = _cfg(plant=_PLANT, known=["mass"]).model_dump()
    tasks = [RunTask(f"r{i}", RunParams(), told, None, 5.0, ".") for i in range(2)]
    made: list[Config] = []
    _solve_run_designs(tasks, cfg, made.append)  # type: ignore[arg-type]
    assert len(made) == 1 and made[0].vehicle.mass == pytest.approx(1.2 * cfg.vehicle.mass)
    assert made[0].vehicle.inertia == cfg.vehicle.inertia
