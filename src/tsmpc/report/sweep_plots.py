"""Summary plots of a sweep (issue 8): RMSE and max lateral error against every axis that varies,
the points coloured by a second varying axis (the method when it varies) and marked by the run's
status, and the distribution of MPC solve times per method."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from tsmpc.io import atomic_savefig
from tsmpc.sweep_axes import AXES

__all__ = ["colour_axis", "save_sweep_plots"]

_STATUS_MARK = {"completed": "o", "diverged": "X", "error": "s", "failed": "s"}
_PALETTE = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
            "tab:gray", "tab:olive", "tab:cyan"]


def _levels(table: Any, axis: str) -> tuple[Any, bool]:
    """The column of ``axis`` (as labels when categorical) and whether it is categorical."""
    from pandas.api.types import is_numeric_dtype

    col = table[axis]
    numeric = is_numeric_dtype(col)
    categorical = not numeric or col.nunique() <= 6
    if categorical:
        col = col.astype(str)
    if axis == "track":  # file paths: the file name is the label
        col = col.map(lambda v: Path(v).stem)
    return col, categorical


def _sorted_levels(table: Any, axis: str, col: Any) -> list[str]:
    """Levels in numeric order when the axis is numeric (0.5, 2, 10, not "10" < "2")."""
    from pandas.api.types import is_numeric_dtype

    if is_numeric_dtype(table[axis]):
        first = dict(zip(col, table[axis], strict=True))
        return sorted(col.unique(), key=lambda v: float(first[v]))
    return sorted(col.unique(), key=str)


def colour_axis(table: Any, axis: str) -> str | None:
    """The second varying axis that colours the points of the plot against ``axis``: ``method``
    when it varies, else the varying axis with the fewest levels (None when nothing else varies)."""
    varying = [a for a in AXES if a != axis and a in table and table[a].nunique(dropna=True) > 1]
    if not varying:
        return None
    if "method" in varying:
        return "method"
    return min(varying, key=lambda a: (table[a].nunique(dropna=True), AXES.index(a)))


def _axis_figure(table: Any, axis: str) -> Any:
    metrics = [("rmse_x", "RMSE x [m]"), ("rmse_y", "RMSE y [m]"), ("max_abs_lateral_m", "max |e_y| [m]")]
    fig, axs = plt.subplots(1, len(metrics), figsize=(13, 4.2))
    col, categorical = _levels(table, axis)
    levels = _sorted_levels(table, axis, col) if categorical else []
    hue = colour_axis(table, axis)
    if hue is not None:
        hcol, _ = _levels(table, hue)
        hcol = hcol.astype(str)
        hlevels = _sorted_levels(table, hue, hcol)
    else:
        hcol, hlevels = None, ["all"]
    many = len(hlevels) > len(_PALETTE)  # a continuous second axis: a colour map instead
    cmap = plt.get_cmap("viridis")
    from matplotlib.lines import Line2D

    for ax, (key, label) in zip(axs, metrics, strict=True):
        if key not in table:
            continue
        xpos = np.array([levels.index(v) for v in col], float) if categorical else col.to_numpy(float)
        if categorical:  # one sub-column per colour in each level, its points spread a little
            h_idx = (np.zeros(len(table)) if hcol is None
                     else np.array([hlevels.index(v) for v in hcol], float))
            width = 0.7 / len(hlevels)
            xpos = xpos + (h_idx - (len(hlevels) - 1) / 2) * width + _jitter(xpos * 1000 + h_idx,
                                                                              0.35 * width)
        for hi, hl in enumerate(hlevels):
            in_h = np.ones(len(table), bool) if hcol is None else (hcol == hl).to_numpy()
            color = cmap(hi / max(1, len(hlevels) - 1)) if many else _PALETTE[hi % len(_PALETTE)]
            for status, mark in _STATUS_MARK.items():
                sel = in_h & (table["status"] == status).to_numpy()
                if sel.any():
                    ax.plot(xpos[sel], table.loc[sel, key], mark, ms=6, alpha=0.85, color=color,
                            mfc=color if status == "completed" else "none", mew=1.3)
        if categorical:
            ax.set_xticks(range(len(levels)), [str(v) for v in levels], rotation=30, ha="right")
        ax.set_xlabel(axis)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles = []
    if hue is not None and not many:
        handles += [Line2D([], [], color=_PALETTE[i % len(_PALETTE)], marker="o", ls="none",
                           label=f"{hue} = {hl}") for i, hl in enumerate(hlevels)]
    elif hue is not None:
        handles += [Line2D([], [], color=cmap(t), marker="o", ls="none", label=f"{hue} = {hlevels[i]}")
                    for i, t in ((0, 0.0), (len(hlevels) - 1, 1.0))]
    present = set(table["status"].unique())
    handles += [Line2D([], [], color="0.2", marker=m, ls="none", mfc="none" if st != "completed" else "0.2",
                       label=st) for st, m in _STATUS_MARK.items() if st in present and st != "failed"]
    fig.legend(handles=handles, loc="upper right", fontsize=8, ncol=min(6, len(handles)))
    title = f"sweep: tracking against {axis}" + (f", coloured by {hue}" if hue else "")
    fig.suptitle(title, x=0.01, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    return fig


def _jitter(xpos: np.ndarray, half: float = 0.15) -> np.ndarray:
    """Offsets in [−half, half] spreading the points that share a level."""
    out = np.zeros_like(xpos)
    for level in np.unique(xpos):
        idx = np.flatnonzero(xpos == level)
        if idx.size > 1:
            out[idx] = np.linspace(-half, half, idx.size)
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


def save_sweep_plots(table: Any, out: str | Path, axes: Sequence[str] = AXES) -> list[Path]:
    """Write ``by_<axis>.png`` for every axis of ``axes`` with more than one value, and
    ``solve_times.png``."""
    out = Path(out)
    files = []
    for axis in axes:
        if axis in table and table[axis].nunique(dropna=True) > 1:
            fig = _axis_figure(table, axis)
            path = out / f"by_{axis}.png"
            try:
                atomic_savefig(fig, path, dpi=110)
            finally:
                plt.close(fig)
            files.append(path)
    if "mpc_median_ms" in table and table["mpc_median_ms"].notna().any():
        fig = _timing_figure(table)
        path = out / "solve_times.png"
        try:
            atomic_savefig(fig, path, dpi=110)
        finally:
            plt.close(fig)
        files.append(path)
    return files
