"""The ablation on the paper reference: the paper preset, then each mechanism beyond the paper
added one at a time, the oracle and the paper preset without friction compensation; and the
speed-mode time constants of the inner loop per vertex of the dynamic design. The same rows as
docs/paper.md and the README (`python docs/generate.py --only ablation,speed-mode` writes them
there).

    python examples/paper_ablation.py [REFERENCE]

Runs from any folder. REFERENCE defaults to the paper's file (not bundled: ``tsmpc data fetch
paper``; found by :func:`tsmpc.datasets.resolve`). Every row is a full REF run of the paper window.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from tsmpc.datasets import path_or_dataset

ROOT = Path(__file__).resolve().parents[1]
# the rows are the docs generator's (docs/generator: project tooling, not part of the package)
sys.path.append(str(ROOT / "docs"))
from generator.published import Context, ablation, speed_mode  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", nargs="?", default="paper",
                    help="a file or a dataset name (default: paper, from `tsmpc data fetch paper`)")
    ap.add_argument("--skip-runs", action="store_true", help="only the speed-mode table")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    ctx = Context(ROOT, reference=path_or_dataset(args.reference).resolve(), max_steps=steps,
                  progress=lambda s: print(f"  running: {s}", file=sys.stderr, flush=True))
    out = speed_mode(ctx)
    if not args.skip_runs:
        out.blocks.update(ablation(ctx).blocks)
    for block, body in out.blocks.items():
        print(f"\n## {block}\n\n{body}")


if __name__ == "__main__":
    main()
