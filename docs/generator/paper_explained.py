"""Table 5 explained, the presentation (the published run): Markdown tables and figures from the rows
measured by :mod:`generator.paper_explained_runs`, and the marked blocks of README.md and
docs/paper.md that ``examples/paper_explained.py --update-docs`` rewrites.

A docs generator calls :func:`generate` (runs, tables, figures) and :func:`update_block` (text)."""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tsmpc.sim.log import RunLog
from tsmpc.sim.metrics import PAPER_TABLE5, RMSE_KEYS, tracking_errors

from .paper_explained_runs import RowResult

__all__ = [
    "ExplainedReport",
    "as_run_table",
    "attribution_text",
    "counterfactual_table",
    "design_points_table",
    "estimator_forms_figure",
    "evidence_text",
    "generate",
    "outside_table",
    "sensitivity_table",
    "startup_figure",
    "trends_text",
    "update_block",
    "walk_table",
]

#: The published run's start-up transient as reported for the published run (read off the paper's figures):
#: (quantity, peak, time [s]). Shown as markers beside the measured curves, never as measurements.
PUBLISHED_TRANSIENT = (("e_y [m]", 1.9, 4.0), ("e_θ [deg]", 8.0, 2.0), ("ω_d − ω [deg/s]", 6.0, None))


def _f(key: str, v: float) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.4f}" if key in ("theta", "omega") else f"{v:.3f}"


def _cell(text: str) -> str:
    """``text`` safe inside a Markdown table cell (``|`` escaped)."""
    return text.replace("|", "\\|")


def _ratio(v: float, p: float) -> str:
    return f"{v / p:.2f}×" if p else "—"


def as_run_table(results: Sequence[RowResult]) -> str:
    """``paper-as-run`` per method beside Table 5: our convention, the published run's
    convention, and the ratio of the latter to Table 5 (the acceptance band is ½–2×)."""
    head = ("| approach | convention | x [m] | y [m] | θ [rad] | v [m/s] | ω [rad/s] "
            "| e_y peak, first 8 s [m] |\n|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in results:
        paper = PAPER_TABLE5.get(r.method)
        ours, pr = r.metrics["rmse"], r.metrics["rmse_paper_run"]
        tr = r.transient
        if r.metrics["termination"] != "completed":
            lines.append(f"| {r.method} | **diverged** | — | — | — | — | — | "
                         f"{abs(tr.ey_peak_m):.2f} at {tr.ey_peak_t_s:.1f} s |")
            lines.append(f"| {r.method} | ours, up to the divergence "
                         f"({r.metrics['termination'].split(' at ')[-1]}) | "
                         + " | ".join(_f(k, ours[k]) for k in RMSE_KEYS) + " | |")
            if paper:
                lines.append(f"| {r.method} | Table 5 | "
                             + " | ".join(_f(k, paper[k]) for k in RMSE_KEYS) + " | |")
            continue
        lines.append(f"| {r.method} | ours | " + " | ".join(_f(k, ours[k]) for k in RMSE_KEYS)
                     + f" | {abs(tr.ey_peak_m):.2f} at {tr.ey_peak_t_s:.1f} s |")
        lines.append(f"| {r.method} | paper-run | " + " | ".join(_f(k, pr[k]) for k in RMSE_KEYS)
                     + " | |")
        if paper:
            lines.append(f"| {r.method} | Table 5 | " + " | ".join(_f(k, paper[k]) for k in RMSE_KEYS)
                         + " | ≈ 1.9 at ≈ 4 s (published run) |")
            lines.append(f"| {r.method} | paper-run ÷ Table 5 | "
                         + " | ".join(_ratio(pr[k], paper[k]) for k in RMSE_KEYS) + " | |")
    return "\n".join(lines) + "\n"


def walk_table(results: Sequence[RowResult], *, convention: str = "rmse") -> str:
    """The walk from ``paper-as-run`` to the paper preset and on to the default: one row per
    result (REF), RMSE in ``convention`` ("rmse" ours, "rmse_paper_run" the published run's),
    the start-up peaks, max |e_x| and the switch each row changes."""
    lines = ["| row | x | y | θ | v | ω | e_y peak (8 s) [m] | e_θ peak [°] | max \\|e_x\\| [m] "
             "| switch |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        m = r.metrics
        if m["termination"] != "completed":
            lines.append(f"| {r.label} | diverged | — | — | — | — | — | — | — | {r.what} |")
            continue
        e = m[convention]
        tr = r.transient
        bold = r.kind in ("as-run", "paper") or "(= default)" in r.label
        label = f"**{r.label}**" if bold else r.label
        xmax = r.max_abs_longitudinal_m
        lines.append(f"| {label} | " + " | ".join(_f(k, e[k]) for k in RMSE_KEYS)
                     + f" | {abs(tr.ey_peak_m):.2f} | {abs(math.degrees(tr.eth_peak_rad)):.1f} "
                     f"| {xmax:.2f} | {r.what} |")
    paper = PAPER_TABLE5["REF"]
    lines.append("| REF, paper Table 5 | " + " | ".join(_f(k, paper[k]) for k in RMSE_KEYS)
                 + " | ≈ 1.9 | ≈ 8 | — | as published (MATLAB; the transient as reported) |")
    return "\n".join(lines) + "\n"


def sensitivity_table(results: Sequence[RowResult]) -> str:
    """The gain-sensitivity study: transient peaks and RMSE per scaling of the steering ζ gain."""
    lines = ["| steering row | δ_f / ζ | e_y peak [m] at [s] | e_θ peak [°] at [s] "
             "| ω error peak [°/s] | x | y | θ | v | ω |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        tr, e = r.transient, r.metrics["rmse_paper_run"]
        ratio = r.what.rsplit("=", 1)[-1].strip()
        lines.append(f"| {r.label} | {ratio} | {abs(tr.ey_peak_m):.2f} at {tr.ey_peak_t_s:.1f} "
                     f"| {abs(math.degrees(tr.eth_peak_rad)):.1f} at {tr.eth_peak_t_s:.1f} "
                     f"| {abs(math.degrees(tr.omega_err_peak)):.1f} | "
                     + " | ".join(_f(k, e[k]) for k in RMSE_KEYS) + " |")
    lines.append("| published run | unknown | ≈ 1.9 at ≈ 4 | ≈ 8 at ≈ 2 | ≈ 6 | "
                 + " | ".join(_f(k, PAPER_TABLE5["REF"][k]) for k in RMSE_KEYS) + " |")
    return "\n".join(lines) + "\n"


def outside_table(results: Sequence[RowResult], start_s: float, end_s: float) -> str:
    """Each method's RMSE (our convention) over the run *outside* the reference-time span
    [start_s, end_s], with the ratio to Table 5: what the columns are without the stretch where
    the speed channel runs out of headroom."""
    lines = ["| approach | steps | x | y | θ | v | ω | ÷ Table 5 (x, y, θ, v, ω) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        if r.log is None:
            continue
        err = tracking_errors(r.log)
        t = r.log.t_outer - r.log.t_outer[0]
        m = (t < start_s) | (t > end_s)
        rms = {k: float(np.sqrt(np.mean(err[k][m] ** 2))) for k in RMSE_KEYS}
        paper = PAPER_TABLE5.get(r.method, {})
        ratios = ", ".join(_ratio(rms[k], paper[k]) for k in RMSE_KEYS) if paper else "—"
        until = "" if r.metrics["termination"] == "completed" else " (until it diverged)"
        lines.append(f"| {r.method} | {int(m.sum())}{until} | "
                     + " | ".join(_f(k, rms[k]) for k in RMSE_KEYS) + f" | {ratios} |")
    return "\n".join(lines) + "\n"


def evidence_text(headroom: Any, stretch: Any, as_run: Sequence[RowResult],
                  sens: Sequence[RowResult], counterfactual: Sequence[RowResult] = (),
                  onset: tuple[float, float] | None = None) -> str:
    """The measured facts behind the columns that leave the ½–2× band (a Markdown list):
    the speed headroom (x, v), NL's divergence (``onset``: when NL's e_y first departs from
    REF's, :func:`~generator.paper_explained_runs.divergence_onset`; ``counterfactual``: the runs of
    :func:`~generator.paper_explained_runs.headroom_counterfactuals`) and the start-up transient."""
    h = headroom
    short = h.force_needed_N - h.force_at_bound_N
    need = h.v_ref_bound + short / h.gain_N_per_mps
    lines = [
        f"* **x, v (the speed headroom).** With the gains of the preset's design, the as-run "
        f"law's steady force at {h.v:.2f} m/s (the fastest reference sample, 1 % slower for the "
        f"time-base drift) is {h.force_at_bound_N:.0f} N with v_ref at the MPC's bound of "
        f"{h.v_ref_bound:g} m/s ({h.gain_N_per_mps:.0f} N per m/s of v_ref); the plant needs "
        f"{h.force_needed_N:.0f} N there (dry asphalt, no compensation): {short:.0f} N short — "
        f"holding that speed would take v_ref ≈ {need:.1f} m/s, above the bound."]
    if stretch is not None:
        lines.append(
            f"  So |e_x| exceeds {stretch.threshold_m:g} m from {stretch.start_s:.1f} s to "
            f"{stretch.end_s:.1f} s (max {stretch.max_abs_m:.1f} m), and RMSE_x is "
            f"{stretch.rmse_x_inside_m:.2f} m inside that stretch and {stretch.rmse_x_outside_m:.3f} m "
            "outside it (Table 5: 0.501 m).")
    for r in as_run:
        if r.metrics["termination"] != "completed":
            ev = r.metrics.get("events", {})
            fails = ", ".join(f"{k} = {ev.get(k, 0)}" for k in ("mpc_soft", "mpc_fallback",
                                                                "step_errors"))
            text = (f"* **{r.method} {r.metrics['termination']}** — on that stretch, with no solver "
                    f"failure ({fails}).")
            if onset is not None:
                from tsmpc.config import Config

                q = Config.preset("paper-as-run").mpc.Q
                text += (f" Its lateral error follows REF's to within 0.1 m until {onset[0]:.1f} s, "
                         f"when |e_x| is {onset[1]:.1f} m: from there the NL-MPC, whose model "
                         "couples e_x and e_y through ω (ė_x = ω e_y − v + v_d cos e_θ, "
                         "ė_y = −ω e_x + v_d sin e_θ), plans to close the heavily weighted e_x "
                         f"(Q = {q[0]:g}) by cutting the curve at the price of the cheap e_y "
                         f"(Q = {q[1]:g}), on the premise that the car reaches v_ref = "
                         f"{h.v_ref_bound:g} m/s. The car does not, so every step re-plans the "
                         "same cut and e_y accumulates. The TS-MPC schedules that coupling on ω_d "
                         "(REF) or the current ω (FZN), fixed over the horizon, and cannot trade it.")
            lines.append(text)
    done = [r for r in counterfactual if r.metrics["termination"] == "completed"]
    if counterfactual:
        by_label: dict[str, list[RowResult]] = {}
        for r in counterfactual:
            by_label.setdefault(r.label, []).append(r)
        parts = []
        for label, rs in by_label.items():
            xs = ", ".join(f"{r.method} {r.metrics['rmse_paper_run']['x']:.3f} m"
                           if r.metrics["termination"] == "completed" else f"{r.method} diverged"
                           for r in rs)
            parts.append(f"{label}: {xs}")
        lines.append(
            "* **Test of that explanation** (the runs of “Testing the explanation” in docs/paper.md): "
            "removing the shortfall either way — the "
            "MPC's bound raised, or the gains' speed entry scaled — gives RMSE_x (paper-run) "
            + "; ".join(parts) + f"; {len(done)} of {len(counterfactual)} runs complete.")
    if len(sens) > 1:
        s0, s1 = sens[0], sens[-1]
        lines.append(
            f"* **y, θ, ω (the start-up transient).** The steering row of the preset's gains has "
            f"{s0.what.split('steering row ', 1)[-1]}: the e_y peak is {abs(s0.transient.ey_peak_m):.2f} m "
            f"at {s0.transient.ey_peak_t_s:.1f} s; with the ζ entry × {s1.label.rsplit(' ', 1)[-1]} "
            f"({s1.what.split('steering row ', 1)[-1]}) it is {abs(s1.transient.ey_peak_m):.2f} m at "
            f"{s1.transient.ey_peak_t_s:.1f} s (published: ≈ 1.9 m at ≈ 4 s). Which point of the "
            "feasible set the published solver returned is unknown (the design points of “What the gains "
            "decide” in docs/paper.md).")
    return "\n".join(lines) + "\n"


def _spread(values: Sequence[float]) -> float:
    """(max / min − 1) in percent."""
    return 100.0 * (max(values) / max(min(values), 1e-12) - 1.0)


def _trend_check(e: dict[str, dict[str, float]]) -> str:
    """'REF ≤ FZN …; NL …' for the RMSE dicts ``e`` by method (FZN, REF and maybe NL)."""
    fails = [_COLUMN[k][0] for k in RMSE_KEYS if e["REF"][k] > e["FZN"][k]]
    out = "REF ≤ FZN in every column" if not fails else f"REF ≤ FZN except {', '.join(fails)}"
    if "NL" in e:
        low_y = e["NL"]["y"] < min(e["FZN"]["y"], e["REF"]["y"])
        hi = [k for k in ("x", "v") if e["NL"][k] > max(e["FZN"][k], e["REF"][k])]
        out += (f"; NL {'lowest' if low_y else 'not lowest'} in y, "
                + ("highest in x and v" if len(hi) == 2 else
                   f"highest in {hi[0]} only" if hi else "not highest in x or v"))
    spread = ", ".join(f"{_COLUMN[k][0]} {_spread([v[k] for v in e.values()]):.1f} %"
                       for k in RMSE_KEYS)
    return f"{out} (spread between the methods: {spread})"


def trends_text(sets: dict[str, Sequence[RowResult]], after_s: float = 10.0) -> str:
    """The paper's trends (REF ≤ FZN in every column; NL lowest in y, highest in x and v) checked
    on each set of runs (FZN, REF, NL of one configuration; paper-run RMSE), with the spread
    between the methods, and again over the run after the start-up (t ≥ ``after_s``, our RMSE
    convention; when the runs kept their logs): one line per set, Table 5's last."""
    lines = []
    for name, rs in sets.items():
        by = {r.method: r for r in rs}
        if not {"FZN", "REF"} <= by.keys():
            continue
        ok = {m: r.metrics["termination"] == "completed" for m, r in by.items()}
        if not (ok["FZN"] and ok["REF"]):
            continue
        done = {m: r for m, r in by.items() if ok[m]}
        text = f"* {name}: {_trend_check({m: r.metrics['rmse_paper_run'] for m, r in done.items()})}"
        if not ok.get("NL", True):
            text += "; NL diverged"
        logs = {m: r.log for m, r in done.items() if r.log is not None}
        if len(logs) == len(done):
            after = {}
            for m, log in logs.items():
                err = tracking_errors(log)
                t = log.t_outer - log.t_outer[0]
                keep = t >= after_s
                after[m] = {k: float(np.sqrt(np.mean(err[k][keep] ** 2))) if keep.any()
                            else float("nan") for k in RMSE_KEYS}
            if all(np.isfinite(v).all() for e in after.values() for v in e.values()):
                text += f". After the start-up (t ≥ {after_s:g} s): {_trend_check(after)}"
        lines.append(text + ".")
    spread = ", ".join(f"{_COLUMN[k][0]} {_spread([v[k] for v in PAPER_TABLE5.values()]):.0f} %"
                       for k in RMSE_KEYS)
    lines.append(f"* Table 5: REF ≤ FZN in every column; NL lowest in y, highest in x and v "
                 f"(spread: {spread}).")
    return "\n".join(lines) + "\n"


def design_points_table(points: Sequence[Any]) -> str:
    """The feasibility LMI's points (:func:`~generator.paper_explained_runs.design_points`): solver,
    certificates, the two gain properties that decide the misses, and the REF run (paper-run
    RMSE; a shortened run for an uncertified point)."""
    lines = ["| point of the feasible set | solver | certificates (worst relative margin) "
             "| δ_f / ζ | speed gain [N per m/s] | force at v_ref = 18 m/s (needed) [N] "
             "| e_y peak [m] at [s] | x | y | θ | v | ω | run |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for p in points:
        r = p.result
        tr, h = r.transient, p.headroom
        e = r.metrics["rmse_paper_run"]
        cols = (" | ".join(_f(k, e[k]) for k in RMSE_KEYS) if p.certified
                else " | ".join("—" for _ in RMSE_KEYS))
        run = _cell(r.metrics["termination"])
        if p.max_steps is not None:
            run = f"{run} (run limited to {p.max_steps} steps)"
        cert = ("hold" if p.certified else "**fail**") + f" ({p.worst_relative:.1e})"
        lines.append(f"| {p.label} | {p.status} | {cert} | {p.steering_ratio:.2f} "
                     f"| {h.gain_N_per_mps:.0f} | {h.force_at_bound_N:.0f} ({h.force_needed_N:.0f}) "
                     f"| {abs(tr.ey_peak_m):.2f} at {tr.ey_peak_t_s:.1f} | {cols} | {run} |")
    return "\n".join(lines) + "\n"


def counterfactual_table(as_run: Sequence[RowResult], rows: Sequence[RowResult]) -> str:
    """``paper-as-run`` and the counterfactuals of
    :func:`~generator.paper_explained_runs.headroom_counterfactuals` per method (paper-run RMSE and
    its ratio to Table 5, max |e_x|)."""
    lines = ["| change | method | run | x | y | θ | v | ω | ÷ Table 5 (x, y, θ, v, ω) "
             "| max \\|e_x\\| [m] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in [*as_run, *rows]:
        label = "— (paper-as-run)" if r.kind == "as-run" else f"{r.label}: {r.what}"
        if r.metrics["termination"] != "completed":
            lines.append(f"| {label} | {r.method} | {_cell(r.metrics['termination'])} | — | — | — | — | — "
                         f"| — | {r.max_abs_longitudinal_m:.2f} |")
            continue
        e = r.metrics["rmse_paper_run"]
        paper = PAPER_TABLE5.get(r.method, {})
        ratios = ", ".join(_ratio(e[k], paper[k]) for k in RMSE_KEYS) if paper else "—"
        lines.append(f"| {label} | {r.method} | completed | "
                     + " | ".join(_f(k, e[k]) for k in RMSE_KEYS)
                     + f" | {ratios} | {r.max_abs_longitudinal_m:.2f} |")
    return "\n".join(lines) + "\n"


_COLUMN = {"x": ("x", "m"), "y": ("y", "m"), "theta": ("θ", "rad"), "v": ("v", "m/s"),
           "omega": ("ω", "rad/s")}


def attribution_text(walk: Sequence[RowResult], *, top: int = 2) -> str:
    """Which quirk accounts for which column: for every column, the removals of the walk (from
    ``paper-as-run`` to the paper preset) that change its RMSE most, with the values before and
    after (a Markdown list)."""
    steps = [r for r in walk if r.kind in ("as-run", "walk", "paper")]
    lines = []
    for key, (sym, unit) in _COLUMN.items():
        deltas = []
        for a, b in itertools.pairwise(steps):
            if a.metrics["termination"] != "completed" or b.metrics["termination"] != "completed":
                continue
            va, vb = a.metrics["rmse"][key], b.metrics["rmse"][key]
            deltas.append((abs(vb - va), b.label.lstrip("− ").replace(" (= paper preset)", ""), va, vb))
        deltas.sort(reverse=True)
        first, last = steps[0].metrics["rmse"][key], steps[-1].metrics["rmse"][key]
        parts = [f"{name} ({_f(key, va)} → {_f(key, vb)})" for _, name, va, vb in deltas[:top]]
        lines.append(f"* **{sym}** [{unit}] {_f(key, first)} → {_f(key, last)}: " + "; ".join(parts))
    return "\n".join(lines) + "\n"


def startup_figure(logs: dict[str, RunLog], seconds: float = 15.0) -> Any:
    """e_y, e_θ and ω_d − ω over the first ``seconds`` of each run (reference time from the first
    sample), with the published run's reported peaks (the published run) as hollow markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    styles = ["-", "--", "-.", ":"]
    for i, (label, log) in enumerate(logs.items()):
        err = tracking_errors(log)
        t = log.t_outer - log.t_outer[0]
        m = t <= seconds + 1e-9
        kw = {"lw": 1.3, "ls": styles[i % len(styles)], "label": label}
        axs[0].plot(t[m], err["y"][m], **kw)
        axs[1].plot(t[m], np.degrees(err["theta"][m]), **kw)
        axs[2].plot(t[m], np.degrees(err["omega"][m]), **kw)
    for a, (name, peak, when) in zip(axs, PUBLISHED_TRANSIENT, strict=True):
        a.axhline(0.0, color="k", lw=0.6)
        if when is None:
            for s in (1, -1):
                a.axhline(s * peak, color="0.4", ls=(0, (2, 3)), lw=1.0,
                          label="published run, ≈ ±6°/s (the published run)" if s == 1 else None)
        else:
            a.plot([when], [peak], "o", ms=9, mfc="none", mec="k", mew=1.5,
                   label=f"published run, ≈ {peak:g} at ≈ {when:g} s (the published run)")
        a.set_ylabel(name)
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="upper right")
    axs[-1].set_xlabel("t [s] (reference time from the first sample)")
    axs[0].set_title(f"start-up transient, first {seconds:g} s (REF, paper reference)")
    fig.tight_layout()
    return fig


def estimator_forms_figure(columns: dict[str, dict[str, RunLog]]) -> Any:
    """The two MHE-UIO forms on the same runs, one column per run (e.g. without and with sensor
    noise): the friction force (true and each form's estimate that reaches the controller, the
    axis limited to the true force ± 3 kN) and the slip angle (true and each estimate)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncol = len(columns)
    fig, axs = plt.subplots(2, ncol, figsize=(7 * ncol, 7), sharex=True, squeeze=False)
    for j, (title, logs) in enumerate(columns.items()):
        first = next(iter(logs.values()))
        t0 = first.t_inner - first.t_inner[0]
        axs[0, j].plot(t0, first.F_fr_true, "k-", lw=1.6, label="true F_fr = (μ(road) − μ_o) M g")
        axs[1, j].plot(t0, first.state[:, 4], "k-", lw=1.6, label="true α")
        # the noisier estimate is drawn first (behind); a form keeps its colour in every column
        order = sorted(logs.items(), key=lambda kv: -float(np.std(kv[1].F_fr_hat - kv[1].F_fr_true)))
        for z, (label, log) in enumerate(order):
            color = "tab:orange" if "UIO" in label else "tab:blue"
            t = log.t_inner - log.t_inner[0]
            err = log.F_fr_hat - log.F_fr_true
            f_rms = float(np.sqrt(np.mean(err**2)))
            a_rms = float(np.sqrt(np.mean((log.estimate[:, 1] - log.state[:, 4]) ** 2)))
            lab = f"F̂ {label} (RMS error {f_rms:.0f} N)"
            noisy = f_rms > 1000.0 and t.size > 10
            if noisy:  # raw (light) and its 1-s mean: the raw trace alone fills the axis
                w = max(1, round(1.0 / float(np.median(np.diff(t)))))
                mean = np.convolve(log.F_fr_hat, np.ones(w) / w, mode="same")
                axs[0, j].plot(t, log.F_fr_hat, lw=0.4, color=color, alpha=0.15, zorder=1 + z)
                axs[0, j].plot(t, mean, lw=1.0, color=color, zorder=1 + z, label=lab + ", 1-s mean")
            else:
                axs[0, j].plot(t, log.F_fr_hat, lw=0.8, color=color, zorder=1 + z, label=lab)
            axs[1, j].plot(t, log.estimate[:, 1], lw=0.7, ls="--", color=color, zorder=1 + z,
                           label=f"α̂ {label} (RMS error {a_rms:.4f} rad)")
        for a in axs[:, j]:
            for line in a.get_lines()[:1]:
                line.set_zorder(10)
        lo, hi = float(np.min(first.F_fr_true)), float(np.max(first.F_fr_true))
        axs[0, j].set_ylim(lo - 3000.0, hi + 3000.0)
        late = t0 > 5.0  # the start-up transient of α is clipped (its extreme in the title)
        if np.any(late):
            a_lo, a_hi = float(np.min(first.state[late, 4])), float(np.max(first.state[late, 4]))
            pad = 0.5 * max(a_hi - a_lo, 1e-3)
            axs[1, j].set_ylim(a_lo - pad, a_hi + pad)
            axs[1, j].set_title(f"α axis clipped: the start-up reaches {np.min(first.state[:, 4]):.2f} rad",
                                fontsize=8)
        axs[0, j].set_title(title, fontsize=10)
        axs[0, j].set_ylabel("F_fr [N]")
        axs[1, j].set_ylabel("α [rad]")
        axs[1, j].set_xlabel("t [s]")
        for a in axs[:, j]:
            a.grid(alpha=0.3)
            a.legend(fontsize=7, loc="lower right")
    fig.suptitle("MHE-UIO: window-constant friction (ours) vs the paper's UIO form", fontsize=11)
    fig.tight_layout()
    return fig


def update_block(text: str, name: str, body: str) -> str:
    """``text`` with the block between ``<!-- paper-explained:NAME:begin -->`` and
    ``<!-- paper-explained:NAME:end -->`` replaced by ``body`` (the docs' one marker scheme,
    :func:`generator.blocks.update_block`). Raises ValueError when the markers are missing (a
    generator must never append blindly)."""
    from .blocks import BlockId
    from .blocks import update_block as update

    return update(text, BlockId("paper-explained", name), body)


@dataclass(frozen=True)
class ExplainedReport:
    """Everything the docs show: the Markdown blocks by name and the figures written."""

    blocks: dict[str, str]
    figures: tuple[Path, ...]
    results: dict[str, list[RowResult]]


def generate(reference: Path, img_dir: Path | None = None, *, max_steps: int | None = None,
             progress: Callable[[str], None] | None = None, estimator_forms: bool = True
             ) -> ExplainedReport:
    """Measure every row (:mod:`generator.paper_explained_runs`), format the tables and, with
    ``img_dir``, write ``paper_explained_startup.png`` and ``paper_explained_estimator.png``.
    ``max_steps`` shortens every run (tests)."""
    from tsmpc.sim.simulator import Method

    from .paper_explained_runs import (
        ablation_rows,
        design_points,
        divergence_onset,
        gain_sensitivity,
        headroom_counterfactuals,
        measure,
        walk_rows,
    )

    walk = walk_rows()
    as_run = measure(reference, walk[:1], methods=(Method.FZN, Method.REF, Method.NL),
                     max_steps=max_steps, keep_logs=True, progress=progress)
    rest = measure(reference, [*walk[1:], *ablation_rows()], max_steps=max_steps, keep_logs=True,
                   progress=progress)
    as_run_ref = next(r for r in as_run if r.method == "REF")
    from tsmpc.config import Config
    from tsmpc.sim.compare import load_scenario
    from tsmpc.synthesis.cache import load_or_design_dynamic

    from .paper_explained_runs import longitudinal_stretch, speed_headroom

    cfg = Config.preset("paper-as-run")
    v_d_max = float(np.max(load_scenario(cfg, reference).reference.v))
    headroom = speed_headroom(cfg, load_or_design_dynamic(cfg), v_d_max)
    assert as_run_ref.log is not None
    stretch = longitudinal_stretch(as_run_ref.log)
    rows = [as_run_ref, *rest]
    if progress is not None:
        progress("gain sensitivity")
    sens = gain_sensitivity(reference, max_steps=max_steps, keep_logs=True)
    if progress is not None:
        progress("design points of the feasibility LMI")
    points = design_points(reference, as_run_ref, max_steps=max_steps)
    cf = headroom_counterfactuals(reference, max_steps=max_steps, keep_logs=True, progress=progress)
    by_method = {r.method: r for r in as_run}
    onset = None
    if "NL" in by_method and by_method["NL"].log is not None and as_run_ref.log is not None:
        onset = divergence_onset(by_method["NL"].log, as_run_ref.log)
    cf_sets: dict[str, list[RowResult]] = {"paper-as-run": list(as_run)}
    for r in cf:
        cf_sets.setdefault(f"{r.label} ({r.what})", []).append(r)
    blocks = {
        "as-run": as_run_table(as_run),
        "evidence": evidence_text(headroom, stretch, as_run, sens, cf, onset)
        + ("" if stretch is None else "\nThe same runs without that stretch "
           f"({stretch.start_s:.1f}–{stretch.end_s:.1f} s):\n\n"
           + outside_table(as_run, stretch.start_s, stretch.end_s)),
        "counterfactual": counterfactual_table(as_run, cf),
        "trends": trends_text(cf_sets),
        "walk": walk_table(rows),
        "attribution": attribution_text(rows),
        "walk-paper-run": walk_table(rows, convention="rmse_paper_run"),
        "design-points": design_points_table(points),
        "sensitivity": sensitivity_table(sens),
    }
    results: dict[str, list[RowResult]] = {"as-run": as_run, "walk": rows, "sensitivity": sens,
                                           "counterfactual": cf,
                                           "design-points": [p.result for p in points]}
    figures: list[Path] = []
    if img_dir is not None:
        import matplotlib.pyplot as plt

        img_dir.mkdir(parents=True, exist_ok=True)
        picks = {"paper-as-run": as_run_ref.log,
                 f"paper-as-run, steering ζ gain × {sens[-1].label.rsplit(' ', 1)[-1]} (study)":
                     sens[-1].log,
                 "− steering bias": next(r.log for r in rows if r.label.startswith("− steering bias")),
                 "paper preset": next(r.log for r in rows if r.kind == "paper")}
        fig = startup_figure({k: v for k, v in picks.items() if v is not None})
        path = img_dir / "paper_explained_startup.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        figures.append(path)
        if estimator_forms:
            cols, est_rows = _estimator_runs(reference, as_run_ref, max_steps, progress)
            results["estimator"] = est_rows
            fig = estimator_forms_figure(cols)
            path = img_dir / "paper_explained_estimator.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            figures.append(path)
            blocks["estimator"] = _estimator_block(est_rows)
    return ExplainedReport(blocks, tuple(figures), results)


def _estimator_runs(reference: Path, as_run_ref: RowResult, max_steps: int | None,
                    progress: Callable[[str], None] | None
                    ) -> tuple[dict[str, dict[str, RunLog]], list[RowResult]]:
    """``paper-as-run`` with each MHE form, without and with the default sensor noise. The MHE is
    computed but unused there (the inner law runs on the true state, no compensation), so both
    forms estimate from the same run."""
    from tsmpc.config import Config, replace

    from .paper_explained_runs import ExplainedRow, run_row

    cfg = Config.preset("paper-as-run")
    noisy = replace(cfg, noise=replace(cfg.noise, scale=1.0))
    specs = [("window", "no noise", cfg, as_run_ref), ("uio", "no noise", cfg, None),
             ("window", "default noise", noisy, None), ("uio", "default noise", noisy, None)]
    cols: dict[str, dict[str, RunLog]] = {}
    rows = []
    for form, noise, base, done in specs:
        label = f"mhe.form = {form}, {noise}"
        if done is None:
            row = ExplainedRow(label, replace(base, mhe=replace(base.mhe, form=form)), form, "study")
            if progress is not None:
                progress(f"paper-as-run, {label}")
            done = run_row(row, reference, max_steps=max_steps, keep_log=True)
        rows.append(RowResult(label, done.method, form, "study", done.metrics, done.transient,
                              done.max_abs_longitudinal_m, done.log))
        name = "window form (ours)" if form == "window" else "UIO form (paper)"
        assert done.log is not None
        cols.setdefault(f"paper-as-run, {noise} (T_d = 1 ms)", {})[name] = done.log
    return cols, rows


def _estimator_block(rows: Sequence[RowResult]) -> str:
    lines = ["| run (paper-as-run, same trajectory for both forms) | MHE form | F̂_fr RMS error [N] "
             "| α̂ RMS error [rad] | v̂ RMS error [m/s] | MHE step median / p99 [ms] |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        m = r.metrics
        form = ("window-constant friction (ours, compiled)" if r.what == "window"
                else "the paper's UIO form (numpy path)")
        noise = r.label.split(", ", 1)[1]
        lines.append(f"| {noise} | {form} | {m['friction_rmse_N']:.0f} | {m['slip_rmse_rad']:.4f} "
                     f"| {m['speed_estimate_rmse']:.4f} | {m['mhe_ms']['median']:.3f} / "
                     f"{m['mhe_ms']['p99']:.3f} |")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines.append(f"\n(step times measured inside the runs, load average {load:.1f} on this machine)")
    return "\n".join(lines) + "\n"
