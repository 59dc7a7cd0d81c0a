"""RMSE and timing tables in the paper's Table 5 layout: CSV, Markdown and LaTeX; the
comfort and effort table (issue 26, :mod:`tsmpc.sim.comfort`): CSV and Markdown."""

from __future__ import annotations

import math
from typing import Any

from tsmpc.sim.metrics import PAPER_TABLE5, RMSE_KEYS

__all__ = ["COMFORT_COLUMNS", "COMFORT_CONSOLE", "comfort_cell", "comfort_csv", "comfort_markdown",
           "comfort_rows", "factor_cell", "is_diverged", "rmse_csv", "rmse_latex", "rmse_markdown",
           "rmse_rows", "time_cell", "timed_in_note", "timing_rows"]

_HEAD = ("approach", "x [m]", "y [m]", "theta [rad]", "v [m/s]", "omega [rad/s]")


def is_diverged(m: dict[str, Any]) -> bool:
    """A method's metrics entry describes a run that ended early (left the road, plant blew up)."""
    status = m.get("status")
    if status is None:  # metrics written before the status field: any early stop diverged
        return m.get("termination", "completed") != "completed"
    return bool(status == "diverged")


def rmse_rows(metrics: dict[str, Any], with_paper: bool) -> list[tuple[str, list[float]]]:
    """Rows (label, [x, y, θ, v, ω]): ours, the same run under the published run's RMSE
    convention when ``metrics["paper_run_rmse"]`` is set (``metrics.paper_run_rmse`` of the
    config, the published run), and the paper's beside each when requested.

    A diverged run is never shown as if it had completed: its label says ``(diverged)`` and its
    values are NaN (printed as a dash); no paper row is put beside it."""
    rows: list[tuple[str, list[float]]] = []
    for name, m in metrics["methods"].items():
        if is_diverged(m):
            rows.append((f"{name} (diverged)", [float("nan")] * len(RMSE_KEYS)))
            continue
        rows.append((name, [m["rmse"][k] for k in RMSE_KEYS]))
        if metrics.get("paper_run_rmse") and "rmse_paper_run" in m:  # published run's RMSE convention
            rows.append((f"{name} (paper-run RMSE)", [m["rmse_paper_run"][k] for k in RMSE_KEYS]))
        if with_paper and name in PAPER_TABLE5:
            rows.append((f"{name} (paper)", [PAPER_TABLE5[name][k] for k in RMSE_KEYS]))
    return rows


def _fmt(v: float, dash: str = "—") -> str:
    return dash if math.isnan(v) else f"{v:.3f}"


def rmse_csv(metrics: dict[str, Any], with_paper: bool) -> str:
    """CSV with header ``approach,x,y,theta,v,omega``."""
    lines = ["approach,x,y,theta,v,omega"]
    lines += [f"{lab}," + ",".join(f"{v:.6g}" for v in vals)
              for lab, vals in rmse_rows(metrics, with_paper)]
    return "\n".join(lines) + "\n"


def rmse_markdown(metrics: dict[str, Any], with_paper: bool) -> str:
    """Markdown table, 3 decimals like the paper."""
    out = ["| " + " | ".join(_HEAD) + " |", "|" + "---|" * len(_HEAD)]
    out += [f"| {lab} | " + " | ".join(_fmt(v) for v in vals) + " |"
            for lab, vals in rmse_rows(metrics, with_paper)]
    return "\n".join(out) + "\n"


def rmse_latex(metrics: dict[str, Any], with_paper: bool) -> str:
    """LaTeX tabular (booktabs), 3 decimals."""
    out = [
        r"\begin{tabular}{lrrrrr}", r"\toprule",
        r"approach & $x$ [m] & $y$ [m] & $\theta$ [rad] & $v$ [m/s] & $\omega$ [rad/s] \\",
        r"\midrule",
    ]
    out += [f"{lab} & " + " & ".join(_fmt(v, "--") for v in vals) + r" \\"
            for lab, vals in rmse_rows(metrics, with_paper)]
    out += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(out) + "\n"


def timing_rows(metrics: dict[str, Any]) -> list[tuple[str, dict[str, float], dict[str, float], float]]:
    """(method, mpc_ms stats, mhe_ms stats, realtime factor) per method."""
    return [(name, m["mpc_ms"], m["mhe_ms"], m["realtime_factor"])
            for name, m in metrics["methods"].items()]


def time_cell(ms: float | None) -> str:
    """A per-step time [ms] in at most 7 characters with its own unit, 3 significant digits:
    ``2.97 µs``, ``366 µs``, ``2.07 ms``, ``1.25 s``; '—' when undefined. (The timing columns
    span four decades, FZN's microseconds to NL's milliseconds: one fixed unit would print
    ``0.00297`` or ``2070``.)"""
    if ms is None or not math.isfinite(ms):
        return "—"
    if ms < 1.0:
        return f"{ms * 1e3:.3g} µs"
    if ms < 1e3:
        return f"{ms:.3g} ms"
    return f"{ms / 1e3:.3g} s"


def factor_cell(x: float | None) -> str:
    """A ratio as ``976×`` (≥ 10) or ``1.3×``; '—' when undefined."""
    if x is None or not math.isfinite(x):
        return "—"
    return f"{x:.0f}×" if abs(x) >= 10 else f"{x:.1f}×"


#: Where a method's per-step times are measured, for the note under the timing table.
_WHERE = {"engine": "inside the compiled run engine",
          "Python": "in the Python loop (its call overhead included)"}


def timed_in_note(timed_in: dict[str, str]) -> str:
    """One note naming where each method was timed (method -> "engine" or "Python"), e.g.
    "Times measured inside the compiled run engine: FZN, REF, ITER; in the Python loop (its call
    overhead included): NL. Compare times within a group." Empty when ``timed_in`` is."""
    groups: dict[str, list[str]] = {}
    for name, where in timed_in.items():
        groups.setdefault(where, []).append(name)
    if not groups:
        return ""
    parts = [f"{_WHERE.get(w, w)}: {', '.join(names)}" for w, names in groups.items()]
    tail = " Compare times within a group." if len(groups) > 1 else ""
    return "Times measured " + "; ".join(parts) + "." + tail


#: (metrics.json key under ``comfort``, column head, decimals) of the comfort table.
COMFORT_COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("lat_accel_max", "max |a_y| [m/s²]", 2),
    ("lat_accel_rms", "RMS a_y [m/s²]", 3),
    ("lat_jerk_max", "max |jerk_y| [m/s³]", 2),
    ("lat_jerk_rms", "RMS jerk_y [m/s³]", 3),
    ("lon_jerk_max", "max |jerk_x| [m/s³]", 1),
    ("lon_jerk_rms", "RMS jerk_x [m/s³]", 2),
    ("steering_rate_max", "max |δ̇| [rad/s]", 3),
    ("steering_rate_rms", "RMS δ̇ [rad/s]", 4),
    ("force_rate_max", "max |Ḟ| [kN/s]", 1),
    ("force_rate_rms", "RMS Ḟ [kN/s]", 2),
    ("settling_time_s", "settling [s]", 1),
)
_KILO = {"force_rate_max", "force_rate_rms"}  # N/s shown as kN/s

#: The console's comfort tables: (title, ((key, short two-line head), ...)), at most six values
#: each, so that each table fits 80 columns (the files keep the one table of COMFORT_COLUMNS).
COMFORT_CONSOLE: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = (
    ("Comfort (5 Hz zero-phase low-pass before each derivative)", (
        ("lat_accel_max", "max|a_y|\nm/s²"), ("lat_accel_rms", "RMS a_y\nm/s²"),
        ("lat_jerk_max", "max|j_y|\nm/s³"), ("lat_jerk_rms", "RMS j_y\nm/s³"),
        ("lon_jerk_max", "max|j_x|\nm/s³"), ("lon_jerk_rms", "RMS j_x\nm/s³"))),
    ("Effort and settling", (
        ("steering_rate_max", "max|δ̇|\nrad/s"), ("steering_rate_rms", "RMS δ̇\nrad/s"),
        ("force_rate_max", "max|Ḟ|\nkN/s"), ("force_rate_rms", "RMS Ḟ\nkN/s"),
        ("settling_time_s", "settling\ns"))),
)


def comfort_rows(metrics: dict[str, Any]) -> list[tuple[str, list[float]]]:
    """Rows (method, values in :data:`COMFORT_COLUMNS` order, force rates in kN/s). A run without
    comfort metrics (older metrics.json) has NaN values; a diverged run is labelled so."""
    rows = []
    for name, m in metrics["methods"].items():
        c = m.get("comfort", {})
        vals = [float(c.get(k, float("nan"))) / (1e3 if k in _KILO else 1.0)
                for k, _, _ in COMFORT_COLUMNS]
        rows.append((f"{name} (diverged)" if is_diverged(m) else name, vals))
    return rows


def comfort_csv(metrics: dict[str, Any]) -> str:
    """CSV ``method,<comfort keys>`` (SI units; force rates in N/s as in metrics.json)."""
    lines = ["method," + ",".join(k for k, _, _ in COMFORT_COLUMNS)]
    for name, m in metrics["methods"].items():
        c = m.get("comfort", {})
        label = f"{name} (diverged)" if is_diverged(m) else name
        lines.append(label + "," + ",".join(f"{float(c.get(k, float('nan'))):.6g}"
                                            for k, _, _ in COMFORT_COLUMNS))
    return "\n".join(lines) + "\n"


def comfort_cell(v: float, decimals: int) -> str:
    """A comfort value: '—' when undefined (NaN), 'never' for a settling time that is infinite."""
    if math.isnan(v):
        return "—"
    return "never" if math.isinf(v) else f"{v:.{decimals}f}"


def comfort_markdown(metrics: dict[str, Any]) -> str:
    """Markdown comfort table (definitions and filtering: :mod:`tsmpc.sim.comfort`)."""
    head = ("method", *(h for _, h, _ in COMFORT_COLUMNS))
    out = ["| " + " | ".join(h.replace("|", "\\|") for h in head) + " |", "|" + "---|" * len(head)]
    for lab, vals in comfort_rows(metrics):
        cells = [comfort_cell(v, d) for v, (_, _, d) in zip(vals, COMFORT_COLUMNS,
                                                                               strict=True)]
        out.append(f"| {lab} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"
