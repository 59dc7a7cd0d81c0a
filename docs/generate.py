"""Regenerate every published result of README.md and docs/*.md from real runs — the tables, the
numbers in the text, the figures in docs/img and the README's GIF — or check them (``--check``).

    python docs/generate.py                        # everything (≈ 30 min on 2 shared cores)
    python docs/generate.py --only ablation,offset-start
    python docs/generate.py --check --only ablation  # re-run and compare, write nothing
    python docs/generate.py --list                 # the sections and their blocks

Every generated block sits between ``<!-- SECTION:NAME:begin -->`` and ``<!-- SECTION:NAME:end -->``
(``generator.blocks``); SECTION is one of the sections below (``generator.published``). The
paper's reference and the race tracks are found by tsmpc.datasets ($TSMPC_DATA_DIR, the cache of
``tsmpc data fetch``, then ../shared/data next to the repository).
``--check`` fails (exit 1) when a published number differs from the fresh run by more than 2 %
beyond half a unit of its last printed digit; timings are regenerated but never checked.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from generator.blocks import blocks_in, check_files, update_block
from generator.published import PRODUCERS, TIMING_COLUMNS, TIMING_LINES, Context, precise

from tsmpc.blas import limit_blas_threads

ROOT = Path(__file__).resolve().parents[1]


def markdown_files(root: Path) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def write_blocks(files: list[Path], blocks: dict) -> None:
    """Replace ``blocks`` in the pages as they are now (they may have been edited meanwhile)."""
    for f in files:
        old = f.read_text(encoding="utf-8")
        new = old
        for b, body in blocks.items():
            if b in blocks_in(new):
                new = update_block(new, b, body)
        if new != old:
            f.write_text(new, encoding="utf-8")
            print(f"updated {f.relative_to(ROOT)}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated sections (default: all)")
    ap.add_argument("--check", action="store_true", help="re-run and compare; write nothing")
    ap.add_argument("--list", action="store_true", help="list the sections and where their blocks are")
    args = ap.parse_args(argv)
    files = markdown_files(ROOT)
    texts = {str(f.relative_to(ROOT)): f.read_text(encoding="utf-8") for f in files}
    if args.list:
        for p in PRODUCERS:
            where = sorted({f"{f}:{b.name}" for f, t in texts.items() for b in blocks_in(t)
                            if b.producer == p.name})
            print(f"{p.name:16} {'CI ' if p.ci else '   '}{p.about}\n{'':20}{', '.join(where)}")
        return 0
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    known = {p.name for p in PRODUCERS}
    if unknown := [n for n in names if n not in known]:
        print(f"error: --only: unknown section(s) {unknown}; allowed: {', '.join(sorted(known))}",
              file=sys.stderr)
        return 2
    limit_blas_threads()
    ctx = Context(ROOT, img_dir=None if args.check else ROOT / "docs" / "img",
                  progress=lambda s: print(f"  running: {s}", file=sys.stderr, flush=True))
    problems: list[str] = []
    t_all = time.perf_counter()
    for prod in PRODUCERS:
        if names and prod.name not in names:
            continue
        t0 = time.perf_counter()
        print(f"[{prod.name}] {prod.about}", file=sys.stderr, flush=True)
        try:
            if args.check:  # fresh numbers printed more precisely than the published ones
                with precise():
                    out = prod.fn(ctx)
            else:
                out = prod.fn(ctx)
        except Exception as err:  # one broken section must not lose the others' results
            import traceback

            traceback.print_exc()
            problems.append(f"[{prod.name}] failed: {type(err).__name__}: {err}")
            continue
        if args.check:
            fresh = {b: body for b, body in out.blocks.items() if b not in out.timing}
            problems += check_files(texts, fresh, skip_columns=TIMING_COLUMNS, skip_lines=TIMING_LINES,
                                    rows_only=out.partial)
        else:
            for b in out.blocks:
                if not any(b in blocks_in(text) for text in texts.values()):
                    problems.append(f"{b}: published nowhere (add its markers to a page)")
            write_blocks(files, out.blocks)  # after each section: a long run keeps what it made
            for f in out.figures:
                print(f"  wrote {os.path.relpath(f, ROOT)}", file=sys.stderr)
        print(f"[{prod.name}] {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    print(f"({time.perf_counter() - t_all:.0f} s)", file=sys.stderr)
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
