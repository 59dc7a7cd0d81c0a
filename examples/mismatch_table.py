"""The mismatch benchmark's tables and figure (issue 21) from a finished sweep of
examples/mismatch.toml: the results per reference, the acceptance check on the paper's reference
and docs/img/mismatch.png (docs/mismatch.md shows this script's output).

    tsmpc sweep examples/mismatch.toml --out results/mismatch
    python examples/mismatch_table.py results/mismatch [--img docs/img/mismatch.png] [--update-docs]

``--update-docs`` rewrites the marked blocks of docs/mismatch.md with the tables printed here.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tsmpc.report.mismatch import acceptance, figure, reference_table, update_block, verdict_table
from tsmpc.sweep import aggregate, load_sweep

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "mismatch.md"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="the sweep's output folder (tsmpc sweep --out)")
    ap.add_argument("--spec", type=Path, default=ROOT / "examples" / "mismatch.toml",
                    help="the sweep file (its axes order the tables)")
    ap.add_argument("--img", type=Path, default=None, help="write the figure here (docs/img/mismatch.png)")
    ap.add_argument("--update-docs", action="store_true",
                    help="rewrite the marked blocks of docs/mismatch.md")
    args = ap.parse_args()
    spec = load_sweep(args.spec)
    table = aggregate(args.out)
    if table.empty:
        raise SystemExit(f"{args.out}: no run records")
    tracks = [t for t in (spec.grid.track or []) if t in set(table["track"])]
    cases = [c for c in (spec.grid.case or []) if c in set(table["case"])]
    ctrls = [c for c in (spec.grid.controller or []) if c in set(table["controller"])]
    blocks = {}
    for i, track in enumerate(tracks):
        blocks[f"results-{i + 1}"] = reference_table(table, track, cases, ctrls)
    verdicts = acceptance(table, tracks[0], cases)
    blocks["acceptance"] = verdict_table(verdicts)
    n_ok = sum(v.passed for v in verdicts)
    blocks["summary"] = (f"{len(table)} runs ({', '.join(Path(t).stem for t in tracks)}); on "
                         f"{Path(tracks[0]).stem}, {n_ok} of {len(verdicts)} cases meet the criteria.")
    for name, body in blocks.items():
        print(f"\n## {name}\n\n{body}")
    if args.img is not None:
        print(f"wrote {figure(table, tracks, cases, ctrls, args.img)}")
    if args.update_docs:
        text = DOC.read_text(encoding="utf-8")
        for name, body in blocks.items():
            text = update_block(text, name, body)
        DOC.write_text(text, encoding="utf-8")
        print(f"updated {DOC.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
