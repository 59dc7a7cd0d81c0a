"""The mismatch benchmark's tables and figure (issue 21; ``examples/mismatch.toml``): from a sweep's
aggregate table (one row per run: reference × case × controller), the results per reference and
the acceptance check of the issue on the paper's reference:

* every case within 1.5× of the oracle-tuned row in every column (RMSE x, y, θ, v, ω and
  max |e_y|), with inner saturations ≤ 1.2× the oracle's;
* where the oracle-tuned row itself stays within 2× of the nominal row (else the loss is physics,
  not control): RMSE y ≤ 0.04 m, max |e_y| ≤ 0.25 m, RMSE v ≤ 0.15 m/s.

Computation only (the figure function takes an output path; matplotlib is imported there).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tsmpc.datasets import label as ref_name

__all__ = ["COLUMNS", "Verdict", "acceptance", "figure", "reference_table", "verdict_table"]

#: (aggregate column, label, format) of the result tables.
COLUMNS = (("rmse_x", "x [m]", "{:.3f}"), ("rmse_y", "y [m]", "{:.4f}"), ("rmse_theta", "θ [rad]", "{:.4f}"),
           ("rmse_v", "v [m/s]", "{:.3f}"), ("rmse_omega", "ω [rad/s]", "{:.4f}"),
           ("max_abs_lateral_m", "max abs e_y [m]", "{:.3f}"),
           ("events_inner_saturated", "saturated steps", "{:.0f}"))
#: The columns compared with the oracle-tuned row (ratio ≤ RATIO).
RATIO_COLUMNS = ("rmse_x", "rmse_y", "rmse_theta", "rmse_v", "rmse_omega", "max_abs_lateral_m")
RATIO = 1.5
SAT_RATIO = 1.2
PHYSICS_FACTOR = 2.0
#: Absolute bounds where the loss is not physics.
BOUNDS = {"rmse_y": 0.04, "max_abs_lateral_m": 0.25, "rmse_v": 0.15}


def reference_table(table: Any, track: str, cases: list[str], controllers: list[str]) -> str:
    """Markdown: one row per (case, controller) of reference ``track``."""
    sub = table[table["track"] == track]
    head = "| case | controller | " + " | ".join(c[1] for c in COLUMNS) + " | status |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 3)]
    for case in cases:
        for ctrl in controllers:
            r = sub[(sub["case"] == case) & (sub["controller"] == ctrl)]
            if r.empty:
                continue
            row = r.iloc[0]
            vals = []
            for key, _label, fmt in COLUMNS:
                v = row.get(key, math.nan)
                vals.append("—" if v is None or (isinstance(v, float) and math.isnan(v)) else fmt.format(v))
            status = str(row["status"])
            if status != "completed":
                status = f"**{status}**"
            lines.append(f"| {case} | {ctrl} | " + " | ".join(vals) + f" | {status} |")
    return "\n".join(lines)


@dataclass(frozen=True)
class Verdict:
    """The acceptance check of one case (default against oracle-tuned)."""

    case: str
    worst_ratio: float  #: largest default / oracle over RATIO_COLUMNS
    worst_column: str
    sat_ratio: float  #: default / oracle saturated steps (1 when both are 0)
    physics: bool  #: the oracle-tuned row leaves 2× nominal (or diverges where no controller completes)
    bounds_ok: bool | None  #: None when physics
    diverged: bool  #: the default run diverged
    passed: bool
    diverged_at: str = ""  #: when the default run diverged ("8.2 s"), from its record's reason
    completes: tuple[str, ...] = ()  #: the controllers that complete the case (when the oracle does not)


def _ratio(a: float, b: float) -> float:
    if b <= 0.0:
        return 1.0 if a <= 0.0 else math.inf
    return a / b


def acceptance(table: Any, track: str, cases: list[str], default: str = "default",
               oracle: str = "oracle-tuned", nominal: str = "nominal") -> list[Verdict]:
    """The issue's acceptance check per case on reference ``track``."""
    sub = table[table["track"] == track]

    def row(case: str, ctrl: str) -> Any:
        r = sub[(sub["case"] == case) & (sub["controller"] == ctrl)]
        return None if r.empty else r.iloc[0]

    nom = row(nominal, default)
    out = []
    for case in cases:
        d, o = row(case, default), row(case, oracle)
        if d is None or o is None or nom is None:
            continue
        ratios = {k: _ratio(float(d[k]), float(o[k])) for k in RATIO_COLUMNS}
        worst = max(ratios, key=lambda k: ratios[k])
        sat = _ratio(float(d["events_inner_saturated"]), float(o["events_inner_saturated"]))
        o_done = str(o["status"]) == "completed"
        # an oracle that leaves the road is physics only if no controller of the sweep stays on it
        done = tuple(str(r["controller"]) for _, r in sub[sub["case"] == case].iterrows()
                     if str(r["status"]) == "completed")
        physics = (not o_done and not done) or (
            o_done and any(float(o[k]) > PHYSICS_FACTOR * float(nom[k]) for k in RATIO_COLUMNS))
        diverged = str(d["status"]) != "completed"
        when = re.search(r"at t = ([0-9.]+) s", str(d.get("reason", ""))) if diverged else None
        bounds_ok = None if physics else all(float(d[k]) <= b for k, b in BOUNDS.items())
        # a run that leaves the road never meets the criteria, even beside an oracle that does too
        passed = not diverged and ratios[worst] <= RATIO and sat <= SAT_RATIO and bounds_ok is not False
        out.append(Verdict(case, ratios[worst], worst, sat, physics, bounds_ok, diverged, passed,
                           f"{when.group(1)} s" if when else "", () if o_done else done))
    return out


def verdict_table(verdicts: list[Verdict]) -> str:
    """Markdown table of :func:`acceptance`."""
    names = dict((k, label) for k, label, _ in COLUMNS)
    lines = ["| case | worst default ÷ oracle | in column | saturated ÷ oracle | physics? | "
             "bounds (y ≤ 0.04, max abs e_y ≤ 0.25, v ≤ 0.15) | met |", "|---|---|---|---|---|---|---|"]
    for v in verdicts:
        bounds = "n/a (physics)" if v.bounds_ok is None else ("yes" if v.bounds_ok else "**no**")
        at = f" at t = {v.diverged_at}" if v.diverged_at else ""
        met = "yes" if v.passed else (f"**no** (diverged{at})" if v.diverged else "**no**")
        phys = "yes" if v.physics else ("no: " + ", ".join(v.completes) + " completes"
                                        if v.completes else "no")
        lines.append(f"| {v.case} | {v.worst_ratio:.2f} | {names[v.worst_column]} | {v.sat_ratio:.2f} | "
                     f"{phys} | {bounds} | {met} |")
    return "\n".join(lines)


def figure(table: Any, tracks: list[str], cases: list[str], controllers: list[str], path: Path) -> Path:
    """RMSE y and RMSE v per case, a bar per controller, one row of panels per reference (a
    diverged run's bar is hatched)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axs = plt.subplots(len(tracks), 2, figsize=(14, 3.4 * len(tracks)), squeeze=False)
    width = 0.8 / max(len(controllers), 1)
    x = np.arange(len(cases))
    for i, track in enumerate(tracks):
        sub = table[table["track"] == track]
        for j, (key, label) in enumerate((("rmse_y", "RMSE y [m]"), ("rmse_v", "RMSE v [m/s]"))):
            ax = axs[i, j]
            for c, ctrl in enumerate(controllers):
                vals, hatch = [], []
                for case in cases:
                    r = sub[(sub["case"] == case) & (sub["controller"] == ctrl)]
                    vals.append(float(r.iloc[0][key]) if not r.empty else np.nan)
                    hatch.append(not r.empty and str(r.iloc[0]["status"]) != "completed")
                bars = ax.bar(x + (c - (len(controllers) - 1) / 2) * width, vals, width, label=ctrl)
                for b, h in zip(bars, hatch, strict=True):
                    if h:
                        b.set_hatch("//")
            ax.set_yscale("log")
            ax.set_xticks(x, cases, rotation=60, ha="right", fontsize=8)
            ax.set_ylabel(label)
            ax.set_title(f"{ref_name(str(track))}: {label} (hatched: diverged)", fontsize=9)
            ax.grid(axis="y", alpha=0.3, which="both")
    # one legend above the panels: inside a panel it covered bars
    handles, labels = axs[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=max(len(controllers), 1), fontsize=9,
               frameon=False)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.3 / fig.get_figheight()))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

