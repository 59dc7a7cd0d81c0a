"""The paper's comparison in one call (SPEC §10–11): run each method on one scenario, compute
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
from tsmpc.sim.simulator import Method, Scenario, simulate

__all__ = ["CompareResult", "compare", "load_scenario", "versions"]

ProgressFactory = Callable[[str, int], Callable[[int, int], None]]


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
    reference: Path | None = None,
    window: tuple[int, int] | None = None,
    *,
    use_paper_window: bool = True,
) -> Scenario:
    """The comparison scenario: the built-in circuit (``reference=None``), a paper-format file
    (the paper-run window of columns 5…1316 unless ``window`` says otherwise) or a planned CSV;
    the paper's time-based friction profile applies in every case."""
    from tsmpc.planning.paper_format import PAPER_RUN_WINDOW, load_reference
    from tsmpc.scenarios import paper_friction_profile

    if reference is None:
        from tsmpc.planning.circuit import builtin_circuit  # (imports the planner: scipy.interpolate)

        ref = builtin_circuit(dt=cfg.rates.Tc)
        return Scenario("builtin-circuit", ref, paper_friction_profile(),
                        meta={"reference": "builtin-circuit", "paper_reference": False})
    paper = _is_paper_format(Path(reference))
    win = window if window is not None else (PAPER_RUN_WINDOW if (paper and use_paper_window) else None)
    ref = load_reference(reference, window=win)
    check_trackable(ref, cfg, str(reference))
    return Scenario(Path(reference).stem, ref, paper_friction_profile(),
                    meta={"reference": str(reference), "window": list(win) if win else None,
                          "paper_reference": paper})


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
        "tracked_steps": (len(ref) - cfg.mpc.N) if max_steps is None
        else min(len(ref) - cfg.mpc.N, max_steps),
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
    designs: tuple[Any, Any] | None = None,
) -> CompareResult:
    """Run ``methods`` on ``scenario`` and write metrics, tables, time series and figures.

    Every method runs from the same seed (same noise sequence). Nothing is written when
    ``out_dir`` is None. Files are written atomically. ``designs``: the (kinematic, dynamic)
    LMI designs of ``cfg`` when the caller has them (default: the design cache).
    """
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    kd, dd = designs or (load_or_design_kinematic(cfg), load_or_design_dynamic(cfg))
    logs: dict[str, RunLog] = {}
    for method in methods:
        k_total = len(scenario.reference) - cfg.mpc.N
        if max_steps is not None:
            k_total = min(k_total, max_steps)
        prog = progress_factory(method.value, k_total) if progress_factory else None
        logs[method.value] = simulate(cfg, method, scenario, oracle=oracle, kinematic_design=kd,
                                      dynamic_design=dd, progress=prog, max_steps=max_steps)
    metrics: dict[str, Any] = {
        "methods": {name: compute_metrics(log) for name, log in logs.items()},
        "scenario": _scenario_summary(cfg, scenario, max_steps),
        "versions": versions(),
        "oracle": oracle,
        "designs": {"kinematic_S": kd.S.tolist(), "kinematic_P": kd.P.tolist()},
    }
    ref_m = metrics["methods"].get("REF")
    if ref_m:
        for m in metrics["methods"].values():
            m["mpc_ms_ratio_to_REF"] = m["mpc_ms"]["median"] / ref_m["mpc_ms"]["median"]
    files: list[Path] = []
    if out_dir is not None:
        files = write_outputs(cfg, metrics, logs, Path(out_dir), plots=plots)
    return CompareResult(metrics, logs, tuple(files))


def write_outputs(
    cfg: Config, metrics: dict[str, Any], logs: dict[str, RunLog], out: Path, *, plots: bool
) -> list[Path]:
    """metrics.json, rmse.{csv,md,tex}, timeseries.{npz,mat}, config.toml, versions.json, figures,
    and last report.html (one self-contained page of all of it)."""
    from tsmpc.report.tables import rmse_csv, rmse_latex, rmse_markdown

    out.mkdir(parents=True, exist_ok=True)
    with_paper = bool(metrics["scenario"].get("paper_reference"))
    texts = {
        "metrics.json": json.dumps(metrics, indent=2, allow_nan=True),
        "rmse.csv": rmse_csv(metrics, with_paper),
        "rmse.md": rmse_markdown(metrics, with_paper),
        "rmse.tex": rmse_latex(metrics, with_paper),
        "config.toml": cfg.to_toml(),
        "versions.json": json.dumps(metrics["versions"], indent=2),
    }
    files = []
    for name, text in texts.items():
        atomic_write_text(out / name, text)
        files.append(out / name)
    save_logs_npz(logs, out / "timeseries.npz")
    save_logs_mat(logs, out / "timeseries.mat")
    files += [out / "timeseries.npz", out / "timeseries.mat"]
    if plots:
        from tsmpc.report.figures import save_all

        files += save_all(logs, out, cfg)
    from tsmpc.report.html import write_report

    files.append(write_report(out, metrics, files))
    return files
