"""Honest degradation (issue 36 item 3): a run that completes with its actuators saturated most of
the time, or with errors beyond the health bounds, ends ``degraded`` (exit 3, one line naming the
cause and the likely field); force limits follow the mass by default; a config that gives a force
bound both ways, inconsistently, is refused before the run."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config, LQRSettings, VehicleParams, load_config
from tsmpc.errors import ConfigError
from tsmpc.sim.health import MAX_SATURATED_SHARE, MIN_JUDGED_S, START_S, degradation, rmse_bounds

runner = CliRunner()
_HEALTHY = {"x": 0.02, "y": 0.002, "theta": 0.005, "v": 0.05, "omega": 0.002}


def _metrics(**rmse: float) -> dict[str, object]:
    return {"rmse": {**_HEALTHY, **rmse}}


def _log(saturated: int, *, force: float = 0.0, at_limit: int = 0, seconds: float = 20.0,
         steer: float = 0.0) -> SimpleNamespace:
    """An inner-loop log at T_d = 10 ms: the start-up (5 s) saturated throughout, then ``saturated``
    saturated steps, ``at_limit`` of them with the force at ``force``."""
    t = np.arange(round(seconds / 0.01)) * 0.01
    start = int(np.sum(t < START_S))
    sat = np.zeros(t.size, dtype=bool)
    sat[:start] = True
    sat[start:start + saturated] = True
    cmd = np.zeros((t.size, 2))
    cmd[start:start + at_limit, 0] = force
    cmd[:, 1] = steer
    return SimpleNamespace(t_inner=t, saturated=sat, command=cmd)


def test_saturated_most_of_the_time_is_degraded_naming_the_limit_and_field() -> None:
    cfg = Config()
    heavy = Config.model_validate({"vehicle": {"mass": 1000.0}, "lqr": {"force_max": 10000.0}})
    log = _log(900, force=10000.0, at_limit=870)  # of 1500 steps after the start-up: 60 %, 58 %
    line = degradation(_metrics(), log, heavy)
    assert line is not None and "\n" not in line
    assert line.startswith("degraded: inner loop saturated on 60 % of steps after the first 5 s (drive "
                           "force at its 10000 N limit on 58 %)")
    assert "for a 1000 kg car" in line and "lqr.force_max = 10000 N is absolute" in line
    assert "set lqr.force_max_per_kg" in line
    # the per-kg default names the per-kg field alone
    line = degradation(_metrics(), log, cfg)
    assert line is not None and "set lqr.force_max_per_kg" in line and "absolute" not in line
    # steering at its limit names the plan and lqr.delta_max
    line = degradation(_metrics(), _log(1400, steer=cfg.lqr.delta_max), cfg)
    assert line is not None and "steering at its 25 deg limit" in line and "lqr.delta_max" in line


def test_the_saturation_share_is_the_bound_after_the_start_up() -> None:
    cfg = Config()
    at = int(MAX_SATURATED_SHARE * 1500)
    assert degradation(_metrics(), _log(at, force=10000.0, at_limit=at), cfg) is None
    assert degradation(_metrics(), _log(at + 1, force=10000.0, at_limit=at + 1), cfg) is not None
    # the start-up is not judged (the published run's steering transient): saturated throughout,
    # then 40 % — 55 % of the whole run
    assert degradation(_metrics(), _log(600), cfg) is None
    # nor a run too short to judge
    short = _log(0, seconds=START_S + MIN_JUDGED_S - 0.1)
    short.saturated[:] = True
    assert degradation(_metrics(x=9.0), short, cfg) is None


def test_errors_beyond_the_health_bounds_are_degraded() -> None:
    cfg = Config()
    bounds = rmse_bounds()
    assert bounds == pytest.approx({"x": 4 * 0.528, "y": 4 * 0.259})  # 4 x the paper's worst Table 5 RMSE
    assert degradation(_metrics(x=bounds["x"] * 0.99, y=bounds["y"] * 0.99), _log(0), cfg) is None
    line = degradation(_metrics(x=6.64), _log(0), cfg)
    assert line is not None and "RMSE e_x 6.64 m > 2.11 m" in line and "lqr.force_max_per_kg" in line
    line = degradation(_metrics(y=1.2), _log(0), cfg)
    assert line is not None and "RMSE e_y 1.20 m > 1.04 m" in line


@pytest.mark.slow
def test_a_degraded_run_exits_3_with_one_line(tmp_path: Path) -> None:
    """A plant 45 % heavier than the config says (the plan check plans for the config's car): the
    10 kN drive force cannot carry the plan's accelerations against its road resistance; 20 s.
    With the speed governor off: on (the default) it re-times the plan once the rear wheel spins,
    and the same run completes (checked below)."""
    out = tmp_path / "out"
    res = runner.invoke(app, ["run", "--duration", "20", "--no-plots", "--out", str(out),
                              "--set", "scenario.plant.mass_scale=1.45", "--set", "governor.enabled=false"])
    assert res.exit_code == 3, res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("degraded:")]
    assert len(lines) == 1, res.output
    assert "steps after the first 5 s (drive force at its 10000 N limit" in lines[0]
    assert "set lqr.force_max_per_kg" in lines[0]
    m = json.loads((out / "metrics.json").read_text())
    assert m["methods"]["REF"]["status"] == "degraded" and m["degraded"] == ["REF"]
    assert m["methods"]["REF"]["degraded"] == lines[0]
    assert not (out / "PARTIAL").exists()  # the results are complete
    governed = tmp_path / "governed"
    res = runner.invoke(app, ["run", "--duration", "20", "--no-plots", "--out", str(governed),
                              "--set", "scenario.plant.mass_scale=1.45"])
    assert res.exit_code == 0, res.output
    g = json.loads((governed / "metrics.json").read_text())["methods"]["REF"]
    assert g["status"] == "completed" and g["events"]["governor_actions"] >= 1, g["events"]


def test_force_limits_follow_the_mass_by_default() -> None:
    nominal = Config()
    # the per-kg default gives the published limits at the nominal mass exactly: bit-identical runs
    assert nominal.lqr.force_limits(nominal.vehicle) == (-2000.0, 10000.0)
    heavy = VehicleParams(mass=1000.0)
    lo, hi = LQRSettings().force_limits(heavy)
    assert (lo, hi) == (pytest.approx(-2000.0 * 1000 / 683), pytest.approx(10000.0 * 1000 / 683))
    for preset in ("paper", "paper-as-run"):  # faithful: the published absolute limits
        assert Config.preset(preset).lqr.force_limits(heavy) == (-2000.0, 10000.0)


def test_the_oracle_tuned_controllers_keep_the_cars_actuators() -> None:
    """Knowing the true mass (+20 %) gives the oracle-tuned controllers the true models, not
    another engine: the limits stay the config's vehicle's, also in its saved config."""
    from tsmpc.conditions import apply_conditions
    from tsmpc.config import apply_overrides
    from tsmpc.sim.compare import load_scenario

    cfg = apply_overrides(Config(), ["scenario.oracle_tuned=true", "scenario.plant.mass_scale=1.2"])
    oracle, _ = apply_conditions(cfg, load_scenario(cfg))
    assert oracle.vehicle.mass == pytest.approx(1.2 * 683.0)
    assert oracle.lqr.force_limits(oracle.vehicle) == (-2000.0, 10000.0)
    again, _ = apply_conditions(oracle, load_scenario(oracle))  # the saved config re-runs alike
    assert again.lqr.force_limits(again.vehicle) == (-2000.0, 10000.0)


@pytest.mark.parametrize(("text", "needle"), [
    ("[lqr]\nforce_max = 12000.0\nforce_max_per_kg = 20.0\n",
     "lqr.force_max = 12000 N and lqr.force_max_per_kg = 20 N/kg disagree for a 683 kg vehicle"),
    ("[vehicle]\nmass = 1000.0\n[lqr]\nforce_min = -2000.0\nforce_min_per_kg = -2.928\n",
     "lqr.force_min = -2000 N and lqr.force_min_per_kg = -2.928 N/kg disagree for a 1000 kg vehicle"),
    ("[lqr]\nforce_min = 20000.0\n", "F_min = 20000 N >= F_max = 10000 N"),
])
def test_an_inconsistent_pair_is_refused_before_the_run(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"disagree|F_min"):
        load_config(path)
    res = runner.invoke(app, ["run", "--config", str(path), "--no-plots", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and needle in res.output, res.output
    assert len([ln for ln in res.output.splitlines() if ln.strip()]) == 1
    assert not (tmp_path / "o").exists()


def test_a_consistent_pair_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text(f"[lqr]\nforce_max = 13660.0\nforce_max_per_kg = {13660.0 / 683.0!r}\n", encoding="utf-8")
    cfg = load_config(path)
    assert math.isclose(cfg.lqr.force_limits(cfg.vehicle)[1], 13660.0)
