"""Table 5 explained: the paper as it was run (the `paper-as-run` preset), each of its
quirks removed one at a time down to the `paper` preset, and the ablation on to the default —
every row measured here; plus the start-up transient figure, the gain-sensitivity study, the
points of the feasibility LMI, the speed-headroom counterfactuals, the paper's trends and the two
MHE-UIO forms (README.md and docs/paper.md show this script's output).

    python examples/paper_explained.py [REFERENCE] [--img-dir docs/img] [--update-docs]

Runs from any folder. REFERENCE defaults to the paper's file (not bundled: ``tsmpc data fetch
paper``; found by :func:`tsmpc.datasets.resolve`). ``--update-docs`` rewrites the marked blocks
of README.md and docs/paper.md with the tables printed here (``python docs/generate.py --only
paper-explained`` does the same). ≈ 35 full runs at 1–10 ms inner steps: 15–25 minutes on two shared cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from tsmpc.datasets import path_or_dataset

ROOT = Path(__file__).resolve().parents[1]
# the study lives beside the docs generator (docs/generator: project tooling, not in the package)
sys.path.append(str(ROOT / "docs"))
from generator.paper_explained import generate, update_block  # noqa: E402

DOCS = (ROOT / "README.md", ROOT / "docs" / "paper.md")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", nargs="?", default="paper",
                    help="a file or a dataset name (default: paper, from `tsmpc data fetch paper`)")
    ap.add_argument("--img-dir", type=Path, default=None, help="write the figures here (docs/img)")
    ap.add_argument("--update-docs", action="store_true",
                    help="rewrite the marked blocks of README.md and docs/paper.md")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    if args.update_docs and steps is not None:
        sys.exit("refusing to write shortened runs (TSMPC_EXAMPLE_STEPS) into the docs")
    t0 = time.perf_counter()
    rep = generate(path_or_dataset(args.reference), args.img_dir, max_steps=steps,
                   progress=lambda s: print(f"  running: {s}", file=sys.stderr, flush=True))
    for name, body in rep.blocks.items():
        print(f"\n## {name}\n\n{body}")
    for p in rep.figures:
        print(f"wrote {p}")
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.update_docs:
        for path in DOCS:
            text = path.read_text(encoding="utf-8")
            for name, body in rep.blocks.items():
                if f"<!-- paper-explained:{name}:begin -->" in text:
                    text = update_block(text, name, body)
            path.write_text(text, encoding="utf-8")
            print(f"updated {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
