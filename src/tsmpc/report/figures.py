"""The paper's figures from run logs: circuit with a zoom, velocities, errors, control actions,
friction force true vs estimated, per-step MPC solve time (log scale). Each function takes the
logs (and optionally an Axes) and returns the Figure; :func:`save_all` writes PNG and PDF.
Only this module imports matplotlib (Agg backend)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from tsmpc.sim.log import RunLog
from tsmpc.sim.metrics import tracking_errors

__all__ = [
    "circuit_figure",
    "control_figure",
    "errors_figure",
    "friction_figure",
    "save_all",
    "solve_time_figure",
    "velocity_figure",
]

_COLORS = {"FZN": "tab:blue", "REF": "tab:orange", "ITER": "tab:green", "NL": "tab:red"}


def _c(method: str) -> str:
    return _COLORS.get(method, "tab:purple")


def circuit_figure(logs: dict[str, RunLog]) -> Figure:
    """Reference path and driven paths, with a zoom on the point of largest lateral error."""
    fig, (ax, axz) = plt.subplots(1, 2, figsize=(12, 5.5), gridspec_kw={"width_ratios": [1.6, 1]})
    first = next(iter(logs.values()))
    for a in (ax, axz):
        a.plot(first.ref[:, 0], first.ref[:, 1], "k--", lw=1.2, label="reference")
        for name, log in logs.items():
            a.plot(log.state_outer[:, 0], log.state_outer[:, 1], color=_c(name), lw=1.0, label=name)
        # The overview adapts its limits to the data; the zoom keeps its fixed window.
        a.set_aspect("equal", adjustable="datalim" if a is ax else "box")
        a.set_xlabel("X [m]")
        a.set_ylabel("Y [m]")
    ax.plot(first.ref[0, 0], first.ref[0, 1], "go", ms=6, label="start")
    k = int(np.argmax(np.abs(first.errors[:, 1]))) if first.n_outer else 0
    cx, cy = first.ref[k, 0], first.ref[k, 1]
    r = 6.0
    axz.set_xlim(cx - r, cx + r)
    axz.set_ylim(cy - r, cy + r)
    axz.set_title(f"zoom at t = {first.t_outer[k]:.1f} s (largest |e_y| of {first.method})")
    ax.add_patch(plt.Rectangle((cx - r, cy - r), 2 * r, 2 * r, fill=False, ec="0.4", lw=0.8))
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
    for name, log in logs.items():
        axs[0].plot(log.t_inner, log.state[:, 3], color=_c(name), lw=0.9, label=f"v {name}")
        axs[1].plot(log.t_inner, log.state[:, 5], color=_c(name), lw=0.9, label=f"ω {name}")
    axs[0].set_ylabel("v [m/s]")
    axs[1].set_ylabel("ω [rad/s]")
    axs[1].set_xlabel("t [s]")
    for a in axs:
        a.grid(alpha=0.3)
        a.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    return fig


def errors_figure(logs: dict[str, RunLog]) -> Figure:
    """e_x, e_y, e_θ, v_d − v, ω_d − ω against time."""
    labels = [("x", "e_x [m]"), ("y", "e_y [m]"), ("theta", "e_θ [rad]"),
              ("v", "v_d − v [m/s]"), ("omega", "ω_d − ω [rad/s]")]
    fig, axs = plt.subplots(5, 1, figsize=(11, 10), sharex=True)
    for name, log in logs.items():
        err = tracking_errors(log)
        for a, (key, _) in zip(axs, labels, strict=True):
            a.plot(log.t_outer, err[key], color=_c(name), lw=0.9, label=name)
    for a, (_, lab) in zip(axs, labels, strict=True):
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    axs[0].legend(fontsize=8, ncol=4)
    axs[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def control_figure(logs: dict[str, RunLog]) -> Figure:
    """Inner control actions F_xR and δ, and the outer outputs v_ref, ω_ref."""
    fig, axs = plt.subplots(2, 2, figsize=(12, 6), sharex=True)
    for name, log in logs.items():
        c = _c(name)
        axs[0, 0].plot(log.t_inner, log.command[:, 0], color=c, lw=0.7, label=name)
        axs[1, 0].plot(log.t_inner, np.degrees(log.command[:, 1]), color=c, lw=0.7, label=name)
        axs[0, 1].plot(log.t_outer, log.u_c[:, 0], color=c, lw=0.9, label=name)
        axs[1, 1].plot(log.t_outer, log.u_c[:, 1], color=c, lw=0.9, label=name)
    for a, lab in zip(axs.flat, ["F_xR [N]", "v_ref [m/s]", "δ [deg]", "ω_ref [rad/s]"], strict=True):
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    axs[0, 0].legend(fontsize=8, ncol=4)
    axs[1, 0].set_xlabel("t [s]")
    axs[1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def friction_figure(logs: dict[str, RunLog]) -> Figure:
    """True friction force (μ(road) − μ_o) M g against the MHE-UIO estimate."""
    fig, axs = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    first = next(iter(logs.values()))
    axs[0].plot(first.t_inner, first.F_fr_true, "k-", lw=1.5, label="true F_fr")
    for name, log in logs.items():
        axs[0].plot(log.t_inner, log.F_fr_hat, color=_c(name), lw=0.8, label=f"F̂_fr {name}")
    axs[0].set_ylabel("F_fr [N]")
    axs[0].legend(fontsize=8, ncol=3)
    axs[1].plot(first.t_inner, first.mu_road, "k-", lw=1.2)
    axs[1].set_ylabel("μ(road) [-]")
    axs[1].set_xlabel("t [s]")
    for a in axs:
        a.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def solve_time_figure(logs: dict[str, RunLog]) -> Figure:
    """Per-step MPC solve time of every method, log scale."""
    fig, ax = plt.subplots(figsize=(11, 4.5))
    for name, log in logs.items():
        med = np.median(log.mpc_time_s) * 1e3 if log.n_outer else float("nan")
        ax.semilogy(log.t_outer, log.mpc_time_s * 1e3, ".", ms=2.5, color=_c(name),
                    label=f"{name} (median {med:.3g} ms)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("MPC step time [ms]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, markerscale=4)
    fig.tight_layout()
    return fig


FIGURES: dict[str, Any] = {
    "circuit": circuit_figure,
    "velocities": velocity_figure,
    "errors": errors_figure,
    "control": control_figure,
    "friction": friction_figure,
    "solve_time": solve_time_figure,
}


def save_all(logs: dict[str, RunLog], out_dir: str | Path) -> list[Path]:
    """Write every figure as PNG and PDF into ``out_dir``; returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, make in FIGURES.items():
        fig = make(logs)
        for ext in ("png", "pdf"):
            path = out / f"{name}.{ext}"
            tmp = path.with_name(f".{path.name}.tmp.{ext}")
            fig.savefig(tmp, dpi=130)
            tmp.replace(path)
            written.append(path)
        plt.close(fig)
    return written
