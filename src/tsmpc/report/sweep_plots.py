"""Summary plots of a sweep (issue 8): RMSE and max lateral error against every axis that varies,
and the distribution of MPC solve times per method."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

__all__ = ["save_sweep_plots"]

_STATUS_MARK = {"completed": "o", "diverged": "x", "error": "s", "failed": "s"}


def _axis_figure(table: Any, axis: str) -> Any:
    metrics = [("rmse_x", "RMSE x [m]"), ("rmse_y", "RMSE y [m]"), ("max_abs_lateral_m", "max |e_y| [m]")]
    fig, axs = plt.subplots(1, len(metrics), figsize=(13, 3.8))
    from pandas.api.types import is_numeric_dtype

    col = table[axis]
    categorical = not is_numeric_dtype(col) or col.nunique() <= 6
    if categorical:
        col = col.astype(str)
    if axis == "track":  # file paths: the file name is the label
        col = col.map(lambda v: Path(v).stem)
    levels = sorted(col.unique(), key=str)
    for ax, (key, label) in zip(axs, metrics, strict=True):
        for status, mark in _STATUS_MARK.items():
            sel = table["status"] == status
            if not sel.any() or key not in table:
                continue
            xs = col[sel]
            xpos = np.array([levels.index(v) for v in xs], float) if categorical else xs.to_numpy(float)
            if categorical:  # spread the points of each level a little so they stay visible
                xpos = xpos + _jitter(xpos)
            ax.plot(xpos, table.loc[sel, key], mark, ms=5, alpha=0.8, label=status)
        if categorical:
            ax.set_xticks(range(len(levels)), [str(v) for v in levels], rotation=30, ha="right")
        ax.set_xlabel(axis)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    fig.suptitle(f"sweep: tracking against {axis}")
    fig.tight_layout()
    return fig


def _jitter(xpos: np.ndarray) -> np.ndarray:
    """Offsets in [−0.15, 0.15] spreading the points that share a level."""
    out = np.zeros_like(xpos)
    for level in np.unique(xpos):
        idx = np.flatnonzero(xpos == level)
        if idx.size > 1:
            out[idx] = np.linspace(-0.15, 0.15, idx.size)
    return out


def _timing_figure(table: Any) -> Any:
    fig, ax = plt.subplots(figsize=(7, 4))
    methods = sorted(table["method"].unique())
    data = [table.loc[table["method"] == m, "mpc_median_ms"].dropna().to_numpy() for m in methods]
    data99 = [table.loc[table["method"] == m, "mpc_p99_ms"].dropna().to_numpy() for m in methods]
    pos = np.arange(len(methods))
    ax.boxplot(data, positions=pos - 0.18, widths=0.3)
    ax.boxplot(data99, positions=pos + 0.18, widths=0.3)
    ax.set_xticks(pos, methods)
    ax.set_yscale("log")
    ax.set_ylabel("MPC step [ms] (left: median, right: p99 of each run)")
    ax.grid(alpha=0.3, which="both")
    ax.set_title("MPC solve times across the sweep")
    fig.tight_layout()
    return fig


def save_sweep_plots(table: Any, out: str | Path, axes: Sequence[str]) -> list[Path]:
    """Write ``by_<axis>.png`` for every axis (``tsmpc.sweep.AXES``) with more than one value,
    and ``solve_times.png``."""
    out = Path(out)
    files = []
    for axis in axes:
        if axis in table and table[axis].nunique(dropna=True) > 1:
            fig = _axis_figure(table, axis)
            path = out / f"by_{axis}.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            files.append(path)
    if "mpc_median_ms" in table and table["mpc_median_ms"].notna().any():
        fig = _timing_figure(table)
        path = out / "solve_times.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        files.append(path)
    return files
