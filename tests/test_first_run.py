"""A first run that explains itself (issue 37 item 3): the engine's compile step says when it
ends, the quick start can be run twice (an earlier complete result is moved aside, never lost),
the printed tables fit 80 columns and say where each method was timed, one time-series format
by default (.mat on request), a default GIF under 3 MB."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.report.tables import factor_cell, time_cell, timed_in_note

runner = CliRunner()


# -- the compile step says when it is done ---------------------------------------------------
def _fake_engine(monkeypatch: pytest.MonkeyPatch, folder: Path) -> list[int]:
    from tsmpc import kernels
    from tsmpc.sim import engine

    calls: list[int] = []
    monkeypatch.setattr(engine, "enabled", lambda: True)
    monkeypatch.setattr(engine, "_load_kernel", lambda: object())
    monkeypatch.setattr(kernels, "_tree_folder", lambda _cache: folder)
    monkeypatch.setattr(engine, "warmup", lambda: calls.append(1) or True)
    return calls


def test_a_cold_engine_compile_ends_with_a_done_line(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path) -> None:
    from tsmpc.cli.compare import _compile_engine

    calls = _fake_engine(monkeypatch, tmp_path)
    said: list[str] = []
    _compile_engine(said.append)
    assert calls == [1]
    assert len(said) == 1 and re.fullmatch(r"tsmpc: run engine compiled … done in \d+ s \(later runs "
                                           r"load it from the cache\)", said[0]), said


def test_a_warm_engine_cache_compiles_nothing_and_says_nothing(monkeypatch: pytest.MonkeyPatch,
                                                               tmp_path: Path) -> None:
    from tsmpc.cli.compare import _compile_engine

    calls = _fake_engine(monkeypatch, tmp_path)
    (tmp_path / "engine.run-123.py311.nbi").write_bytes(b"")
    said: list[str] = []
    _compile_engine(said.append)
    assert calls == [] and said == []


def test_the_compile_step_runs_one_step_of_the_run_itself(monkeypatch: pytest.MonkeyPatch) -> None:
    """The CLI compiles the engine with one MPC step of the run's own config, scenario and designs
    (no second design solve for the default config); the method is the first the engine runs."""
    from tsmpc.cli.compare import _one_engine_step
    from tsmpc.config import Config
    from tsmpc.sim import experiment

    exp = experiment.prepare(Config(), ["nl", "ref"], duration=1.0)
    designs = experiment.solve_designs(exp.config)
    calls = []
    import tsmpc.sim.simulator as sim

    real = sim.simulate

    def spy(cfg, method, scenario, **kw):
        calls.append((method.value, scenario.name, kw["max_steps"], kw["engine"],
                      kw["kinematic_design"] is designs[0]))
        return real(cfg, method, scenario, **kw)

    monkeypatch.setattr(sim, "simulate", spy)
    assert _one_engine_step(exp, {"NL": "Python", "REF": "engine"}, designs) is True
    assert calls == [("REF", exp.scenario.name, 1, True, True)]


# -- the quick start twice ------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_same_out_twice_moves_the_earlier_result_aside_and_keeps_it(tmp_path: Path) -> None:
    out = tmp_path / "results" / "compare"
    argv = ["run", "--duration", "0.5", "--no-plots", "--out", str(out)]
    first = runner.invoke(app, argv)
    assert first.exit_code == 0, first.output
    # one time-series format by default
    assert (out / "timeseries.npz").is_file() and not (out / "timeseries.mat").exists()
    first_metrics = (out / "metrics.json").read_text()

    second = runner.invoke(app, [*argv, "--seed", "5", "--mat"])
    assert second.exit_code == 0, second.output
    prev = tmp_path / "results" / "compare.prev"
    assert f"moved to {prev}" in second.output
    assert (prev / "metrics.json").read_text() == first_metrics  # the first run, untouched
    assert (out / "timeseries.mat").is_file()  # .mat on request
    second_metrics = (out / "metrics.json").read_text()
    assert json.loads(second_metrics)["scenario"]["seed"] == 5

    third = runner.invoke(app, argv)
    assert third.exit_code == 0, third.output
    prev2 = tmp_path / "results" / "compare.prev-2"
    assert (prev / "metrics.json").read_text() == first_metrics  # never replaced
    assert (prev2 / "metrics.json").read_text() == second_metrics
    assert (prev2 / "timeseries.mat").is_file()


@pytest.mark.parametrize("extra", ["notes.txt", "PARTIAL"])
def test_a_folder_with_anything_else_or_an_unfinished_run_is_still_refused(tmp_path: Path,
                                                                         extra: str) -> None:
    out = tmp_path / "compare"
    out.mkdir()
    (out / "metrics.json").write_text("{}")
    (out / "rmse.csv").write_text("approach\n")
    (out / extra).write_text("mine\n")
    res = runner.invoke(app, ["run", "--duration", "0.5", "--no-plots", "--out", str(out)])
    assert res.exit_code == 2 and "folder is not empty" in res.output, res.output
    assert sorted(p.name for p in out.iterdir()) == sorted(["metrics.json", "rmse.csv", extra])
    assert not (tmp_path / "compare.prev").exists()


def test_move_aside_never_replaces_a_kept_result(tmp_path: Path) -> None:
    from tsmpc.cli._outdir import move_aside

    for n in range(3):
        out = tmp_path / "r"
        out.mkdir()
        (out / "metrics.json").write_text(str(n))
        move_aside(out)
    assert (tmp_path / "r.prev" / "metrics.json").read_text() == "0"
    assert (tmp_path / "r.prev-2" / "metrics.json").read_text() == "1"
    assert (tmp_path / "r.prev-3" / "metrics.json").read_text() == "2"


# -- tables within 80 columns, saying where each method was timed ---------------------------
def _metrics(names: list[str]) -> dict:
    rng = np.random.default_rng(0)

    def ms(scale: float) -> dict:
        return {k: float(scale * rng.uniform(0.5, 3)) for k in ("median", "p95", "p99", "max")}

    comfort = {"lat_accel_max": 2.01, "lat_accel_rms": 0.753, "lat_jerk_max": 123.456,
               "lat_jerk_rms": 0.141, "lon_jerk_max": 1234.5, "lon_jerk_rms": 22.6,
               "steering_rate_max": 0.027, "steering_rate_rms": 0.0029, "force_rate_max": 60400.0,
               "force_rate_rms": 2380.0, "settling_time_s": float("inf")}
    methods = {}
    for i, n in enumerate(names):
        methods[n] = {
            "rmse": {k: 0.0123 for k in ("x", "y", "theta", "v", "omega")},
            "mpc_ms": ms(0.003 if n in ("FZN", "REF", "ITER") else 2.0 * (i + 1)),
            "mhe_ms": ms(0.01), "mpc_ms_ratio_to_REF": 976.4 if n == "NL" else 1.04,
            "max_abs_lateral_m": 0.0123, "friction_rmse_N": 159.2, "realtime_factor": 965.3,
            "events": {"mpc_scheduling_clipped": 12, "friction_steps": 2},
            "termination": "completed", "status": "completed", "comfort": comfort}
    methods["ITER"]["status"] = "diverged"
    methods["ITER"]["termination"] = "diverged at 12.3 s: |e_y| = 3.2 m beyond the bound"
    return {"methods": methods, "scenario": {"name": "builtin-circuit", "paper_reference": False}}


def test_the_printed_tables_fit_80_columns_and_say_where_each_method_was_timed() -> None:
    from rich.console import Console

    from tsmpc.cli.compare import _print_tables

    names = ["FZN", "REF", "ITER", "NL", "pure_pursuit", "stanley", "lqr", "ltv"]
    buf = io.StringIO()
    con = Console(file=buf, width=80, emoji=False, color_system=None)
    timed = {n: "engine" if n in ("FZN", "REF", "ITER") else "Python" for n in names}
    _print_tables(con, _metrics(names), timed)
    text = buf.getvalue()
    lines = text.splitlines()
    assert max(len(ln) for ln in lines) <= 80, max(lines, key=len)
    assert "…" not in text  # no cell cut short (rich's ellipsis when a column does not fit)
    for cell in ("2.01", "0.753", "1234.5", "0.0029", "60.4", "2.38", "never", "976×", "965×"):
        assert cell in text, cell
    words = " ".join(text.split())  # the note wraps at 80 columns
    assert re.search(r"inside the compiled run engine: FZN, REF, ITER; in the Python loop[^:]*: NL, "
                     r"pure_pursuit, stanley, lqr, ltv\.", words), text


@pytest.mark.parametrize(("ms", "cell"), [(0.00297, "2.97 µs"), (0.366, "366 µs"), (2.07, "2.07 ms"),
                                          (12.34, "12.3 ms"), (1250.0, "1.25 s"),
                                          (float("nan"), "—"), (None, "—")])
def test_time_cells_carry_their_unit_in_at_most_seven_characters(ms: float | None, cell: str) -> None:
    assert time_cell(ms) == cell and len(cell) <= 7


def test_factor_cells_and_the_timing_note() -> None:
    assert [factor_cell(x) for x in (976.4, 1.04, float("nan"))] == ["976×", "1.0×", "—"]
    assert timed_in_note({}) == ""
    one = timed_in_note({"REF": "engine"})
    assert one == "Times measured inside the compiled run engine: REF."


# -- the default GIF ------------------------------------------------------------------------
def test_the_default_animation_has_at_most_max_frames(monkeypatch: pytest.MonkeyPatch,
                                                      tmp_path: Path) -> None:
    """A race-track run of 4115 MPC steps (Monza at 14.7 m/s) renders MAX_FRAMES frames at most
    by default, every step with ``every=1``."""
    from PIL import Image

    from tsmpc.report import animation

    seen: list[int] = []

    def fake_render(log, steps, *a, **k):
        seen.append(len(steps))
        for _ in steps[:3]:
            yield Image.new("RGB", (40, 30), "white")

    class Log:
        Tc, n_outer, simulated_s = 0.1, 4115, 411.5

    monkeypatch.setattr(animation, "_render", fake_render)
    animation.animate_run(Log(), tmp_path / "a.gif", mp4=False)  # type: ignore[arg-type]
    animation.animate_run(Log(), tmp_path / "b.gif", mp4=False, every=1)  # type: ignore[arg-type]
    assert seen[0] <= animation.MAX_FRAMES and seen[0] >= animation.MAX_FRAMES * 0.8
    assert seen[1] == 4115


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_default_gif_frame_is_small_enough_for_3_mb(tmp_path: Path) -> None:
    """GIF bytes per frame at the default size, colours and encoding, on 60 frames of a run:
    MAX_FRAMES of them fit 3 MB (measured 3.2 kB a frame on the built-in circuit, 4.4 kB on
    Monza with its borders: 1.4 MB and 1.6 MB for the whole default GIFs; 12 kB a frame before
    the palette was trimmed)."""
    from tsmpc.config import Config
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.report.animation import MAX_FRAMES, animate_run
    from tsmpc.sim.simulator import Method, Scenario, simulate

    cfg = Config()
    log = simulate(cfg, Method.REF, Scenario("builtin", builtin_circuit(dt=cfg.rates.Tc)),
                   max_steps=120)
    res = animate_run(log, tmp_path / "a.gif", mp4=False, start_s=6.0, every=1, road_width=6.0)
    assert res.gif is not None and res.frames == 60
    per_frame = res.gif.stat().st_size / res.frames
    assert per_frame * MAX_FRAMES < 3e6, per_frame
