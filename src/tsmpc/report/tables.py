"""RMSE and timing tables in the paper's Table 5 layout: CSV, Markdown and LaTeX."""

from __future__ import annotations

import math
from typing import Any

from tsmpc.sim.metrics import PAPER_TABLE5, RMSE_KEYS

__all__ = ["is_diverged", "rmse_csv", "rmse_latex", "rmse_markdown", "rmse_rows", "timing_rows"]

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
