"""Divergence is a result (issue 15): a run whose |e_y| passes its bound ends as ``diverged``, is
never tabled as completed and makes the CLI exit 1; closed laps are tracked to their end."""

from __future__ import annotations

import json
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config, PlannerSettings
from tsmpc.planning.planner import plan_path
from tsmpc.planning.reference import Reference, read_csv_meta
from tsmpc.report.tables import rmse_csv, rmse_markdown, rmse_rows
from tsmpc.sim.compare import compare, load_scenario
from tsmpc.sim.simulator import Method, simulate, tracked_steps


def _square(n: int = 8, side: float = 40.0) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return side * np.stack([np.cos(t), np.sin(t)], axis=1)


def test_run_past_its_bound_is_diverged_and_never_tabled_as_completed() -> None:
    cfg = Config()
    sc = dc_replace(load_scenario(cfg), initial_error=(0.5, 0.0), divergence_bound_m=0.2)
    res = compare(cfg, sc, [Method.REF], None, max_steps=20)
    m = res.metrics["methods"]["REF"]
    assert m["status"] == "diverged" and res.metrics["diverged"] == ["REF"]
    assert m["termination"].startswith("diverged: |e_y| = 0.50 m > 0.2 m")
    assert m["outer_steps"] == 1  # stopped at once, not simulated on
    rows = rmse_rows(res.metrics, with_paper=True)
    assert rows[0][0] == "REF (diverged)" and all(np.isnan(rows[0][1]))
    assert len(rows) == 1  # no paper row beside a diverged run
    assert "REF (diverged) | — |" in rmse_markdown(res.metrics, True)
    assert rmse_csv(res.metrics, True).splitlines()[1].startswith("REF (diverged),nan")


def test_default_bound_comes_from_the_config() -> None:
    cfg = Config(divergence_bound_m=0.3)
    sc = dc_replace(load_scenario(cfg), initial_error=(0.4, 0.0))
    log = simulate(cfg, Method.FZN, sc, max_steps=5)
    assert log.termination.startswith("diverged") and log.n_outer == 1


def test_cli_exits_1_when_a_method_diverged(tmp_path: Path) -> None:
    cfg_file = tmp_path / "tight.toml"
    cfg_file.write_text("divergence_bound_m = 1e-7\n")  # any drift at all
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", "--duration", "3", "--config", str(cfg_file), "--out",
                                   str(out), "--no-plots"])
    assert res.exit_code == 1, res.output
    assert "REF (diverged)" in res.output and "diverged: |e_y|" in res.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["methods"]["REF"]["status"] == "diverged"


def test_planned_track_carries_closed_flag_and_half_width(tmp_path: Path, tracks_dir: Path) -> None:
    out = tmp_path / "zandvoort.csv"
    res = CliRunner().invoke(app, ["plan", str(tracks_dir / "Zandvoort.csv"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    meta = read_csv_meta(out)
    assert meta["closed"] == "true" and 3.0 < float(meta["half_width_m"]) < 4.0
    ref = Reference.from_csv(out)
    assert ref.closed
    sc = load_scenario(Config(), out)
    assert sc.divergence_bound_m == pytest.approx(float(meta["half_width_m"]))
    assert tracked_steps(sc.reference, 40) == len(ref)  # the whole lap, not len − N
    sc3 = load_scenario(Config(), out, laps=3)
    assert len(sc3.reference) == 3 * len(ref) and sc3.reference.closed


def test_closed_lap_is_tracked_to_its_end_with_wrapping_look_ahead() -> None:
    ref = plan_path(_square(), PlannerSettings(v_max=6.0), closed=True, dt=0.1)
    assert ref.closed
    two = ref.repeat(2)
    L = len(ref)
    assert len(two) == 2 * L and two.closed
    np.testing.assert_allclose(two.x[L:], ref.x, atol=1e-9)
    np.testing.assert_allclose(two.theta[L:] - ref.theta, 2 * np.pi, atol=1e-6)
    cfg = Config()
    from tsmpc.scenarios import ConstantFriction
    from tsmpc.sim.simulator import Scenario

    sc = Scenario("ring", two, friction=ConstantFriction(0.9), meta={"laps": 2})
    res = compare(cfg, sc, [Method.REF], None)
    log = res.logs["REF"]
    assert log.termination == "completed" and log.n_outer == 2 * L
    # the end of the second lap is driven (not left as look-ahead) and tracked
    per_lap = res.metrics["methods"]["REF"]["max_abs_lateral_per_lap_m"]
    assert len(per_lap) == 2 and max(per_lap) < 0.5
    assert per_lap[1] == pytest.approx(float(np.max(np.abs(log.errors[L:, 1]))))


def test_laps_on_an_open_reference_is_refused(tmp_path: Path) -> None:
    ref = plan_path(np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 10.0]]), PlannerSettings(), closed=False)
    f = tmp_path / "open.csv"
    ref.to_csv(f)
    res = CliRunner().invoke(app, ["run", "--reference", str(f), "--laps", "2", "--out",
                                   str(tmp_path / "o")])
    assert res.exit_code == 2 and "needs a closed lap" in res.output
