"""The mismatch benchmark (issue 21): runs the sweep of examples/mismatch.toml (or finishes it: runs
already on disk are kept), then prints the results per reference, the acceptance check on the paper's
reference and writes the figure (docs/mismatch.md shows this script's output).

    python examples/mismatch_table.py [--out results/mismatch] [--workers 2] [--img mismatch.png]

The same runs as ``tsmpc sweep examples/mismatch.toml --out results/mismatch``.
:func:`mismatch_blocks` is the docs generator's section ``mismatch``
(``python docs/generate.py --only mismatch`` writes docs/mismatch.md and its figure). 135 whole
runs: 10–20 minutes with two workers on two shared cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from tsmpc.datasets import label
from tsmpc.report.mismatch import acceptance, figure, reference_table, verdict_table
from tsmpc.sweep import aggregate, expand, load_sweep, run_sweep

ROOT = Path(__file__).resolve().parents[1]


def mismatch_blocks(out: Path, *, spec_path: Path = ROOT / "examples" / "mismatch.toml", workers: int = 2,
                    img: Path | None = None, steps: int | None = None) -> dict[str, str]:
    """Run (or finish) the sweep into ``out``; return the blocks of docs/mismatch.md (``results-N``
    per reference, ``acceptance``, ``summary``); write the figure to ``img``. ``steps`` shortens
    every run and the grid (the CI smoke run)."""
    spec = load_sweep(spec_path)
    if steps is not None:
        grid = spec.grid.model_copy(update={"track": (spec.grid.track or [])[:1],
                                            "case": ["nominal", "mass_plus_20"]})
        spec = spec.model_copy(update={"duration_s": steps * 0.1, "grid": grid})
    t0 = time.perf_counter()
    res = run_sweep(spec, out, workers=workers, resume=True, plots=False,
                    progress=lambda done, total, rec: print(f"  {done}/{total} {rec['params']['case']} "
                                                            f"{rec['params']['controller']}: {rec['status']}",
                                                            file=sys.stderr, flush=True))
    print(f"{res.n_runs} runs ({res.executed} run now, {res.skipped} on disk) in "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    table = aggregate(out, [t.id for t in expand(spec)])
    if table.empty:
        raise SystemExit(f"{out}: no run records")
    tracks = [t for t in (spec.grid.track or []) if t in set(table["track"])]
    cases = [c for c in (spec.grid.case or []) if c in set(table["case"])]
    ctrls = [c for c in (spec.grid.controller or []) if c in set(table["controller"])]
    blocks = {}
    for i, track in enumerate(tracks):
        blocks[f"results-{i + 1}"] = reference_table(table, track, cases, ctrls)
    verdicts = acceptance(table, tracks[0], cases)
    blocks["acceptance"] = verdict_table(verdicts)
    n_ok = sum(v.passed for v in verdicts)
    blocks["summary"] = (f"{len(table)} runs ({', '.join(label(t) for t in tracks)}); on the "
                         f"{label(tracks[0])}, {n_ok} of {len(verdicts)} cases meet the criteria.")
    if img is not None:
        figure(table, tracks, cases, ctrls, img)
    return blocks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/mismatch"),
                    help="the sweep's output folder (tsmpc sweep --out); runs on disk are kept")
    ap.add_argument("--spec", type=Path, default=ROOT / "examples" / "mismatch.toml",
                    help="the sweep file (its axes order the tables)")
    ap.add_argument("--workers", type=int, default=2, help="local Dask workers")
    ap.add_argument("--img", type=Path, default=None, help="write the figure here")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    out = Path(tempfile.mkdtemp(prefix="tsmpc-mismatch-")) if steps is not None else args.out
    blocks = mismatch_blocks(out, spec_path=args.spec, workers=args.workers, img=args.img, steps=steps)
    for name, body in blocks.items():
        print(f"\n## {name}\n\n{body}")


if __name__ == "__main__":
    main()
