"""``tsmpc compare`` (the paper's comparison) and ``tsmpc run`` (one method, one scenario)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import (
    EXIT_DEGRADED,
    PARTIAL_MARKER,
    check_environment,
    check_interrupted,
    check_laps,
    check_out_dir,
    check_scenario_options,
    data_path,
    deferred_interrupts,
    design_status,
    fail,
    finite,
    guarded_run,
    load_config_or_exit,
    mark_partial,
)
from tsmpc.errors import ConfigError, TsmpcError


def _parse_window(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        a, b = (int(v) for v in text.split(","))
    except ValueError:
        fail(ConfigError(f"--window must be 'FIRST,LAST' (1-based columns), got {text!r}"))
    if not 1 <= a < b:
        fail(ConfigError(f"--window {a},{b}: need 1 <= FIRST < LAST (1-based columns)"))
    return a, b


#: Files a compare/run writes into --out (figures: FIGURES names as .png and .pdf).
_OUTPUT_FILES = ("metrics.json", "rmse.csv", "rmse.md", "rmse.tex", "comfort.csv", "comfort.md",
                 "config.toml", "versions.json",
                 "timeseries.npz", "timeseries.mat", "report.html", PARTIAL_MARKER)


def _is_output(p: Path) -> bool:
    """A file a compare/run (or ``tsmpc animate`` of it) writes into its folder."""
    figures: Any = ()  # no [report] extra: this install writes no figures
    with contextlib.suppress(ImportError):
        from tsmpc.report.figures import FIGURES as figures
    return p.is_file() and (p.name in _OUTPUT_FILES
                            or (p.suffix in (".png", ".pdf") and p.stem in figures)
                            or (p.suffix in (".gif", ".mp4") and p.stem.startswith("animation_")))


def _remove_previous_outputs(out: Path) -> None:
    """--overwrite: remove tsmpc's files of an earlier run (never anything else) so the folder
    never mixes new and stale results."""
    for p in out.iterdir():
        if _is_output(p):
            p.unlink()


def _holds_previous_result(out: Path) -> bool:
    """``out`` holds the complete result of an earlier compare/run: its ``metrics.json``, no
    PARTIAL marker (an unfinished run is not moved aside: the user decides) and nothing but
    tsmpc's output files (a folder with anything else is refused as before)."""
    try:
        if not out.is_dir() or out.resolve() in (Path.cwd().resolve(), *Path.cwd().resolve().parents):
            return False
        entries = [p for p in out.iterdir() if not p.name.startswith(".tsmpc-probe-")]
    except OSError:
        return False
    names = {p.name for p in entries}
    return "metrics.json" in names and PARTIAL_MARKER not in names and all(map(_is_output, entries))


def _timed_in(exp: Any) -> dict[str, str]:
    """Where each method's per-step times are measured: "engine" (inside the compiled run engine,
    :mod:`tsmpc.sim.engine`: FZN, REF, ITER when it applies) or "Python" (the Python loop, with
    its call overhead: NL, the baselines, and any case the engine does not run)."""
    from tsmpc.sim import engine

    plant = None if exp.plant == "tsmpc" else exp.plant
    return {m.value: "engine" if engine.enabled() and engine.applicability(
        exp.config, m, exp.scenario, oracle=exp.oracle, plant=plant) is None else "Python"
        for m in exp.methods}


def _one_engine_step(exp: Any, timed_in: dict[str, str], designs: tuple[Any, Any]) -> bool:
    """One MPC step of this run's first engine method through the engine: compiles it."""
    from tsmpc.sim.simulator import simulate

    method = next(m for m in exp.methods if timed_in.get(m.value) == "engine")
    simulate(exp.config, method, exp.scenario, oracle=exp.oracle, max_steps=1, engine=True,
             kinematic_design=designs[0], dynamic_design=designs[1])
    return True


def _compile_engine(say: Any, warm: Any = None) -> None:
    """Compile the run engine before the progress bars when its cache is cold, and say when that
    ends and how long it took (the engine's own line says it starts: "compiling the run engine
    (first run only)…"). ``warm()`` compiles it (default :func:`tsmpc.sim.engine.warmup`; the
    CLI passes one MPC step of the run itself, whose designs are solved already). A warm cache
    costs nothing here."""
    import time

    from tsmpc.sim import engine

    if engine.cached() is not False:  # unavailable, or compiled before: loaded on the first run
        return
    t0 = time.perf_counter()
    ok = (warm or engine.warmup)()
    seconds = time.perf_counter() - t0
    say(f"tsmpc: run engine compiled … done in {seconds:.0f} s (later runs load it from the cache)"
        if ok else f"tsmpc: the run engine could not be compiled ({seconds:.0f} s): the Python loop runs")


def _consoles() -> tuple[Any, Any]:
    """(stdout console, stderr console); 140 columns when stdout is piped to a file or CI log.
    User strings are escaped where printed (markup)."""
    from rich.console import Console

    console = Console(emoji=False)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console = Console(width=140, emoji=False)
    return console, Console(stderr=True, highlight=False, soft_wrap=True)


def _load_config(config: Path | None, preset: str | None, sets: list[str] | None, *,
                 duration: float | None, dt: float | None, seed: int | None) -> Any:
    """The numeric options checked, then the config (``--config``/``--preset``, ``--set`` over it)."""
    finite("--duration", duration, lo=0.1)
    finite("--dt", dt, lo=1e-4)
    if seed is not None and seed < 0:
        fail(ConfigError(f"--seed = {seed}: must be an integer >= 0"))
    cfg = load_config_or_exit(config, preset)
    if sets:  # --set KEY=VALUE over the config (issue 21: the scenario vocabulary on the CLI)
        from tsmpc.config import apply_overrides

        try:
            cfg = apply_overrides(cfg, list(sets))
        except TsmpcError as err:
            fail(err)
    return cfg


def _prepare(cfg: Any, methods_text: str, *, reference: Path | None, window: str | None, laps: int,
             no_plots: bool, **options: Any) -> Any:
    """The methods, the reference, the memory bound and the experiment (``options``: the rest of
    :func:`tsmpc.sim.experiment.prepare`'s), every one checked before any work."""
    import tsmpc.cli._memory as _memory  # memory bound (issue 38): the file's size and samples, then the run
    from tsmpc.sim import experiment

    methods = [m for m in methods_text.split(",") if m.strip()]
    if not methods:
        fail(ConfigError("--methods is empty"))
    check_laps(laps)
    reference = data_path(reference, "--reference")  # `--reference paper`: a downloaded dataset
    problem = _memory.reference_problem(
        reference, methods=methods, duration=options["duration"], window=_parse_window(window), laps=laps,
        Tc=cfg.rates.Tc, Td=cfg.rates.Td, horizon=cfg.mpc.N)
    if problem is not None:
        fail(ConfigError(problem))
    try:
        exp = experiment.prepare(cfg, methods, reference=reference, window=_parse_window(window), laps=laps,
                                 **options)
    except (TsmpcError, OSError) as err:
        fail(err)
    check_scenario_options(exp.scenario, reference=reference, laps=laps, plant=options["plant"])
    problem = _memory.experiment_problem(exp)
    if problem is not None:
        fail(ConfigError(problem))
    _check_extras(exp, plots=not no_plots)
    return exp


def _claim_out(out: Path | None, *, overwrite: bool, command: str, err_console: Any) -> Path:
    """The output folder: a new one by default (never another run's, issue 23); an earlier complete
    result in ``out`` moved aside (the quick start, run again: docs/outputs.md); then checked."""
    if out is None:
        from tsmpc.cli._outdir import claim_default_out

        out = claim_default_out(command)
        err_console.print(f"output folder: {out}", markup=False)
    elif not overwrite and _holds_previous_result(out):
        from tsmpc.cli._outdir import move_aside

        try:
            moved = move_aside(out)
        except OSError as err:
            fail(ConfigError(f"--out {out}: holds an earlier result that cannot be moved aside "
                             f"({err.strerror or err}); choose another folder or pass --overwrite"))
        err_console.print(f"the earlier result in {out} was moved to {moved}", markup=False)
    check_out_dir(out, overwrite=overwrite)
    return out


def _compile_first(exp: Any, designs: tuple[Any, Any], err_console: Any) -> dict[str, str]:
    """Load (or, on a cold cache, compile) the kernels and the run engine before the progress
    bars, the first run saying so; where each method is timed (:func:`_timed_in`)."""
    from tsmpc import kernels

    with deferred_interrupts():  # numba/LLVM call back into Python: never raise in there
        timed_in = _timed_in(exp)  # may load (or, on a cold cache, compile) the kernels
        kernels.warmup()
        if "engine" in timed_in.values():  # and the run engine, saying when it is done
            _compile_engine(lambda text: err_console.print(text, markup=False),
                            lambda: _one_engine_step(exp, timed_in, designs))
    return timed_in


def _run_with_progress(console: Any, exp: Any, out: Path, designs: tuple[Any, Any], *, no_plots: bool,
                       mat: bool) -> Any:
    """Run the experiment into ``out`` under one progress bar per method."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from tsmpc.sim import experiment

    with Progress(TextColumn("[bold]{task.description:>5}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total} MPC steps"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console) as progress:

        def factory(name: str, total: int) -> Any:
            task = progress.add_task(name, total=total)

            def update(k: int, _k_total: int) -> None:
                check_interrupted()  # a solver may have swallowed the signal
                progress.update(task, completed=k)
            return update

        # The loop's blocks call compiled code: a signal only sets a flag there, checked
        # after every MPC step (check_interrupted in the progress callback).
        with deferred_interrupts():
            return experiment.run(exp, out, plots=not no_plots, progress_factory=factory,
                                  designs=designs, mat=mat)


def _report(console: Any, out: Path, result: Any, timed_in: dict[str, str]) -> None:
    """The tables and the files written; a method whose controller did not work marks the folder
    failed (exit 1); else the PARTIAL marker goes (unless interrupted meanwhile)."""
    from rich.markup import escape

    _print_tables(console, result.metrics, timed_in)
    console.print(f"wrote {len(result.files)} files to [bold]{escape(str(out))}[/bold]")
    sick = _unhealthy(result.metrics)
    if sick:
        mark_partial(out, "failed", reason="; ".join(sick))
        fail("; ".join(sick), code=1)
    check_interrupted()
    (out / PARTIAL_MARKER).unlink(missing_ok=True)


def _exit_status(metrics: dict[str, Any]) -> None:
    """Exit 1 when a method did not complete; exit 3 (one line) when the results are written but
    the car could not do what the plan asked."""
    bad = [n for n, m in metrics["methods"].items() if m["termination"] != "completed"]
    if bad:
        raise typer.Exit(1)
    degraded = [f"{n}: {m['degraded']}" if len(metrics["methods"]) > 1 else m["degraded"]
                for n, m in metrics["methods"].items() if m.get("status") == "degraded"]
    if degraded:
        with contextlib.suppress(OSError, ValueError):
            typer.secho("; ".join(degraded), err=True, fg=typer.colors.YELLOW)
        raise typer.Exit(EXIT_DEGRADED)


def _execute(
    methods_text: str, *, reference: Path | None, window: str | None, out: Path | None,
    seed: int | None,
    config: Path | None, no_plots: bool, oracle: bool, duration: float | None, robustness: str = "nominal",
    overwrite: bool = False, preset: str | None = None,
    laps: int = 1, dt: float | None = None, strict_box: bool = False, strict_plan: bool = False,
    plant: str = "tsmpc", cr_vehicle: int = 2, command: str = "compare",
    sets: list[str] | None = None, mat: bool = False,
) -> None:
    """The body of ``compare`` and ``run``: a thin shell over :mod:`tsmpc.sim.experiment`
    (``prepare`` validates every input before any work, ``run`` solves the designs and runs).
    The options arrive by name (the commands pass their parameters, which carry the same names),
    so adding an option cannot shift the others."""
    from tsmpc.blas import limit_blas_threads

    check_environment()  # cache folders, BLAS threads: before any work
    limit_blas_threads()
    console, err_console = _consoles()
    # Every input is checked before any work: options, config, reference, envelope, output folder.
    cfg = _load_config(config, preset, sets, duration=duration, dt=dt, seed=seed)
    exp = _prepare(cfg, methods_text, reference=reference, window=window, laps=laps, no_plots=no_plots,
                   dt=dt, robustness=robustness, duration=duration, seed=seed, plant=plant,
                   cr_vehicle=cr_vehicle, strict_box=strict_box, oracle=oracle, strict_plan=strict_plan)
    out = _claim_out(out, overwrite=overwrite, command=command, err_console=err_console)
    if exp.envelope.widened:
        console.print(exp.envelope.message, markup=False, highlight=False)
    if exp.plan_note:  # the plan exceeded the vehicle's limits: capped (or the published one, exempt)
        console.print(exp.plan_note, markup=False, highlight=False, soft_wrap=True)  # one line

    # Every ending that is not success is one line, a non-zero exit and PARTIAL saying why
    # (interrupted, no design for this config: exit 2, a failed write, an unexpected error).
    with guarded_run(out, on_interrupt=f"{out} holds a partial run: the methods that had finished "
                     f"are written (see {out / PARTIAL_MARKER})"):
        if overwrite:
            _remove_previous_outputs(out)
        mark_partial(out, "running", methods=[m.value for m in exp.methods])
        designs = design_status(exp.config)  # no design for this config: DesignError (exit 2)
        timed_in = _compile_first(exp, designs, err_console)
        result = _run_with_progress(console, exp, out, designs, no_plots=no_plots, mat=mat)
        _report(console, out, result, timed_in)
    _exit_status(result.metrics)


def _unhealthy(metrics: dict[str, Any]) -> list[str]:
    """A method that completed but whose controller did not work (tsmpc.sim.health)."""
    from tsmpc.sim.health import health_problem

    out = []
    for name, m in metrics["methods"].items():
        problem = health_problem(m) if m["termination"] == "completed" else None
        if problem:
            out.append(f"{name}: {problem}")
    return out


def _check_extras(exp: Any, *, plots: bool) -> None:
    """Before any work: the optional dependencies this run needs are installed, else exit 2 with
    the install line of their extra (tsmpc.extras)."""
    from tsmpc.config import Method
    from tsmpc.extras import is_available, missing_message

    if Method.NL in exp.methods and not is_available("casadi"):
        fail(ConfigError(missing_message("casadi", "method nl (NL-MPC)") + "; or leave nl out of --methods"))
    if plots and not is_available("matplotlib"):
        fail(ConfigError(missing_message("matplotlib", "the figures") + "; or pass --no-plots"))


def _print_tables(console: Any, metrics: dict[str, Any], timed_in: dict[str, str] | None = None) -> None:
    """The RMSE, timing, tracking and comfort tables, each within 80 columns (compact units,
    short two-line heads); ``timed_in`` (method -> "engine" or "Python") says under the timing
    table where each method's times were measured."""
    from rich.markup import escape
    from rich.table import Table

    from tsmpc.report.tables import factor_cell, rmse_rows, time_cell, timed_in_note

    paper = bool(metrics["scenario"].get("paper_reference"))
    t = Table(title=f"RMSE — {escape(str(metrics['scenario']['name']))}"
              + (" (paper rows from Table 5)" if paper else ""))
    for col in ("approach", "x [m]", "y [m]", "θ [rad]", "v [m/s]", "ω [rad/s]"):
        t.add_column(escape(col), justify="right" if col != "approach" else "left")
    for label, vals in rmse_rows(metrics, paper):
        if label.endswith("(diverged)"):  # never RMSEs as if the run had completed
            t.add_row(label, *(["diverged"] + ["—"] * (len(vals) - 1)), style="bold red")
            continue
        style = "dim" if label.endswith("(paper)") else None
        t.add_row(label, *(f"{v:.3f}" for v in vals), style=style)
    console.print(t)
    tt = Table(title="Per-step solve times (median, p99, max)")
    for col in ("method", "MPC\nmedian", "MPC\np99", "MPC\nmax", "MPC\n×REF", "MHE\nmedian",
                "MHE\np99"):
        tt.add_column(escape(col), justify="right" if col != "method" else "left", no_wrap=True)
    for name, m in metrics["methods"].items():
        if m.get("status") == "diverged":  # timings of a run cut short are not comparable
            tt.add_row(name, *(["—"] * 6), style="bold red")
            continue
        mpc, mhe = m["mpc_ms"], m["mhe_ms"]
        tt.add_row(name, time_cell(mpc["median"]), time_cell(mpc["p99"]), time_cell(mpc["max"]),
                   factor_cell(m.get("mpc_ms_ratio_to_REF")), time_cell(mhe["median"]),
                   time_cell(mhe["p99"]))
    console.print(tt)
    note = timed_in_note({n: w for n, w in (timed_in or {}).items() if n in metrics["methods"]})
    if note:
        console.print(note, markup=False, highlight=False)
    tr = Table(title="Tracking, friction estimate, real time")
    for col in ("method", "max |e_y|\n[m]", "F̂ RMSE\n[N]", "real-time\nfactor", "events"):
        tr.add_column(escape(col), justify="right" if col not in ("method", "events") else "left",
                      no_wrap=True)
    for name, m in metrics["methods"].items():
        ev = "\n".join(([f"behind plan {m['plan_delay_s']:.1f} s"] if m.get("plan_delay_s") else [])
                       + [f"{k}={v}" for k, v in m["events"].items() if v]) or "-"
        if m.get("status") == "diverged":
            tr.add_row(name, f"{m['max_abs_lateral_m']:.3f}", "—", "—", ev, style="bold red")
            continue
        tr.add_row(name, f"{m['max_abs_lateral_m']:.3f}", f"{m['friction_rmse_N']:.0f}",
                   factor_cell(m["realtime_factor"]), ev)
    console.print(tr)
    _print_comfort(console, metrics)
    for name, m in metrics["methods"].items():
        if m.get("max_abs_lateral_per_lap_m"):
            laps = ", ".join(f"{v:.3f}" for v in m["max_abs_lateral_per_lap_m"])
            console.print(f"{name}: max |e_y| per lap [m]: {laps}", markup=False)
        if m["termination"] != "completed":
            console.print(f"[red]{name}: {escape(m['termination'])}[/red]")


def _print_comfort(console: Any, metrics: dict[str, Any]) -> None:
    """The comfort and effort tables (tsmpc.sim.comfort) below the timing tables: two tables of
    at most six values with short heads, so each fits 80 columns."""
    from rich.markup import escape
    from rich.table import Table

    from tsmpc.report.tables import COMFORT_COLUMNS, COMFORT_CONSOLE, comfort_cell, comfort_rows

    index = {key: i for i, (key, _, _) in enumerate(COMFORT_COLUMNS)}
    rows = comfort_rows(metrics)
    for title, columns in COMFORT_CONSOLE:
        t = Table(title=escape(title))
        t.add_column("method", overflow="fold")  # "ITER (diverged)" wraps: the values never do
        for _, head in columns:
            t.add_column(escape(head), justify="right", no_wrap=True)
        for label, vals in rows:
            cells = [comfort_cell(vals[index[k]], COMFORT_COLUMNS[index[k]][2]) for k, _ in columns]
            t.add_row(label, *cells, style="bold red" if label.endswith("(diverged)") else None)
        console.print(t)


_SCENARIO_HELP = ("Robustness scenario: nominal, ice_patch, wet_section, noise_x10, sensor_dropout, "
                  "nan_bursts, mass_stiffness_mismatch, stiffness_mismatch, offset_start, actuator_lag (see "
                  "tsmpc.robustness).")
_PLANT_HELP = ("Plant: tsmpc (the built-in nonlinear single-track), commonroad-st or commonroad-mb "
               "(CommonRoad's single-track / multi-body model behind a steering servo; needs the "
               "[commonroad] extra).")
_PRESET_HELP = ("Named configuration under --config: 'default' (our best cascade), 'paper' (the cascade "
                "as published: no speed-error feedback, the paper's UIO friction estimate) or "
                "'paper-as-run' (the published run's quirks: not a recommendation).")
_STRICT_HELP = ("Refuse a reference that leaves the designs' scheduling boxes (default: widen the boxes "
                "by a margin and re-solve and re-certify the designs, cached).")
_STRICT_PLAN_HELP = ("Refuse a reference whose lateral acceleration or acceleration exceeds the "
                     "vehicle's grip or force budget (with their margins; docs/planning.md) instead of "
                     "capping its speed profile along the same path.")
_DT_HELP = ("Column period [s] of a paper-format file (default: measured from the data; a value the "
            "data contradict is refused).")
_LAPS_HELP = "Laps of a closed track (a planned track CSV); the look-ahead wraps around the lap."
_REF_HELP = ("Reference: a paper-format file (6 rows; the paper-run window 5..1316 is used unless "
             "--window says otherwise), a planned CSV (t,x,y,theta,v,omega,kappa) or 'paper' (the "
             "paper's reference: tsmpc data fetch paper). Default: the built-in paper-like circuit.")


# Options shared by ``compare`` and ``run`` (one definition, two commands).
_OPT_REFERENCE = typer.Option(None, "--reference", help=_REF_HELP)
_OPT_WINDOW = typer.Option(None, "--window", help="1-based FIRST,LAST: columns of a paper file, "
                           "rows of a planned CSV.")
_OPT_SEED = typer.Option(None, "--seed", help="Seed of the sensor noise, >= 0 (default: config).")
_OPT_CONFIG = typer.Option(None, "--config", help="TOML config file.")
_OPT_NO_PLOTS = typer.Option(False, "--no-plots", help="Skip the figures.")
_OPT_ORACLE = typer.Option(False, "--oracle", help="Ablation: the inner loop gets the true state, "
                           "no friction compensation.")
_OPT_DURATION = typer.Option(None, "--duration", help="Track only the first S s (finite, >= 0.1).")
_OPT_SCENARIO = typer.Option("nominal", "--scenario", help=_SCENARIO_HELP)
_OPT_PRESET = typer.Option(None, "--preset", help=_PRESET_HELP)
_OPT_LAPS = typer.Option(1, "--laps", min=1, help=_LAPS_HELP)
_OPT_DT = typer.Option(None, "--dt", help=_DT_HELP)
_OPT_STRICT = typer.Option(False, "--strict-box", help=_STRICT_HELP)
_OPT_STRICT_PLAN = typer.Option(False, "--strict-plan", help=_STRICT_PLAN_HELP)
_OPT_PLANT = typer.Option("tsmpc", "--plant", help=_PLANT_HELP)
_OPT_CR_VEHICLE = typer.Option(2, "--cr-vehicle", help="CommonRoad parameter set (1, 2, 3).")
_OPT_OVERWRITE = typer.Option(False, "--overwrite", help="Write into a non-empty --out folder, "
                              "replacing tsmpc's outputs of an earlier run (other files are kept).")
_OPT_MAT = typer.Option(False, "--mat", help="Also write the time series as timeseries.mat (MATLAB); "
                        "timeseries.npz is always written.")
_OPT_SET = typer.Option(None, "--set", help="KEY=VALUE over the config, repeatable: a dotted field "
                        "and a TOML value, e.g. --set scenario.plant.mass_scale=1.2 --set "
                        "scenario.sensors.dropout_probability=0.05 (docs/mismatch.md).")


@app.command("compare")
def compare_cmd(
    reference: Path | None = _OPT_REFERENCE,
    window: str | None = _OPT_WINDOW,
    methods: str = typer.Option("fzn,ref,iter,nl", "--methods", help="Comma-separated: fzn,ref,iter,nl "
                                "(TS-MPC modes, NL-MPC) and the baselines pure_pursuit,stanley,lqr,ltv."),
    out: Path | None = typer.Option(None, "--out", help="Output folder (new, empty, or holding an "
                                    "earlier complete result, which is moved to OUT.prev first; "
                                    "default: a new folder results/compare, results/compare-2, …)."),
    seed: int | None = _OPT_SEED,
    config: Path | None = _OPT_CONFIG,
    no_plots: bool = _OPT_NO_PLOTS,
    oracle: bool = _OPT_ORACLE,
    duration: float | None = _OPT_DURATION,
    robustness: str = _OPT_SCENARIO,
    overwrite: bool = _OPT_OVERWRITE,
    preset: str | None = _OPT_PRESET,
    laps: int = _OPT_LAPS,
    dt: float | None = _OPT_DT,
    strict_box: bool = _OPT_STRICT,
    strict_plan: bool = _OPT_STRICT_PLAN,
    plant: str = _OPT_PLANT,
    cr_vehicle: int = _OPT_CR_VEHICLE,
    sets: list[str] | None = _OPT_SET,
    mat: bool = _OPT_MAT,
) -> None:
    """Run the paper's comparison (FZN, REF, ITER, NL) and write tables, data and figures."""
    options = dict(locals())
    _execute(options.pop("methods"), **options)


@app.command("run")
def run_cmd(
    method: str = typer.Option("ref", "--method", help="One of fzn, ref, iter, nl, pure_pursuit, "
                               "stanley, lqr, ltv."),
    reference: Path | None = _OPT_REFERENCE,
    window: str | None = _OPT_WINDOW,
    out: Path | None = typer.Option(None, "--out", help="Output folder (new, empty, or holding an "
                                    "earlier complete result, which is moved to OUT.prev first; "
                                    "default: a new folder results/run, results/run-2, …)."),
    seed: int | None = _OPT_SEED,
    config: Path | None = _OPT_CONFIG,
    no_plots: bool = _OPT_NO_PLOTS,
    oracle: bool = _OPT_ORACLE,
    duration: float | None = _OPT_DURATION,
    robustness: str = _OPT_SCENARIO,
    overwrite: bool = _OPT_OVERWRITE,
    preset: str | None = _OPT_PRESET,
    laps: int = _OPT_LAPS,
    dt: float | None = _OPT_DT,
    strict_box: bool = _OPT_STRICT,
    strict_plan: bool = _OPT_STRICT_PLAN,
    plant: str = _OPT_PLANT,
    cr_vehicle: int = _OPT_CR_VEHICLE,
    sets: list[str] | None = _OPT_SET,
    mat: bool = _OPT_MAT,
) -> None:
    """Run one method on one scenario (same outputs as compare, for one method)."""
    options = dict(locals())
    if "," in method:
        fail(ConfigError("--method takes one method; use `tsmpc compare --methods` for several"))
    _execute(options.pop("method"), command="run", **options)
