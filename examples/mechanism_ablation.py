"""Which mechanisms pay (issue 34 item 3): runs the sweep of examples/mechanisms.toml (or finishes
it: runs already on disk are kept) — every default-on switch off alone, on the mismatch
benchmark's 15 cases, a stalled bus, a biased gyro and a steering offset, on the paper's reference
and two race tracks — and prints, per switch, the largest gain it brings on any case and column,
and the cases that complete only with it (docs/mismatch.md shows this script's output).

    python examples/mechanism_ablation.py [--out results/mechanisms] [--workers 1]

The rule: a switch stays when some case is better by 5 % or more with it in some column (RMSE x, y,
θ, v, ω or max |e_y|), or completes only with it; else it is removed, not switched off.
:func:`mechanism_blocks` is the docs generator's section ``mechanisms``. 1026 whole runs: ≈ 61 min
with one worker on two shared cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tsmpc.datasets import label as track_label
from tsmpc.sweep import aggregate, expand, load_sweep, run_sweep

ROOT = Path(__file__).resolve().parents[1]

#: The sweep's controllers: the switch each turns off, and what the mechanism is.
MECHANISMS = {
    "no-speed-feedback": ("lqr.speed_feedback", "speed-error feedback in the inner loop"),
    "no-window-friction": ("lqr.friction_estimate", "the MHE window's friction fit (not the one-step UIO)"),
    "no-low-speed-res": ("lqr.low_speed_resistance", "the model's resistance below 2 m/s"),
    "no-friction-step": ("lqr.friction_step", "friction-step detection"),
    "no-slip-aware": ("mpc.slip_aware", "the velocity-frame errors (slip-aware outer loop)"),
    "no-tangent": ("mpc.tangent_heading", "the path's tangent heading"),
    "no-step-average": ("mpc.step_average_reference", "the T_c step averages of the reference"),
    "no-repeat-guard": ("fusion.reject_repeated_samples", "repeated samples treated as missing"),
    "no-predict-pose": ("fusion.predict_pose", "dead-reckoned pose for a missing one"),
    "no-course-slip": ("fusion.course_slip", "slip corrected by the course over ground"),
    "no-course-speed": ("fusion.course_speed", "speed sensor offset and scale from the speed over ground"),
    "no-gyro-bias": ("fusion.gyro_bias", "yaw-rate sensor bias from the measured heading"),
    "no-steering-offset": ("fusion.steering_offset", "steering-angle offset from the yaw balance"),
    "no-stiffness": ("fusion.stiffness_estimate", "cornering stiffness fit"),
    "no-lateral-fit": ("fusion.lateral_fit", "joint lateral fit (stiffnesses, inertia, CoG)"),
    "no-mass": ("fusion.mass_estimate", "mass-error inertia out of the friction estimate"),
    "no-governor": ("governor.enabled",
                    "speed governor (the plan re-timed to the grip and the force budget)"),
    "no-yaw-margin": ("mhe.margin_slip_rate",
                      "the MHE's yaw-model margin (Q_ω grows with the slip residual)"),
}
COLUMNS = {"rmse_x": "RMSE x", "rmse_y": "RMSE y", "rmse_theta": "RMSE θ", "rmse_v": "RMSE v",
           "rmse_omega": "RMSE ω", "max_abs_lateral_m": "max abs e_y"}
#: The smallest gain that counts (off / default in one column of one case).
PAYS = 1.05


def _track_name(t: Any) -> str:
    name = track_label(str(t))
    return "paper ref." if name == "paper reference" else name


def verdicts(table: Any) -> list[dict[str, Any]]:
    """Per switch: the largest gain (the run without it over the default run, any completed case
    and column) and the largest cost (the default run over the run without it), where, and the
    cases that complete only with it."""
    track = table["track"].map(_track_name)
    rows = {(tr, c, k): r for (tr, (_, r)) in zip(track, table.iterrows(), strict=True)
            for c, k in [(r["case"], r["controller"])]}
    cases = sorted({(tr, c) for tr, c, _ in rows})
    out = []
    for ctrl, (switch, what) in MECHANISMS.items():
        best, where, only = 0.0, "", []
        cost, cost_where = 0.0, ""
        for tr, case in cases:
            d, o = rows.get((tr, case, "default")), rows.get((tr, case, ctrl))
            if d is None or o is None:
                continue
            d_ok, o_ok = str(d["status"]) == "completed", str(o["status"]) == "completed"
            if d_ok and not o_ok:
                only.append(f"{tr} {case}")
            if not (d_ok and o_ok):
                continue
            for col, label in COLUMNS.items():
                g = float(o[col]) / max(float(d[col]), 1e-12)
                if g > best:
                    best, where = g, f"{tr} {case}, {label}"
                c = float(d[col]) / max(float(o[col]), 1e-12)
                if c > cost:
                    cost, cost_where = c, f"{tr} {case}, {label}"
        out.append({"switch": switch, "what": what, "gain": best, "where": where, "only": only,
                    "cost": cost, "cost_where": cost_where, "keep": best >= PAYS or bool(only)})
    return out


def verdict_table(rows: list[dict[str, Any]]) -> str:
    lines = ["| switch | mechanism | largest gain | where | largest cost | where | completes only "
             "with it | verdict |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        only = ", ".join(r["only"]) or "–"
        lines.append(f"| `{r['switch']}` | {r['what']} | {r['gain']:.2f}× | {r['where']} | "
                     f"{r['cost']:.2f}× | {r['cost_where']} | {only} | "
                     f"{'kept' if r['keep'] else '**removed**'} |")
    return "\n".join(lines)


def mechanism_blocks(out: Path, *, spec_path: Path = ROOT / "examples" / "mechanisms.toml",
                     workers: int = 1, steps: int | None = None) -> dict[str, str]:
    """Run (or finish) the sweep into ``out``; the blocks of docs/mismatch.md (``table``,
    ``summary``). ``steps`` shortens every run and the grid (a smoke run)."""
    spec = load_sweep(spec_path)
    if steps is not None:
        grid = spec.grid.model_copy(update={"track": (spec.grid.track or [])[:1],
                                            "case": ["nominal", "v_bias"],
                                            "controller": ["default", "no-course-speed", "no-mass"]})
        spec = spec.model_copy(update={"duration_s": steps * 0.1, "grid": grid})
    t0 = time.perf_counter()
    res = run_sweep(spec, out, workers=workers, resume=True, plots=False)
    print(f"{res.n_runs} runs ({res.executed} run now, {res.skipped} on disk) in "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    table = aggregate(out, [t.id for t in expand(spec)])
    if table.empty:
        raise SystemExit(f"{out}: no run records")
    rows = verdicts(table)
    kept = [r["switch"] for r in rows if r["keep"]]
    removed = [r["switch"] for r in rows if not r["keep"]]
    summary = (f"{len(table)} runs; {len(kept)} of {len(rows)} switches pay on a measured case"
               + (f"; removed: {', '.join(f'`{s}`' for s in removed)}." if removed else "."))
    return {"table": verdict_table(rows), "summary": summary}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="sweep folder (default: a temporary one)")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="tsmpc-mechanisms-"))
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    for body in mechanism_blocks(out, workers=args.workers, steps=steps).values():
        print(body, end="\n\n")


if __name__ == "__main__":
    main()
