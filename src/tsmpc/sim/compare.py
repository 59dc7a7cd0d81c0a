"""The paper's comparison in one call (the paper's comparison): run each method on one scenario, compute
the metrics and write every output file. ``tsmpc compare`` and ``tsmpc run`` are shells over
:func:`compare`."""

from __future__ import annotations

import json
import platform
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from tsmpc.config import Config
from tsmpc.sim.log import RunLog, atomic_write_text, save_logs_mat, save_logs_npz
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.plant import Plant
from tsmpc.sim.simulator import Method, Scenario, simulate, tracked_steps

__all__ = ["CompareResult", "compare", "load_scenario", "versions"]

ProgressFactory = Callable[[str, int], Callable[[int, int], None]]
#: Draws the figures of a comparison into a folder; returns the files (the report layer's).
FigureFn = Callable[[dict[str, RunLog], Path, Config], list[Path]]


@dataclass(frozen=True)
class CompareResult:
    """Metrics (the metrics.json content), the logs by method, and the files written."""

    metrics: dict[str, Any]
    logs: dict[str, RunLog]
    files: tuple[Path, ...]


def versions() -> dict[str, str]:
    """Versions of Python, tsmpc and the numerical dependencies used by a run."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for pkg in ("tsmpc", "numpy", "scipy", "daqp", "clarabel", "cvxpy", "casadi", "pydantic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def load_scenario(
    cfg: Config,
    reference: Path | str | None = None,
    window: tuple[int, int] | None = None,
    *,
    use_paper_window: bool = True,
    laps: int = 1,
    dt: float | None = None,
) -> Scenario:
    """The comparison scenario: the built-in circuit (``reference=None``), a paper-format file
    (the paper-run window of columns 5…1316 unless ``window`` says otherwise) or a planned CSV;
    the paper's time-based friction profile applies in every case. ``laps`` > 1 repeats a closed
    lap (a planned track). A paper-format file's column period is measured (``dt`` given: checked
    against the data); the default window is the paper run's time span at that period, and the
    paper's Table 5 rows go beside ours only for the paper's own run (``paper_reference``).
    ``reference`` may name a dataset (``"paper"``: :func:`tsmpc.datasets.resolve`; not downloaded:
    :class:`~tsmpc.datasets.DataNotFoundError` naming ``tsmpc data fetch``)."""
    from tsmpc.planning.paper_format import (
        is_paper_run,
        load_reference,
        paper_window,
    )
    from tsmpc.scenarios import paper_friction_profile

    if reference is None:
        from tsmpc.planning.circuit import builtin_circuit  # (imports the planner: scipy.interpolate)

        ref = builtin_circuit(dt=cfg.rates.Tc)
        return Scenario("builtin-circuit", ref, paper_friction_profile(),
                        meta={"reference": "builtin-circuit", "paper_reference": False})
    from tsmpc import datasets
    from tsmpc.planning.reference import read_csv_meta

    if not Path(reference).exists() and datasets.is_dataset_name(reference):
        reference = datasets.resolve(str(reference))
    paper = _is_paper_format(Path(reference))
    if paper:  # measure the column period on the whole file, then take the window in it
        full = load_reference(reference, window=None, dt=dt)
        win = window if window is not None else (paper_window(full.dt) if use_paper_window
                                                 else None)
        ref = full if win is None else load_reference(reference, window=win, dt=full.dt)
        paper_run = is_paper_run(full, win, cfg.rates.Tc)
    else:
        win, paper_run = window, False
        ref = load_reference(reference, window=win)
    check_trackable(ref, cfg, str(reference))
    if laps != 1:
        if not ref.closed:
            from tsmpc.errors import DataFormatError

            raise DataFormatError(f"{reference}: --laps {laps} needs a closed lap (a track planned "
                                  "with `tsmpc plan TRACK --out FILE`, no --tail)")
        ref = ref.repeat(laps)
    info = {} if paper else read_csv_meta(reference)
    try:  # a planned track carries its half-width: leaving it is diverging
        bound: float | None = float(info["half_width_m"])
    except (KeyError, ValueError):
        bound = None
    bound = bound if bound is not None and bound > 0 else None
    return Scenario(Path(reference).stem, ref, paper_friction_profile(), divergence_bound_m=bound,
                    meta={"reference": str(reference), "window": list(win) if win else None,
                          "paper_reference": paper_run, "paper_format": paper,
                          "column_period_s": ref.dt, "divergence_bound_m": bound
                          or cfg.divergence_bound_m, "closed": ref.closed, "laps": laps})


def _is_paper_format(path: Path) -> bool:
    """A planned CSV starts with its ``t,x,y,...`` header; the paper's file is 6 numeric rows."""
    from tsmpc.textfile import first_line

    first = first_line(path, "reference")  # an unreadable file is reported here, naming it
    return not first.lower().startswith(("t,", "#"))


def check_trackable(ref: Any, cfg: Config, source: str) -> None:
    """A reference the closed loop can track: more samples than the horizon N (look-ahead),
    moving (v_d > 0). Raises :class:`DataFormatError` naming ``source``."""
    from tsmpc.errors import DataFormatError

    n_min = cfg.mpc.N + 2
    n = int(ref.duration / cfg.rates.Tc + 1e-9) + 1  # samples at T_c (the simulator resamples)
    if n < n_min:
        raise DataFormatError(f"{source}: {n} samples at Tc = {cfg.rates.Tc:g} s; tracking needs at "
                              f"least N + 2 = {n_min} (the MPC looks N = {cfg.mpc.N} steps ahead): "
                              "use a longer reference or a wider --window")
    if ref.v.min() <= 0.0:
        k = int(ref.v.argmin())
        raise DataFormatError(f"{source}: sample {k + 1} of the tracked window has v_d = "
                              f"{ref.v[k]:g} m/s; a tracked reference must move (v_d > 0)")


def _scenario_summary(cfg: Config, sc: Scenario, max_steps: int | None) -> dict[str, Any]:
    ref = sc.reference
    return {
        "name": sc.name,
        "samples": len(ref),
        "duration_s": float(ref.duration),
        "tracked_steps": tracked_steps(ref, cfg.mpc.N) if max_steps is None
        else min(tracked_steps(ref, cfg.mpc.N), max_steps),
        "Tc": cfg.rates.Tc, "Td": cfg.rates.Td, "h": cfg.rates.h,
        "tyre": cfg.tyre.model.value,
        "noise_scale": cfg.noise.scale,
        "seed": cfg.seed,
        "friction": type(sc.friction).__name__,
        **sc.meta,
    }


def compare(
    cfg: Config,
    scenario: Scenario,
    methods: Sequence[Method],
    out_dir: Path | None,
    *,
    plots: bool = True,
    oracle: bool = False,
    max_steps: int | None = None,
    progress_factory: ProgressFactory | None = None,
    plant_factory: Callable[[], Plant] | None = None,
    figures: FigureFn | None = None,
    designs: tuple[Any, Any] | None = None,
    mat: bool = False,
) -> CompareResult:
    """Run ``methods`` on ``scenario`` and write metrics, tables, time series and figures.

    Every method runs from the same seed (same noise sequence) on a fresh plant from
    ``plant_factory`` (None: tsmpc's own plant). Nothing is written when ``out_dir`` is None.
    Files are written atomically. Figures (``plots``) are drawn by ``figures(logs, out_dir, cfg)``;
    None = the report layer's :func:`tsmpc.report.figures.save_all`, imported only then.
    ``designs``: the (kinematic, dynamic) LMI designs of ``cfg`` when the caller has them
    (default: the design cache). A run that stops early (|e_y| beyond the scenario's bound,
    non-finite plant) has ``status`` ``"diverged"``; ``metrics["diverged"]`` lists those methods.
    One that completed beyond the health bounds (:func:`tsmpc.sim.health.degradation`) has
    ``status`` ``"degraded"`` and the cause in ``"degraded"``; ``metrics["degraded"]`` lists them.
    Interrupted (KeyboardInterrupt, which the CLI raises for SIGINT and SIGTERM), the methods that
    had finished are written (without figures; ``metrics["interrupted"]`` names them and the ones
    that did not finish) before the interrupt propagates. ``mat``: also write the time series as
    ``timeseries.mat`` (MATLAB; ``timeseries.npz`` is always written).
    """
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    kd, dd = designs or (load_or_design_kinematic(cfg), load_or_design_dynamic(cfg))
    logs: dict[str, RunLog] = {}
    try:
        for method in methods:
            k_total = tracked_steps(scenario.reference, cfg.mpc.N)
            if max_steps is not None:
                k_total = min(k_total, max_steps)
            prog = progress_factory(method.value, k_total) if progress_factory else None
            plant = plant_factory() if plant_factory is not None else None
            logs[method.value] = simulate(cfg, method, scenario, oracle=oracle, plant=plant,
                                          kinematic_design=kd, dynamic_design=dd, progress=prog,
                                          max_steps=max_steps)
    except KeyboardInterrupt:  # Ctrl-C / SIGTERM: keep the methods that had finished
        if logs and out_dir is not None:
            metrics = _metrics(cfg, scenario, logs, max_steps, oracle, kd)
            metrics["interrupted"] = {"finished": list(logs),
                                      "not_finished": [m.value for m in methods if m.value not in logs]}
            write_outputs(cfg, metrics, logs, Path(out_dir), plots=False, mat=mat)
        raise
    metrics = _metrics(cfg, scenario, logs, max_steps, oracle, kd)
    files: list[Path] = []
    if out_dir is not None:
        files = write_outputs(cfg, metrics, logs, Path(out_dir), plots=plots, figures=figures, mat=mat)
    return CompareResult(metrics, logs, tuple(files))


def _metrics(cfg: Config, scenario: Scenario, logs: dict[str, RunLog], max_steps: int | None,
             oracle: bool, kd: Any) -> dict[str, Any]:
    """The metrics.json content of the runs in ``logs``."""
    metrics: dict[str, Any] = {
        "methods": {name: compute_metrics(log) for name, log in logs.items()},
        "scenario": _scenario_summary(cfg, scenario, max_steps),
        "versions": versions(),
        "oracle": oracle,
        "paper_run_rmse": cfg.metrics.paper_run_rmse,  # tables show the published run's RMSE convention too
        "designs": {"kinematic_S": kd.S.tolist(), "kinematic_P": kd.P.tolist()},
    }
    laps = int(scenario.meta.get("laps", 1) or 1)
    if scenario.reference.closed and laps > 1:
        lap_len = len(scenario.reference) // laps
        for name, log in logs.items():
            e = abs(log.errors[:, 1])
            metrics["methods"][name]["max_abs_lateral_per_lap_m"] = [
                float(e[i:i + lap_len].max()) for i in range(0, e.size, lap_len)]
    from tsmpc.sim.health import degradation

    for name, m in metrics["methods"].items():  # any early stop (|e_y| bound, plant blew up) diverged
        m["status"] = "completed" if m["termination"] == "completed" else "diverged"
        problem = degradation(m, logs[name], cfg) if m["status"] == "completed" else None
        if problem:  # completed, but beyond the car: saturated most of the time, errors past the bounds
            m["status"], m["degraded"] = "degraded", problem
    metrics["diverged"] = [n for n, m in metrics["methods"].items() if m["status"] == "diverged"]
    metrics["degraded"] = [n for n, m in metrics["methods"].items() if m["status"] == "degraded"]
    ref_m = metrics["methods"].get("REF")
    if ref_m:
        for m in metrics["methods"].values():
            den = ref_m["mpc_ms"]["median"]  # 0 or NaN when REF stopped before its first solve
            m["mpc_ms_ratio_to_REF"] = m["mpc_ms"]["median"] / den if den > 0 else float("nan")
    return metrics


def _config_toml(cfg: Config, methods: list[str]) -> str:
    """The run's config as TOML; ``mpc.mode`` says which methods ran (each method runs with its
    own scheduling mode, whatever the config's ``mpc.mode``)."""
    lines = cfg.to_toml().splitlines()
    if methods != [cfg.mpc.mode.value]:
        section = ""
        for i, line in enumerate(lines):
            if line.startswith("["):
                section = line
            elif section == "[mpc]" and line.startswith("mode = "):
                lines[i] = f"{line}  # this run: {', '.join(methods)} (each with its own mode, --methods)"
                break
    return "\n".join(lines) + "\n"


def write_outputs(
    cfg: Config, metrics: dict[str, Any], logs: dict[str, RunLog], out: Path, *, plots: bool,
    figures: FigureFn | None = None, mat: bool = False,
) -> list[Path]:
    """metrics.json, rmse.{csv,md,tex}, comfort.{csv,md}, timeseries.npz (and timeseries.mat when
    ``mat``), config.toml, versions.json, figures, and last report.html (one self-contained page of
    all of it)."""
    from tsmpc.report.tables import comfort_csv, comfort_markdown, rmse_csv, rmse_latex, rmse_markdown

    out.mkdir(parents=True, exist_ok=True)
    with_paper = bool(metrics["scenario"].get("paper_reference"))
    texts = {
        "metrics.json": json.dumps(metrics, indent=2, allow_nan=True),
        "rmse.csv": rmse_csv(metrics, with_paper),
        "rmse.md": rmse_markdown(metrics, with_paper),
        "rmse.tex": rmse_latex(metrics, with_paper),
        "comfort.csv": comfort_csv(metrics),
        "comfort.md": comfort_markdown(metrics),
        "config.toml": _config_toml(cfg, list(logs)),
        "versions.json": json.dumps(metrics["versions"], indent=2),
    }
    files = []
    for name, text in texts.items():
        atomic_write_text(out / name, text)
        files.append(out / name)
    save_logs_npz(logs, out / "timeseries.npz")
    files.append(out / "timeseries.npz")
    if mat:  # one time-series format by default; MATLAB's on request (tsmpc compare --mat)
        save_logs_mat(logs, out / "timeseries.mat")
        files.append(out / "timeseries.mat")
    if plots:
        if figures is None:
            from tsmpc.report.figures import save_all

            figures = save_all
        files += figures(logs, out, cfg)
    from tsmpc.report.html import write_report

    files.append(write_report(out, metrics, files))
    return files
