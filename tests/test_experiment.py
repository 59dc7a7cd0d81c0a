"""One pipeline (issue 20): ``tsmpc run`` / ``compare`` are thin shells over
:mod:`tsmpc.sim.experiment`, so the same inputs through the library give the same metrics.json;
the envelope is fitted and the designs certified by the library, with status lines that say
"solving…" before and "certified (margin …)" only after the check."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config
from tsmpc.errors import DesignError, TsmpcError
from tsmpc.sim import experiment

#: metrics.json entries that measure the machine, not the run (wall times, versions).
_TIMING = ("mpc_ms", "mhe_ms", "lqr_ms", "wall_s", "realtime_factor", "mpc_ms_ratio_to_REF")


def _strip(metrics: dict) -> dict:
    out = {k: v for k, v in metrics.items() if k != "versions"}
    out["methods"] = {n: {k: v for k, v in m.items() if k not in _TIMING}
                      for n, m in metrics["methods"].items()}
    return out


@pytest.mark.slow
def test_library_call_reproduces_the_cli_metrics_on_a_widened_fast_plan(
        tracks_dir: Path, tmp_path: Path) -> None:
    """Monza planned at 25 m/s, 6 m/s² leaves the default boxes: both paths widen them, certify
    the designs and write the same metrics.json (timings aside), bit for bit."""
    plan = tmp_path / "monza25.csv"
    res = CliRunner().invoke(app, ["plan", str(tracks_dir / "Monza.csv"), "--v-max", "25",
                                   "--a-lat", "6", "--out", str(plan)])
    assert res.exit_code == 0, res.output
    cli_out = tmp_path / "cli"
    res = CliRunner().invoke(app, ["run", "--reference", str(plan), "--duration", "40",
                                   "--no-plots", "--out", str(cli_out), "--seed", "4"])
    assert res.exit_code == 0, res.output
    assert "scheduling boxes widened" in res.output
    lines: list[str] = []
    exp = experiment.prepare(Config(), ["ref"], reference=plan, duration=40.0, seed=4)
    assert exp.envelope.widened and exp.config.dynamic_box.v[1] >= 25.0
    result = experiment.run(exp, tmp_path / "lib", plots=False, status=lines.append)
    cli = json.loads((cli_out / "metrics.json").read_text())
    lib = json.loads((tmp_path / "lib" / "metrics.json").read_text())
    assert _strip(cli) == _strip(lib)
    assert _strip(result.metrics) == _strip(lib)
    # status: a "solving"/"loading" line before each design, "certified ... margin" after
    assert len(lines) == 4 and "certified" not in lines[0] and "certified" not in lines[2]
    assert "certified" in lines[1] and "margin" in lines[1] and "certified" in lines[3]


def test_prepare_validates_before_any_work(tmp_path: Path) -> None:
    with pytest.raises(TsmpcError, match="unknown method"):
        experiment.prepare(Config(), ["refx"])
    with pytest.raises(TsmpcError, match="allowed: tsmpc, commonroad-st"):
        experiment.prepare(Config(), ["ref"], plant="carla")
    with pytest.raises(TsmpcError, match="duration"):
        experiment.prepare(Config(), ["ref"], duration=0.0)
    assert not any(tmp_path.iterdir())


def test_a_config_without_a_certified_design_is_a_design_error(tmp_path: Path, monkeypatch) -> None:
    """A box no common Lyapunov matrix covers: DesignError (an input error: exit 2) naming the
    LMI, where it fails and the settings that would help; the CLI says so in one line.

    The infeasible SDP is solved once (~8 s of CPU): the CLI, given the same box in a TOML file,
    gets the solver's answer replayed for that design key (any other key is solved for real), so
    its own path — the file, the config, solve_designs, the diagnosis, exit 2 — is the real one.
    tests/test_design_failures.py runs real infeasible designs through the CLI."""
    from tsmpc.config import replace
    from tsmpc.synthesis import cache

    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "cache"))
    cfg = Config()
    # down to 0.2 m/s the 1/v terms leave no common Lyapunov matrix (SPEC §5's low-speed floor)
    bad = replace(cfg, dynamic_box=replace(cfg.dynamic_box, v=(0.2, 20.0)))
    solve = cache.load_or_design_dynamic
    raised: dict[str, Exception] = {}
    replayed: list[str] = []

    def once(c: Config, *args, **kwargs):
        key = cache.dynamic_key(c)
        if key in raised:
            replayed.append(key)
            raise raised[key]
        try:
            return solve(c, *args, **kwargs)
        except Exception as err:
            raised[key] = err
            raise

    monkeypatch.setattr(cache, "load_or_design_dynamic", once)
    with pytest.raises(DesignError, match=r"no certified dynamic LMI design .*dynamic_box.*"
                       r"v = 0\.20 m/s is added.*narrow dynamic_box\.v"):
        experiment.solve_designs(bad)
    assert list(raised) == [cache.dynamic_key(bad)]
    f = tmp_path / "bad.toml"
    f.write_text("[dynamic_box]\nv = [0.2, 20.0]\n", encoding="utf-8")
    res = CliRunner().invoke(app, ["run", "--config", str(f), "--duration", "1", "--out",
                                   str(tmp_path / "o")])
    assert res.exit_code == 2 and "no certified dynamic LMI design" in res.output
    assert "Traceback" not in res.output
    assert replayed == [cache.dynamic_key(bad)]  # the CLI's config is the library's
