"""The paper's figures from run logs: circuit with a zoom, velocities, errors, each method's
difference from a baseline (NL when present), control actions with their saturation limits,
friction force true vs estimated, per-step MPC solve time against the T_c deadline (log scale).
Each function takes the logs and returns the Figure; :func:`save_all` writes PNG and PDF.

Methods often track almost identically; every method therefore has its own colour, line style and
marker, and :func:`differences_figure` plots what separates them. Only the report package imports
matplotlib (Agg backend)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from tsmpc.config import Config
from tsmpc.io import atomic_savefig
from tsmpc.sim.log import RunLog
from tsmpc.sim.metrics import tracking_errors

__all__ = [
    "baseline_method",
    "circuit_figure",
    "control_figure",
    "differences_figure",
    "errors_figure",
    "friction_figure",
    "save_all",
    "solve_time_figure",
    "velocity_figure",
]

# (colour, line style, marker): curves that coincide stay distinguishable by dash and marker.
_STYLES = {
    "FZN": ("tab:blue", "-", "o"),
    "REF": ("tab:orange", "--", "s"),
    "ITER": ("tab:green", "-.", "^"),
    "NL": ("tab:red", ":", "D"),
    # the baselines of issue 26 (tsmpc.control.baselines)
    "PURE_PURSUIT": ("tab:purple", "-", "v"),
    "STANLEY": ("tab:brown", "--", "P"),
    "LQR": ("tab:pink", "-.", "X"),
    "LTV": ("tab:olive", ":", "*"),
}
_EXTRA = [("tab:purple", "-", "v"), ("tab:brown", "--", "P"), ("tab:pink", "-.", "X")]


def _c(method: str) -> str:
    return _style(method)["color"]


def _style(method: str, n: int | None = None, every: int | None = None) -> dict[str, Any]:
    """Line keywords of a method; ``n`` samples get about 12 markers (or one every ``every``)."""
    color, ls, marker = _STYLES.get(method, _EXTRA[sum(map(ord, method)) % len(_EXTRA)])
    kw: dict[str, Any] = {"color": color, "ls": ls}
    if n:
        # Staggered starts: markers of coinciding curves sit side by side, not on top of each other.
        step = every or max(1, n // 12)
        slot = list(_STYLES).index(method) if method in _STYLES else len(_STYLES)
        kw.update(marker=marker, ms=4, markevery=(slot * step // 4 % step, step), mfc="none")
    return kw


_ERROR_LABELS = [("x", "e_x [m]"), ("y", "e_y [m]"), ("theta", "e_θ [rad]"),
                 ("v", "v_d − v [m/s]"), ("omega", "ω_d − ω [rad/s]")]


def baseline_method(logs: dict[str, RunLog]) -> str:
    """The method the others are compared with: NL when present, else the first one."""
    return "NL" if "NL" in logs else next(iter(logs))


def circuit_figure(logs: dict[str, RunLog]) -> Figure:
    """Reference path and driven paths, with a zoom on the point of largest lateral error."""
    fig, (ax, axz) = plt.subplots(1, 2, figsize=(12, 5.5), gridspec_kw={"width_ratios": [1.6, 1]})
    first = next(iter(logs.values()))
    for a in (ax, axz):
        a.plot(first.ref[:, 0], first.ref[:, 1], "k--", lw=1.2, label="reference")
        for name, log in logs.items():
            a.plot(log.state_outer[:, 0], log.state_outer[:, 1], lw=1.0, label=name,
                   **(_style(name, log.n_outer, every=4) if a is axz else _style(name)))
        # The overview adapts its limits to the data; the zoom keeps its fixed window.
        a.set_aspect("equal", adjustable="datalim" if a is ax else "box")
        a.set_xlabel("X [m]")
        a.set_ylabel("Y [m]")
    ax.plot(first.ref[0, 0], first.ref[0, 1], "go", ms=6, label="start")
    k = int(np.argmax(np.abs(first.errors[:, 1]))) if first.n_outer else 0
    # The window holds the reference point and the car at that step (a diverged car is metres off).
    car = first.state_outer[k, :2] if first.n_outer else first.ref[0, :2]
    cx, cy = 0.5 * (first.ref[k, 0] + car[0]), 0.5 * (first.ref[k, 1] + car[1])
    r = max(6.0, 0.5 * float(np.hypot(*(car - first.ref[k, :2]))) + 3.0)
    axz.set_xlim(cx - r, cx + r)
    axz.set_ylim(cy - r, cy + r)
    axz.set_title(f"zoom at t = {first.t_outer[k]:.1f} s (largest |e_y| of {first.method})")
    ax.add_patch(Rectangle((cx - r, cy - r), 2 * r, 2 * r, fill=False, ec="0.4", lw=0.8))
    ax.set_title(f"circuit: {first.scenario}")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    axz.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def velocity_figure(logs: dict[str, RunLog]) -> Figure:
    """v and ω: references, MPC outputs and the true plant values."""
    fig, axs = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    first = next(iter(logs.values()))
    axs[0].plot(first.t_outer, first.ref[:, 3], "k--", lw=1.2, label="v_d")
    axs[1].plot(first.t_outer, first.ref[:, 4], "k--", lw=1.2, label="ω_d")
    _governor_lines(axs[0], logs)
    for name, log in logs.items():
        st = _style(name, log.t_inner.size)
        axs[0].plot(log.t_inner, log.state[:, 3], lw=0.9, label=f"v {name}", **st)
        axs[1].plot(log.t_inner, log.state[:, 5], lw=0.9, label=f"ω {name}", **st)
    axs[0].set_ylabel("v [m/s]")
    axs[1].set_ylabel("ω [rad/s]")
    axs[1].set_xlabel("t [s]")
    for a in axs:
        a.grid(alpha=0.3)
        a.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    return fig


def _governor_lines(ax: Any, logs: dict[str, RunLog]) -> None:
    """The speed governor's slow-down (tsmpc.control.governor): the planned speed, and each
    governed run's own v_d (the reference it tracked) where it differs from the first's."""
    governed = {n: g for n, g in logs.items()  # (on by default: only the runs it slowed)
                if "planned_v" in g.meta and g.events.get("governor_actions", 0) > 0}
    if not governed:
        return
    first = next(iter(governed.values()))
    planned = np.asarray(first.meta["planned_v"], dtype=float)
    n = min(planned.size, first.t_outer.size)
    ax.plot(first.t_outer[:n], planned[:n], color="0.55", ls=":", lw=1.2, label="v_d planned")
    for name, log in governed.items():
        if log is not first:
            ax.plot(log.t_outer, log.ref[:, 3], lw=0.8, label=f"v_d governed {name}", **_style(name))
    ax.set_title("governor: v_d is the governed speed (the plan's: dotted)", fontsize=9)


#: The errors figure zooms on the first seconds of a run at least this many times longer.
_ZOOM_S = 10.0


def errors_figure(logs: dict[str, RunLog]) -> Figure:
    """e_x, e_y, e_θ, v_d − v, ω_d − ω against time; for a run much longer than 10 s a second
    column zooms on its first 10 s (a start-up transient is invisible on a 127 s axis)."""
    labels = _ERROR_LABELS
    t_end = max((float(log.t_outer[-1] - log.t_outer[0]) for log in logs.values() if log.n_outer),
                default=0.0)
    zoom = t_end > 4 * _ZOOM_S
    fig, grid = plt.subplots(5, 2 if zoom else 1, figsize=(14 if zoom else 11, 10), squeeze=False,
                             sharex="col", gridspec_kw={"width_ratios": [3, 1.2]} if zoom else None)
    for name, log in logs.items():
        err = tracking_errors(log)
        for i, (key, _) in enumerate(labels):
            grid[i, 0].plot(log.t_outer, err[key], lw=0.9, label=name, **_style(name, log.n_outer))
            if zoom:
                t0 = log.t_outer[0] if log.n_outer else 0.0
                k = log.t_outer <= t0 + _ZOOM_S
                grid[i, 1].plot(log.t_outer[k], err[key][k], lw=1.0, label=name,
                                **_style(name, int(k.sum())))
    for i, (_, lab) in enumerate(labels):
        grid[i, 0].set_ylabel(lab)
        for a in grid[i]:
            a.grid(alpha=0.3)
    grid[0, 0].legend(fontsize=8, ncol=4)
    if zoom:
        grid[0, 1].set_title(f"the first {_ZOOM_S:g} s", fontsize=10)
        grid[-1, 1].set_xlabel("t [s]")
    grid[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def differences_figure(logs: dict[str, RunLog]) -> Figure:
    """Each method's tracking errors minus the baseline's (NL when present), against time.

    The methods share the noise sequence, so the difference isolates what the outer-loop
    method changes; curves that overlap in :func:`errors_figure` separate here.
    """
    base = baseline_method(logs)
    fig, axs = plt.subplots(len(_ERROR_LABELS), 1, figsize=(13, 10), sharex=True)
    b = logs[base]
    eb = tracking_errors(b)
    others = [n for n in logs if n != base]
    for name in others:
        log = logs[name]
        k = min(log.n_outer, b.n_outer)
        err = tracking_errors(log)
        for a, (key, _) in zip(axs, _ERROR_LABELS, strict=True):
            d = err[key][:k] - eb[key][:k]
            peak = float(np.max(np.abs(d))) if k else float("nan")
            a.plot(log.t_outer[:k], d, lw=0.9, label=f"{name} − {base} (max |Δ| {peak:.2g})",
                   **_style(name, k))
    for a, (_, lab) in zip(axs, _ERROR_LABELS, strict=True):
        a.axhline(0.0, color="k", lw=0.6)
        a.set_ylabel("Δ " + lab)
        a.grid(alpha=0.3)
        if others:  # beside the axes: a legend inside would hide the peaks it describes
            a.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.005, 0.5), frameon=False)
    if not others:
        axs[0].text(0.5, 0.5, f"one method ({base}): nothing to compare", transform=axs[0].transAxes,
                    ha="center")
    axs[0].set_title(f"tracking errors minus the {base} baseline (same noise sequence)")
    axs[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def control_figure(logs: dict[str, RunLog], cfg: Config | None = None) -> Figure:
    """Inner control actions F_xR and δ with their saturation limits (inner saturation shaded),
    and the outer outputs v_ref, ω_ref with the MPC's input bounds (``cfg``; defaults if None)."""
    cfg = cfg if cfg is not None else Config()
    fig, axs = plt.subplots(2, 2, figsize=(12, 6.5), sharex=True)
    for name, log in logs.items():
        st = _style(name, log.t_inner.size)
        axs[0, 0].plot(log.t_inner, log.command[:, 0], lw=0.7, label=name, **st)
        axs[1, 0].plot(log.t_inner, np.degrees(log.command[:, 1]), lw=0.7, label=name, **st)
        so = _style(name, log.n_outer)
        axs[0, 1].plot(log.t_outer, log.u_c[:, 0], lw=0.9, label=name, **so)
        axs[1, 1].plot(log.t_outer, log.u_c[:, 1], lw=0.9, label=name, **so)
    lq, mpc = cfg.lqr, cfg.mpc
    limits = [
        (axs[0, 0], lq.force_limits(cfg.vehicle), "F_xR saturation"),
        (axs[1, 0], (-np.degrees(lq.delta_max), np.degrees(lq.delta_max)), "δ saturation"),
        (axs[0, 1], (mpc.u_min[0], mpc.u_max[0]), "MPC bound"),
        (axs[1, 1], (mpc.u_min[1], mpc.u_max[1]), "MPC bound"),
    ]
    for a, (lo, hi), lab in limits:
        a.axhline(lo, color="0.3", ls=(0, (6, 3)), lw=1.0, label=f"{lab} [{lo:.3g}, {hi:.3g}]")
        a.axhline(hi, color="0.3", ls=(0, (6, 3)), lw=1.0)
        span = hi - lo
        a.set_ylim(lo - 0.06 * span, hi + 0.06 * span)
    # Time steps where any method's inner loop saturated.
    saturated = any(log.saturated.any() for log in logs.values())
    for name, log in logs.items():
        if log.saturated.any():
            for a in (axs[0, 0], axs[1, 0]):
                a.fill_between(log.t_inner, 0, 1, where=log.saturated, transform=a.get_xaxis_transform(),
                               color=_c(name), alpha=0.15, lw=0)
    for a, lab in zip(axs.flat, ["F_xR [N]", "v_ref [m/s]", "δ [deg]", "ω_ref [rad/s]"], strict=True):
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
        a.legend(fontsize=7, ncol=3, loc="upper right")
    axs[1, 0].set_xlabel("t [s]")
    axs[1, 1].set_xlabel("t [s]")
    fig.suptitle("control actions with their limits" + (" (shaded: inner saturation active)" if saturated
                  else " (the inner loop never saturated)"), fontsize=10)
    fig.tight_layout()
    return fig


def friction_figure(logs: dict[str, RunLog]) -> Figure:
    """True friction force (μ(road) − μ_o) M g against the MHE-UIO estimate."""
    fig, axs = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    first = next(iter(logs.values()))
    axs[0].plot(first.t_inner, first.F_fr_true, "k-", lw=1.5, label="true F_fr")
    for name, log in logs.items():
        axs[0].plot(log.t_inner, log.F_fr_hat, lw=0.8, label=f"F̂_fr {name}", **_style(name, log.t_inner.size))
    axs[0].set_ylabel("F_fr = (μ(road) − μ_o) M g [N]", fontsize=9)
    if first.t_inner.size:  # explain the deepest dip: where the road resists less than the models
        i = int(np.argmin(first.F_fr_true))
        if first.F_fr_true[i] < 0.0:
            axs[0].annotate(f"μ(road) = {first.mu_road[i]:.2f} at t = {first.t_inner[i]:.1f} s: the road "
                            f"resists {abs(first.F_fr_true[i]):.0f} N less than the models assume",
                            xy=(first.t_inner[i], first.F_fr_true[i]), xytext=(0.02, 0.06),
                            textcoords="axes fraction", fontsize=8,
                            arrowprops={"arrowstyle": "->", "color": "0.4", "lw": 0.8})
    axs[0].legend(fontsize=8, ncol=3)
    axs[1].plot(first.t_inner, first.mu_road, "k-", lw=1.2)
    axs[1].set_ylabel("μ(road) [-]")
    axs[1].set_xlabel("t [s]")
    for a in axs:
        a.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def solve_time_figure(logs: dict[str, RunLog]) -> Figure:
    """Per-step MPC solve time of every method, log scale, against the T_c deadline."""
    fig, ax = plt.subplots(figsize=(11, 4.5))
    tc_ms = next(iter(logs.values())).Tc * 1e3
    for name, log in logs.items():
        ms = log.mpc_time_s * 1e3
        med = np.median(ms) if log.n_outer else float("nan")
        late = int(np.count_nonzero(ms > tc_ms))
        color, _, marker = _STYLES.get(name, _EXTRA[0])
        ax.semilogy(log.t_outer, ms, marker, ms=2.5, color=color, ls="none", alpha=0.7,
                    label=f"{name} (median {med:.3g} ms, {late} over T_c)")
    ax.axhline(tc_ms, color="k", ls="--", lw=1.2, label=f"T_c deadline ({tc_ms:.0f} ms)")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, max(hi, 8.0 * tc_ms))  # room above the deadline for the legend
    ax.set_xlabel("t [s]")
    ax.set_ylabel("MPC step time [ms]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, markerscale=3, loc="upper left", ncol=3)
    fig.tight_layout()
    return fig


FIGURES: dict[str, Any] = {
    "circuit": circuit_figure,
    "velocities": velocity_figure,
    "errors": errors_figure,
    "differences": differences_figure,
    "control": control_figure,
    "friction": friction_figure,
    "solve_time": solve_time_figure,
}


def save_all(logs: dict[str, RunLog], out_dir: str | Path, cfg: Config | None = None) -> list[Path]:
    """Write every figure as PNG and PDF into ``out_dir``; returns the paths written.

    ``cfg`` gives the saturation limits of the control figure (the defaults when None)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, make in FIGURES.items():
        fig = make(logs, cfg) if make is control_figure else make(logs)
        try:
            for ext in ("png", "pdf"):
                path = out / f"{name}.{ext}"
                atomic_savefig(fig, path, dpi=130)  # interrupted, disk full: no partial file
                written.append(path)
        finally:
            plt.close(fig)
    return written
