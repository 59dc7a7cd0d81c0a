"""The README's baseline table (issue 26): every outer-loop method — the TS-MPC's three scheduling
modes, the NL-MPC and the four baselines users pick instead — in the same cascade on five cases.

    python examples/baseline_table.py [--out results/baselines] [--data DIR] [--markdown FILE]

Cases: the paper reference (paper-run window), two public race tracks (TUMFTM, LGPL-3.0) planned
at v_max = 22 m/s and a_lat = 5 m/s² (as ``tsmpc plan TRACK --v-max 22 --a-lat 5``; the scheduling
boxes are widened and the designs re-certified as ``tsmpc compare`` does), and two model
mismatches on the paper reference (plant mass +20 % and cornering stiffness −20 %; stiffness −20 %
alone), plus the settling time after an offset start (2 m, 0.2 rad) on the paper reference.
Every case is one :func:`tsmpc.sim.compare.compare` call (all methods, one seed); its outputs
(metrics.json, comfort.md, …) are written under ``--out/<case>/`` and the table is built from
those metrics only. :func:`baseline_table` returns the Markdown (the docs generator's entry point)
and writes it to ``--out/baseline_table.md``. ``TSMPC_EXAMPLE_STEPS`` shortens every run (CI).
The paper's reference and the tracks are found by :func:`tsmpc.datasets.resolve` (``tsmpc data
fetch`` downloads them) unless ``--data`` names a folder laid out as ``paper/…`` and ``tracks/…``.
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tsmpc import datasets
from tsmpc.config import Config, Method, PlannerSettings

#: Rows: every method, in this order.
METHODS = (Method.FZN, Method.REF, Method.ITER, Method.NL, Method.PURE_PURSUIT, Method.STANLEY,
           Method.LQR, Method.LTV)
#: The two race tracks (TUMFTM, `tsmpc data fetch tracks`) and their plan.
TRACKS = ("Monza", "Silverstone")
V_MAX, A_LAT = 22.0, 5.0
ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Case:
    """One column group of the table: a reference and a robustness scenario on it."""

    key: str  #: folder name under --out
    label: str  #: label in the table
    reference: Path  #: paper-format file or planned CSV
    robustness: str = "nominal"


def plan_tracks(tracks: Path, work: Path, cfg: Config) -> dict[str, Path]:
    """Plan each of :data:`TRACKS` at (V_MAX, A_LAT) into ``work/<track>.csv`` (as ``tsmpc plan``:
    a closed lap, the track's narrowest half-width as the divergence bound)."""
    from tsmpc.planning.planner import plan_path
    from tsmpc.planning.tracks import load_tumftm

    out = {}
    settings = PlannerSettings(v_max=V_MAX, a_lat_max=A_LAT)
    for name in TRACKS:
        track = load_tumftm(tracks / f"{name}.csv")
        ref = plan_path(track.centre, settings, closed=True, dt=cfg.rates.Tc)
        half = float(min(track.w_left.min(), track.w_right.min()))
        path = work / f"{name}_{V_MAX:g}_{A_LAT:g}.csv"
        ref.to_csv(path, {"source": f"{name}.csv", "half_width_m": f"{half:.3f}"})
        out[name] = path
    return out


def cases(paper: Path, planned: dict[str, Path]) -> list[Case]:
    """The five table cases and the offset start (key ``offset_start``), in order."""
    return [
        Case("paper", "paper reference", paper),
        *(Case(name.lower(), f"{name} (22 m/s, 5 m/s²)", path) for name, path in planned.items()),
        Case("mass_stiffness", "paper ref., mass +20 %, stiffness −20 %", paper, "mass_stiffness_mismatch"),
        Case("stiffness", "paper ref., stiffness −20 %", paper, "stiffness_mismatch"),
        Case("offset_start", "paper ref., offset start", paper, "offset_start"),
    ]


def run_case(case: Case, out: Path, methods: tuple[Method, ...], max_steps: int | None) -> dict[str, Any]:
    """All ``methods`` on ``case`` through the CLI's own pipeline (``tsmpc compare --reference R
    --scenario S``: :func:`tsmpc.sim.experiment.prepare` and :func:`~tsmpc.sim.experiment.run`,
    envelope fit and certified designs included); writes the comparison's files into
    ``out/<case.key>``; returns its metrics."""
    from tsmpc.sim.experiment import prepare, run

    cfg = Config()
    duration = None if max_steps is None else max_steps * cfg.rates.Tc
    exp = prepare(cfg, methods, reference=case.reference, robustness=case.robustness,
                  duration=duration)
    return run(exp, out / case.key, plots=False).metrics


#: (column head, value of a method's metrics entry, decimals) of the table, after the case/method.
COLUMNS: tuple[tuple[str, Any, int], ...] = (
    ("RMSE y [m]", lambda m: m["rmse"]["y"], 3),
    ("max \\|e_y\\| [m]", lambda m: m["max_abs_lateral_m"], 3),
    ("RMSE x [m]", lambda m: m["rmse"]["x"], 3),
    ("RMS lateral jerk [m/s³]", lambda m: m["comfort"]["lat_jerk_rms"], 3),
    ("RMS steering rate [rad/s]", lambda m: m["comfort"]["steering_rate_rms"], 4),
    ("outer step, median [ms]", lambda m: m["mpc_ms"]["median"], 3),
)


def _cells(m: dict[str, Any], Tc: float) -> list[str]:
    if m["status"] == "diverged":  # where it left the road; no comfort or timing of a partial run
        return [f"diverged at {m['outer_steps'] * Tc:.1f} s", f"> {m['max_abs_lateral_m']:.2f}",
                *(["—"] * (len(COLUMNS) - 2))]
    return [f"{get(m):.{d}f}" for _, get, d in COLUMNS]


def table_markdown(results: dict[str, tuple[Case, dict[str, Any]]]) -> str:
    """One table: a row per (case, method), the case named on its first row."""
    head = ("case", "method", *(h for h, _, _ in COLUMNS))
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key, (case, metrics) in results.items():
        if key == "offset_start":
            continue
        for i, (name, m) in enumerate(metrics["methods"].items()):
            label = f"**{case.label}**" if i == 0 else ""
            lines.append(f"| {label} | {name} | " + " | ".join(_cells(m, metrics["scenario"]["Tc"])) + " |")
    return "\n".join(lines) + "\n"


def verdict_markdown(results: dict[str, tuple[Case, dict[str, Any]]], ts: str = "REF") -> str:
    """Where the TS-MPC (``ts``) wins: per other method, the cases it completes, and on the cases
    both complete, ``ts``'s wins–ties–losses per column (lower is better; a tie is equal at the
    table's precision) and the range of its step-time ratio."""
    keys = [k for k in results if k != "offset_start"]
    others = [n for n in next(iter(results.values()))[1]["methods"] if n != ts]
    head = ("method", "completes (cases)", *(f"{ts}: {h.split(' [')[0]}" for h, _, _ in COLUMNS[:-1]),
            f"outer step ÷ {ts}'s")
    lines = [f"{ts} against every other method, wins–ties–losses over the cases both complete:", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in others:
        done = [k for k in keys if results[k][1]["methods"][n]["status"] == "completed"]
        both = [k for k in done if results[k][1]["methods"][ts]["status"] == "completed"]
        cells = [f"{len(done)} of {len(keys)}"]
        for _, get, d in COLUMNS[:-1]:
            w = t = lo = 0
            for k in both:
                a = round(get(results[k][1]["methods"][ts]), d)
                b = round(get(results[k][1]["methods"][n]), d)
                w, t, lo = w + (a < b), t + (a == b), lo + (a > b)
            cells.append(f"{w}–{t}–{lo}")
        r = [results[k][1]["methods"][n]["mpc_ms"]["median"]
             / results[k][1]["methods"][ts]["mpc_ms"]["median"] for k in both]
        cells.append(f"{min(r):.1f}–{max(r):.1f}" if r else "—")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def settling_markdown(metrics: dict[str, Any]) -> str:
    """Settling time (|e_y| ≤ 0.10 m from then on) after the offset start, per method."""
    names = list(metrics["methods"])
    vals = []
    for n in names:
        m = metrics["methods"][n]
        s = m["comfort"]["settling_time_s"]
        vals.append("diverged" if m["status"] == "diverged" else ("never" if math.isinf(s) else f"{s:.1f}"))
    return ("| offset start (paper ref.) | " + " | ".join(names) + " |\n|" + "---|" * (len(names) + 1)
            + "\n| settling time [s] | " + " | ".join(vals) + " |\n")


def baseline_table(out: Path, *, data: Path | None = None, methods: tuple[Method, ...] = METHODS,
                   max_steps: int | None = None, run: bool = True) -> str:
    """Run every case (``run``; else read the metrics.json files an earlier run left under
    ``out``), write ``out/baseline_table.md`` and return the Markdown. ``data``: a folder holding
    ``paper/planner_references_100ms.csv`` and ``tracks/<Name>.csv`` (default: tsmpc's data
    folders, :func:`tsmpc.datasets.resolve`)."""
    import json

    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    if data is not None:
        paper, tracks = data / datasets.PAPER_FILE, data / "tracks"
    elif run:
        paper, tracks = datasets.resolve("paper"), datasets.resolve("tracks")
    else:  # the table from an earlier run's metrics.json files: no data is read
        paper, tracks = Path(datasets.PAPER_FILE), Path("tracks")
    planned = (plan_tracks(tracks, out, Config()) if run
               else {n: out / f"{n}_{V_MAX:g}_{A_LAT:g}.csv" for n in TRACKS})
    results = {}
    # Every method's outer step timed as a Python caller sees it: the TS-MPC methods would
    # otherwise run in the compiled run engine (tsmpc.sim.engine), timed inside it without the
    # call overhead every baseline pays. The tracking numbers are the same either way.
    engine, os.environ["TSMPC_ENGINE"] = os.environ.get("TSMPC_ENGINE"), "0"
    try:
        for case in cases(paper, planned):
            metrics = (run_case(case, out, methods, max_steps) if run
                       else json.loads((out / case.key / "metrics.json").read_text(encoding="utf-8")))
            results[case.key] = (case, metrics)
    finally:
        if engine is None:
            os.environ.pop("TSMPC_ENGINE", None)
        else:
            os.environ["TSMPC_ENGINE"] = engine
    from tsmpc.io import atomic_write_text

    facts = out / "baseline_run.json"  # the machine's facts of the run, read back by --no-run
    if run:
        atomic_write_text(facts, json.dumps({"cores": os.cpu_count(), "load_start": load0,
                                             "load_end": os.getloadavg()[0], "max_steps": max_steps}))
    f = json.loads(facts.read_text(encoding="utf-8"))
    short = f["max_steps"]
    text = (table_markdown(results) + "\n" + verdict_markdown(results) + "\n"
            + settling_markdown(results["offset_start"][1])
            + f"\nProduced by `python docs/generate.py --only baselines` (this script's "
            f"`baseline_table()`); {f['cores']} cores, load average {f['load_start']:.1f} at the start and "
            f"{f['load_end']:.1f} at the end of the runs"
            + (f"; runs shortened to {short} outer steps" if short else "") + ".\n")

    atomic_write_text(out / "baseline_table.md", text)
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/baselines"))
    ap.add_argument("--data", type=Path, default=None,
                    help="folder holding paper/ and tracks/ (default: tsmpc's data folders; the data "
                    "is not bundled: tsmpc data fetch)")
    ap.add_argument("--markdown", type=Path, default=None,
                    help="also write the table here (docs/generated/baseline_table.md for the docs)")
    ap.add_argument("--no-run", action="store_true",
                    help="rebuild the table from the metrics.json files of an earlier run in --out")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None
    text = baseline_table(args.out, data=args.data, max_steps=steps, run=not args.no_run)
    if args.markdown is not None:
        from tsmpc.io import atomic_write_text

        atomic_write_text(args.markdown, text)
    print(text)


if __name__ == "__main__":
    main()
