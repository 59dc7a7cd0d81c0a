"""The ablation on the paper reference: the paper preset, then each mechanism beyond the paper
added one at a time, the oracle and the paper preset without friction compensation; and the
speed-mode time constants of the inner loop per vertex of the dynamic design. The same rows as
docs/paper.md and the README (`python docs/generate.py --only ablation,speed-mode` writes them
there).

    python examples/paper_ablation.py [REFERENCE]

Runs from any folder. REFERENCE defaults to the paper's file in ../shared/data next to the
repository (not bundled). Every row is a full REF run of the paper window.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from tsmpc.report.published import Context, ablation, speed_mode

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT.parent / "shared" / "data" / "paper" / "planner_references_100ms.csv"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", nargs="?", type=Path, default=PAPER)
    ap.add_argument("--skip-runs", action="store_true", help="only the speed-mode table")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    ctx = Context(ROOT, reference=args.reference.resolve(), max_steps=steps,
                  progress=lambda s: print(f"  running: {s}", file=sys.stderr, flush=True))
    out = speed_mode(ctx)
    if not args.skip_runs:
        out.blocks.update(ablation(ctx).blocks)
    for block, body in out.blocks.items():
        print(f"\n## {block}\n\n{body}")


if __name__ == "__main__":
    main()
