"""Race speeds (issue 21, item 5): the five public TUMFTM tracks (``tsmpc data fetch tracks``) planned at
22 m/s, 5 m/s² and at 25 m/s, 6 m/s² (``tsmpc plan --v-max … --a-lat …``), one whole lap each with
the default cascade (REF; the boxes widened and certified for the plan automatically), and three
synthetic S-bends at 22 m/s: the largest lateral error (docs/mismatch.md shows this script's
output). None of these references was used to tune.

    python examples/race_tracks.py [TRACKS_DIR]

:func:`race_block` is the docs generator's section ``race-speeds``.

10 laps of 4–8 simulated minutes: about 5 minutes on two shared cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tsmpc.config import Config, PlannerSettings
from tsmpc.datasets import path_or_dataset
from tsmpc.planning.planner import plan_path
from tsmpc.planning.tracks import load_tumftm
from tsmpc.sim import experiment

ROOT = Path(__file__).resolve().parents[1]
TRACKS = ("Hockenheim", "Monza", "Silverstone", "Spa", "Zandvoort")
PLANS = ((22.0, 5.0, 0.25), (25.0, 6.0, 0.35))  # v_max, a_lat, the bound on max |e_y|
S_BENDS = (45.0, 60.0, 80.0)  # radii [m] of the synthetic S-bends


def s_bend(radius: float) -> np.ndarray:
    """Waypoints: 300 m straight, a left arc of ``radius`` turning 0.7 rad, a right arc of the same
    radius turning 1.4 rad, 400 m straight."""
    pts = [(0.0, 0.0), (100.0, 0.0), (200.0, 0.0), (300.0, 0.0)]
    h = 0.0
    for turn in (0.7, -1.4):
        x0, y0, side = pts[-1][0], pts[-1][1], np.sign(turn)
        cx, cy = x0 - side * radius * np.sin(h), y0 + side * radius * np.cos(h)
        for i in range(1, 31):
            hh = h + turn * i / 30
            pts.append((cx + side * radius * np.sin(hh), cy - side * radius * np.cos(hh)))
        h += turn
    x0, y0 = pts[-1]
    pts += [(x0 + d * np.cos(h), y0 + d * np.sin(h)) for d in (100.0, 200.0, 300.0, 400.0)]
    return np.array(pts)


def race_block(tracks: Path, steps: int | None = None) -> str:
    """One lap of every track of ``tracks`` at each plan, and the S-bends: the table (Markdown)."""
    lines = ["| track | plan | lap [s] | max abs e_y [m] | required | RMSE y [m] | RMSE v [m/s] | "
             "status |", "|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name in TRACKS:
            track = load_tumftm(tracks / f"{name}.csv")
            half = float(min(track.w_left.min(), track.w_right.min()))
            for v_max, a_lat, bound in PLANS:
                print(f"  running: {name} at {v_max:g} m/s, {a_lat:g} m/s²", file=sys.stderr, flush=True)
                ref = plan_path(track.centre, PlannerSettings(v_max=v_max, a_lat_max=a_lat), closed=True,
                                dt=0.1)
                path = Path(tmp) / f"{name}_{v_max:g}.csv"
                ref.to_csv(path, {"source": f"{name}.csv", "half_width_m": f"{half:.3f}"})
                exp = experiment.prepare(Config(), ["ref"], reference=path,
                                         duration=None if steps is None else steps * 0.1)
                m = experiment.run(exp, None, plots=False).metrics["methods"]["REF"]
                ok = m["termination"] == "completed" and m["max_abs_lateral_m"] <= bound
                lap = exp.scenario.reference.duration  # as run: a plan beyond the grip is capped
                lines.append(f"| {name} | {v_max:g} m/s, {a_lat:g} m/s² | {lap:.0f} | "
                             f"{m['max_abs_lateral_m']:.3f} | ≤ {bound:g} | {m['rmse']['y']:.4f} | "
                             f"{m['rmse']['v']:.4f} | {m['termination'] if not ok else 'met'} |")
    # S-bends, planned at 22 m/s and 5 m/s² (the hardest piece: ω_d reverses within a second
    # while the car brakes into it): a straight, a left arc of radius R, at once a right arc of
    # radius R, a straight
    for radius in S_BENDS:
        print(f"  running: S-bend R = {radius:g} m", file=sys.stderr, flush=True)
        ref = plan_path(s_bend(radius), PlannerSettings(v_max=22.0, a_lat_max=5.0), closed=False, dt=0.1,
                        tail_s=4.1)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "s_bend.csv"
            ref.to_csv(path)
            exp = experiment.prepare(Config(), ["ref"], reference=path,
                                     duration=None if steps is None else steps * 0.1)
            m = experiment.run(exp, None, plots=False).metrics["methods"]["REF"]
        ok = m["termination"] == "completed" and m["max_abs_lateral_m"] <= 0.25
        dw = float(np.max(np.abs(np.diff(ref.omega))) / ref.dt)
        lines.append(f"| S-bend R = {radius:g} m (max abs dω_d/dt {dw:.1f} rad/s²) | 22 m/s, 5 m/s² | "
                     f"{ref.duration:.0f} | {m['max_abs_lateral_m']:.3f} | ≤ 0.25 | {m['rmse']['y']:.4f} | "
                     f"{m['rmse']['v']:.4f} | {m['termination'] if not ok else 'met'} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="?", default="tracks",
                    help="a folder of TUMFTM tracks or 'tracks' (default: `tsmpc data fetch tracks`)")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    t0 = time.perf_counter()
    block = race_block(path_or_dataset(args.tracks), steps)
    print(f"\n## race-speeds\n\n{block}\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
