"""CommonRoad's single-track model as a plant (optional extra ``[commonroad]``; CI installs it)."""

from __future__ import annotations

import json
import math
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("vehiclemodels", reason="the [commonroad] extra is not installed")

from tsmpc.cli import app
from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.plant import Plant
from tsmpc.sim.simulator import Method, simulate
from tsmpc.vehicle.actuators import Actuators, SteeringServo
from tsmpc.vehicle.commonroad import CommonRoadPlant, commonroad_config
from tsmpc.vehicle.plant import Plant as RK4Plant


@pytest.mark.parametrize("seed", range(4))
def test_commonroad_rates_equal_tsmpc_linear_plant(seed: int) -> None:
    """Independent check of the adapter's state map and of VehicleParams.from_commonroad:
    CommonRoad's own right-hand side against tsmpc's linear-tyre plant with the equivalent
    parameters, both with zero longitudinal force (CommonRoad: a = 0, so no load transfer;
    tsmpc: F_xR = 0 on a road with μ = 0). At α = δ = 0 the two single-track models are the same
    equations; their α and δ derivatives of α̇ and ω̇ (central differences) agree too."""
    from vehiclemodels.vehicle_dynamics_st import vehicle_dynamics_st

    rng = np.random.default_rng(seed)
    cr = CommonRoadPlant(2)
    own = RK4Plant(cr.vehicle, TyreParams(model=TyreModel.LINEAR))
    v, om, th = rng.uniform(3.0, 15.0), rng.uniform(-0.3, 0.3), rng.uniform(-3, 3)

    def rates_cr(al: float, d: float) -> np.ndarray:
        f = vehicle_dynamics_st([0.0, 0.0, d, v, th, om, al], [0.0, 0.0], cr.params)
        return np.array([f[0], f[1], f[4], f[3], f[6], f[5]])  # → [Ẋ, Ẏ, θ̇, v̇, α̇, ω̇]

    def rates_own(al: float, d: float) -> np.ndarray:
        return own.derivatives([0.0, 0.0, th, v, al, om], [0.0, d], 0.0)

    np.testing.assert_allclose(rates_cr(0.0, 0.0), rates_own(0.0, 0.0), rtol=1e-12, atol=1e-12)
    h = 1e-6
    for dal, dd in ((h, 0.0), (0.0, h)):
        jc = (rates_cr(dal, dd) - rates_cr(-dal, -dd)) / (2 * h)
        jo = (rates_own(dal, dd) - rates_own(-dal, -dd)) / (2 * h)
        # (∂ω̇/∂α is 0 for this car: C_f a = C_r b with one normalised stiffness at static loads)
        np.testing.assert_allclose(jc[4:], jo[4:], rtol=1e-6, atol=1e-6)


def test_adapter_follows_the_servo_and_reports_what_it_applied() -> None:
    cr = CommonRoadPlant(2)
    assert isinstance(cr, Plant)
    cr.reset([0, 0, 0, 10.0, 0, 0])
    cr.step([3000.0, 0.0], 0.01, 0.5)
    x = cr.step([3000.0, 0.1], 0.2, 0.5)  # 0.2 s at the 0.4 rad/s rate limit: δ = 0.08 rad
    assert cr.steering_angle == pytest.approx(0.08, abs=2e-3)
    assert 0.03 < cr.applied_input[1] < 0.05  # the mean over the step, half way up the ramp
    assert cr.friction_force == pytest.approx(0.0)  # μ(road) = μ_o
    assert x[5] > 0.0 and np.all(np.isfinite(x))


@pytest.fixture(scope="module")
def runs() -> tuple:
    """REF on the built-in circuit's first 45 s, CommonRoad vehicle 2: on CommonRoad's ST model
    and on tsmpc's plant with the same parameters (linear tyres, same steering servo)."""
    cfg = commonroad_config(Config(), 2)
    sc = dc_replace(load_scenario(cfg), measured_steering=True)
    cr = simulate(cfg, Method.REF, sc, plant=CommonRoadPlant(2, h=cfg.rates.h), max_steps=450)
    own_sc = dc_replace(sc, plant_tyre=TyreParams(model=TyreModel.LINEAR),
                        actuators=Actuators(SteeringServo(0.05, 0.4)))
    own = simulate(cfg, Method.REF, own_sc, max_steps=450)
    return compute_metrics(cr), compute_metrics(own)


@pytest.mark.slow
def test_ref_on_commonroad_st_tracks_like_on_tsmpc_plant(runs: tuple) -> None:
    cr, own = runs
    assert cr["termination"] == "completed" and cr["events"]["step_errors"] == 0
    assert cr["max_abs_lateral_m"] <= 0.25
    pos = [math.hypot(m["rmse"]["x"], m["rmse"]["y"]) for m in (cr, own)]
    # The same controller on two implementations of the same single-track car: position tracking
    # within 10 % (CommonRoad adds load transfer, drops the small-angle trigonometry and applies
    # the acceleration directly within its own limits, so the speed errors differ more on this
    # short window: 15 %; over the whole circuit all RMSEs are in the README).
    assert pos[0] == pytest.approx(pos[1], rel=0.10)


@pytest.mark.slow
def test_cli_runs_the_commonroad_plant(tmp_path: Path) -> None:
    out = tmp_path / "cr"
    res = CliRunner().invoke(app, ["run", "--plant", "commonroad-st", "--cr-vehicle", "2",
                                   "--duration", "3", "--no-plots", "--out", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["scenario"]["plant"] == "commonroad-st" and m["scenario"]["cr_vehicle"] == 2
    assert m["methods"]["REF"]["termination"] == "completed"
    bad = CliRunner().invoke(app, ["run", "--plant", "carla", "--duration", "1"])
    assert bad.exit_code == 2 and "allowed: tsmpc, commonroad-st" in bad.output
    bad = CliRunner().invoke(app, ["run", "--plant", "commonroad-st", "--cr-vehicle", "7",
                                   "--duration", "1"])
    assert bad.exit_code == 2 and "allowed: 1, 2, 3" in bad.output


@pytest.mark.slow
def test_multibody_model_runs_through_the_cascade() -> None:
    """CommonRoad's multi-body model (roll, pitch, wheel spin, Pacejka tyres) on the circuit's
    first 8 s: the state map holds (speed and heading follow the reference, no divergence)."""
    cfg = commonroad_config(Config(), 2)
    sc = dc_replace(load_scenario(cfg), measured_steering=True)
    plant = CommonRoadPlant(2, model="mb", h=cfg.rates.h)
    log = simulate(cfg, Method.REF, sc, plant=plant, max_steps=80)
    m = compute_metrics(log)
    assert m["termination"] == "completed" and m["events"]["step_errors"] == 0
    # (accelerating from 1 m/s: a broken state map is metres or metres per second off)
    assert m["max_abs_lateral_m"] < 0.05 and m["rmse"]["v"] < 0.5
    # the multi-body state seen in tsmpc's convention: slip small, speed = the body's
    assert np.max(np.abs(log.state[:, 4])) < 0.05
    with pytest.raises(Exception, match="allowed: st, mb"):
        CommonRoadPlant(2, model="ks")


@pytest.mark.slow
@pytest.mark.parametrize("vid", [1, 2, 3])
def test_vehicles_1_to_3_certify_on_the_full_steering_box(vid: int) -> None:
    """Issue 20: the designs of CommonRoad vehicles 1–3 certify on the paper's ±25° steering box
    (no narrowed box for a heavier or stiffer car)."""
    from tsmpc.synthesis.cache import load_or_design_dynamic

    cfg = commonroad_config(Config(), vid)
    assert cfg.dynamic_box.delta == Config().dynamic_box.delta
    assert max(abs(d) for d in cfg.dynamic_box.delta) >= math.radians(25) - 1e-3
    d = load_or_design_dynamic(cfg)
    assert all(c.holds for c in d.certificates)


@pytest.mark.slow
def test_multibody_van_drives_the_circuit_past_where_it_left_the_road() -> None:
    """CommonRoad's multi-body VW Vanagon (vehicle 3: 1.5 t, C/M three times the paper car's) on
    the built-in circuit with the default cascade, to 75 s. It left the road at 74 s while the
    online stiffness fit took chords under hard acceleration (combined slip, load transfer: its
    front/rear balance went 10 % off); with the fusion's steady-speed gate (STIFF_MAX_ACCEL)
    max |e_y| is 0.023 m over these 75 s (0.027 m over the whole 134 s circuit). Measured with the
    gate removed (every other fix since in place): 0.072 m, above 0.05 m from 65.6 s — so the
    bound is 0.05 m (2x the gated run's) and the run stops at 75 s, past both; the whole circuit
    cost ~41 s of CPU (the Python loop at 1 kHz), these 75 s ~22 s."""
    cfg = commonroad_config(Config(), 3)
    sc = dc_replace(load_scenario(cfg), measured_steering=True)
    log = simulate(cfg, Method.REF, sc, plant=CommonRoadPlant(3, model="mb", h=cfg.rates.h),
                   max_steps=750)
    m = compute_metrics(log)
    assert m["termination"] == "completed" and log.n_outer == 750, m["termination"]
    assert m["max_abs_lateral_m"] < 0.05
