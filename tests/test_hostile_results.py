"""No successful-looking wrong results (issue 24): a run that reaches its end while its controller
did not work — most MPC steps fell back to the previous plan or solved only the softened problem,
most estimator solves failed — is not "completed" (``tsmpc.sim.health``): the CLI exits 1 with
one line and PARTIAL "failed", a sweep records the run as ``degraded``.

The absurd configs of the issue (weights of 1e300, noise of 1e300, du_max = 1e-300) are refused
before any work by the plausible ranges; these tests use configs *inside* the ranges that still
leave the controller unable to act (a rate bound of 1 mm/s per step).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.cli._common import PARTIAL_MARKER
from tsmpc.sim.health import health_problem

CRAWL = "[mpc]\ndu_max = [0.001, 0.0001]\n"  # in range, but the MPC can barely change its inputs


@pytest.mark.parametrize(("events", "outer", "inner", "word"), [
    ({"mpc_fallback": 30}, 30, 300, "fell back"),
    ({"mpc_fallback": 7}, 30, 300, "fell back"),
    ({"mpc_soft": 50}, 50, 500, "softened"),
    ({"mhe_failed": 298}, 30, 300, "estimator"),
    ({"mpc_fallback": 3, "mpc_soft": 10, "mhe_failed": 20}, 30, 300, None),  # a few: healthy
    ({"mpc_fallback": 5}, 5, 50, None),  # too short to judge
    ({}, 1272, 12720, None),
])
def test_health_counts_what_the_controller_could_not_do(events: dict, outer: int, inner: int,
                                                        word: str | None) -> None:
    problem = health_problem({"events": events, "outer_steps": outer, "inner_steps": inner})
    if word is None:
        assert problem is None
    else:
        assert problem is not None and word in problem and "\n" not in problem


@pytest.mark.timeout(120)
def test_a_run_whose_mpc_could_not_act_exits_1_with_partial_failed(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(CRAWL)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", "--duration", "5", "--no-plots", "--config", str(cfg),
                                   "--out", str(out)])
    assert res.exit_code == 1, res.output
    line = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(line) == 1 and "softened problem" in line[0] and "not trustworthy" in line[0]
    marker = json.loads((out / PARTIAL_MARKER).read_text())
    assert marker["status"] == "failed" and "softened" in marker["reason"]


@pytest.mark.timeout(120)
def test_a_sweep_records_such_a_run_as_degraded(tmp_path: Path) -> None:
    from tsmpc.sweep import expand, load_sweep, run_task

    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 5.0\n[config.mpc]\ndu_max = [0.001, 0.0001]\n')
    (task,) = expand(load_sweep(sweep))
    rec = run_task(task)
    assert rec["status"] == "degraded" and "softened" in rec["reason"]
