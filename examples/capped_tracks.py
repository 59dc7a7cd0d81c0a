"""Every race track of a folder planned at 30 m/s and 8 m/s² (``tsmpc plan --v-max 30 --a-lat 8``),
capped by the plan check to the vehicle's limits (issue 36: the lateral margin and the friction
circle, docs/planning.md), then one lap with the default cascade (REF): the largest lateral error
against issue 36's 0.5 m. The docs' five tracks are ``tsmpc data fetch tracks``; the held-back
ones the issue's acceptance checks "the same way" are the other tracks of the TUMFTM
racetrack-database (LGPL-3.0, github.com/TUMFTM/racetrack-database, its ``tracks/`` folder: clone
it and pass that folder). None of them was used to tune.

    python examples/capped_tracks.py [TRACKS_DIR] [--v-max 30] [--a-lat 8] [--bound 0.5]

(default: the docs' five tracks, ``tsmpc data fetch tracks``).

Exit 0 when every lap stays within the bound, 1 when one does not. A few seconds per track.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from tsmpc.config import Config, PlannerSettings
from tsmpc.datasets import path_or_dataset
from tsmpc.planning.feasibility import feasible_plan_for
from tsmpc.planning.planner import plan_path
from tsmpc.planning.tracks import load_tumftm
from tsmpc.sim import experiment


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tracks", nargs="?", default="tracks",
                    help="a folder of TUMFTM track files (x_m, y_m, w_tr_right_m, w_tr_left_m) or 'tracks' "
                    "(default: `tsmpc data fetch tracks`)")
    ap.add_argument("--v-max", type=float, default=30.0)
    ap.add_argument("--a-lat", type=float, default=8.0)
    ap.add_argument("--bound", type=float, default=0.5, help="max |e_y| a lap must stay within [m]")
    args = ap.parse_args()
    folder = path_or_dataset(args.tracks)
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    files = sorted(p for p in folder.glob("*.csv") if not p.name.startswith("."))
    if not files:
        print(f"error: {folder}: no track files (*.csv)", file=sys.stderr)
        return 2
    cfg = Config()
    print(f"| track | plan check | lap [s]: planned → capped | run | max abs e_y [m] | within "
          f"{args.bound:g} m |\n|---|---|---|---|---|---|")
    within = 0
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            raw = plan_path(load_tumftm(path).centre, PlannerSettings(v_max=args.v_max, a_lat_max=args.a_lat),
                            closed=True, dt=0.1)
            capped, check, _ = feasible_plan_for(cfg, raw)
            out = Path(tmp) / path.name
            capped.to_csv(out)
            duration = None if steps is None else steps * cfg.rates.Tc
            m = experiment.run(experiment.prepare(cfg, ["ref"], reference=out, duration=duration), None,
                               plots=False).metrics["methods"]["REF"]
            ok = m["status"] != "diverged" and m["max_abs_lateral_m"] <= args.bound
            within += ok
            print(f"| {path.stem} | {check.limit or 'within'} | {raw.duration:.1f} → {capped.duration:.1f} | "
                  f"{m['status']} | {m['max_abs_lateral_m']:.3f} | {'yes' if ok else '**no**'} |", flush=True)
    print(f"\n{within} of {len(files)} tracks within {args.bound:g} m")
    return 0 if within == len(files) else 1


if __name__ == "__main__":
    sys.exit(main())
