"""Sweep axes ``case`` and ``controller`` (issue 21): named [scenario] tables and config overrides,
validated before any task, expanded into each run's config."""

from __future__ import annotations

from pathlib import Path

import pytest

from tsmpc.config import Config, validate
from tsmpc.errors import ConfigError
from tsmpc.sweep import expand, load_sweep, run_config

GOOD = """
name = "cases"
duration_s = 2.0
[cases.heavy]
plant = { mass_scale = 1.2 }
[cases.drop]
sensors = { dropout_probability = 0.05 }
[controllers.oracle]
scenario = { oracle_tuned = true }
[controllers.slow-speed-loop]
preset = "default"
lqr = { speed_time_constant = 0.6 }
[grid]
case = ["nominal", "heavy", "drop"]
controller = ["paper", "default", "oracle", "slow-speed-loop"]
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def test_cases_and_controllers_expand_into_each_runs_config(tmp_path: Path) -> None:
    spec = load_sweep(_write(tmp_path, GOOD))
    tasks = expand(spec)
    assert len(tasks) == 12 and len({t.id for t in tasks}) == 12
    by = {(t.params.case, t.params.controller): validate(Config, t.config) for t in tasks}
    assert by[("heavy", "oracle")].scenario.plant.mass_scale == 1.2
    assert by[("heavy", "oracle")].scenario.oracle_tuned
    assert by[("drop", "default")].scenario.sensors.dropout_probability == 0.05
    assert by[("nominal", "default")] == Config()
    paper = Config.preset("paper")
    assert by[("nominal", "paper")] == paper  # a built-in preset over the base config
    assert by[("heavy", "paper")].lqr == paper.lqr and not by[("heavy", "paper")].fusion.predict_pose
    assert by[("nominal", "slow-speed-loop")].lqr.speed_time_constant == 0.6


@pytest.mark.parametrize(("change", "message"), [
    ('[cases.bad]\nplant = { mass_scale = 9.0 }\n', "cases.bad: .*scenario.plant.mass_scale"),
    ('[cases.bad]\nplnt = { mass_scale = 1.2 }\n', "cases.bad: .*scenario.plnt: unknown field"),
    ('[controllers.bad]\nlqr = { speed_time_constant = -1.0 }\n',
     "controllers.bad: .*lqr.speed_time_constant"),
    ('[controllers.bad]\npreset = "fast"\n', "controllers.bad: .*unknown preset 'fast'"),
])
def test_a_bad_named_case_or_controller_fails_before_any_task(tmp_path: Path, change: str,
                                                              message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_sweep(_write(tmp_path, GOOD + change))


def test_an_unknown_name_on_an_axis_is_refused_with_the_allowed_ones(tmp_path: Path) -> None:
    text = GOOD.replace('case = ["nominal", "heavy", "drop"]', 'case = ["nominal", "hevy"]')
    with pytest.raises(ConfigError, match=r"case: unknown 'hevy'; allowed: nominal, heavy, drop"):
        load_sweep(_write(tmp_path, text))
    spec = load_sweep(_write(tmp_path, GOOD))
    with pytest.raises(ConfigError, match="controller: unknown 'orcale'; allowed: default, paper"):
        run_config(spec, "nominal", "orcale")
