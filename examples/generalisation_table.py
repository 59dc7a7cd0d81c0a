"""The generalisation benchmark (issue 35): runs the sweeps of examples/generalisation.toml (50 draws
of the class) and examples/generalisation_heldback.toml (50 held-back draws) — or finishes them:
runs already on disk are kept — and prints the distribution of the worst-column ratio default /
oracle-tuned, its check against issue 35's bounds, the five worst draws and what each of their
errors costs (the default controller told one part of the plant at a time; docs/mismatch.md shows
this script's output).

    python examples/generalisation_table.py [--out results/generalisation] [--workers 2]

The same runs as ``tsmpc sweep examples/generalisation.toml --out results/generalisation/main``
(and ``..._heldback.toml`` into ``.../heldback``). :func:`generalisation_blocks` is the docs
generator's section ``generalisation`` (``python docs/generate.py --only generalisation``). 200
whole runs and 100 oracle-tuned LMI designs (one per drawn vehicle).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from tsmpc.config import Config
from tsmpc.report.generalisation import (
    ATTRIBUTION,
    WORST_K,
    Draw,
    attribution_controllers,
    attribution_table,
    distribution,
    draw_results,
    draws,
    drivers_table,
    levels_table,
    summary_table,
    worst_draws,
    worst_table,
)
from tsmpc.sweep import aggregate, expand, load_sweep, run_sweep

ROOT = Path(__file__).resolve().parents[1]
#: (label, sweep file, sub-folder of the output)
SETS = (("main (seed 35)", "generalisation.toml", "main"),
        ("held back (seed 9035)", "generalisation_heldback.toml", "heldback"))


def _draws_of(spec_path: Path) -> list[Draw]:
    """The draws a sweep file was written from (its comment names seed and n; the file must match)."""
    import re

    text = spec_path.read_text(encoding="utf-8")
    m = re.search(r"draws\(seed=(\d+), n=(\d+)\)", text)
    if m is None:
        raise SystemExit(f"{spec_path}: not written by examples/generalisation_draws.py")
    case = tomllib.loads(text)["grid"]["case"]
    prefix = case[0].rstrip("0123456789")
    return draws(int(m.group(1)), int(m.group(2)), prefix)


def generalisation_blocks(out: Path, *, workers: int = 2, steps: int | None = None,
                          sets: tuple[tuple[str, str, str], ...] = SETS) -> dict[str, str]:
    """Run (or finish) the sweeps into ``out/<set>``; return the blocks of docs/mismatch.md
    (``table``: the distributions, ``levels``: the two rows' own medians, ``worst`` /
    ``worst-heldback``: the five worst draws of each set, ``drivers``: which quantity drives the
    ratio on the main set, ``attribution`` /
    ``attribution-heldback``: the five worst draws of each set re-run with the default controller
    told one part of the plant at a time, ``scenario.known``, ``time``: how long it took).
    ``steps`` shortens every run to that many MPC steps and runs the first two draws of each set
    only (the CI smoke run)."""
    rows, blocks, took, levels = [], {}, [], []
    for label, file, sub in sets:
        spec_path = ROOT / "examples" / file
        spec = load_sweep(spec_path)
        if steps is not None:
            grid = spec.grid.model_copy(update={"case": (spec.grid.case or [])[:2]})
            spec = spec.model_copy(update={"duration_s": steps * Config().rates.Tc, "grid": grid})
        t0 = time.perf_counter()
        res = run_sweep(spec, out / sub, workers=workers, resume=True, plots=False,
                        progress=lambda done, total, rec: print(
                            f"  {done}/{total} {rec['params']['case']} {rec['params']['controller']}: "
                            f"{rec['status']}", file=sys.stderr, flush=True))
        wall = time.perf_counter() - t0
        table = aggregate(out / sub, [t.id for t in expand(spec)])
        if table.empty:
            raise SystemExit(f"{out / sub}: no run records")
        # the runs' own time from their records (a resumed sweep's wall is only what it ran now)
        took.append(f"{label}: {res.n_runs} runs, {table['elapsed_s'].sum():.0f} s of run time summed "
                    f"over the runs ({res.executed} run in this call, {wall:.0f} s wall)")
        print(took[-1], file=sys.stderr)
        results = draw_results(table, list(spec.grid.case or []))
        rows.append((label, distribution(results)))
        levels.append((label, table))
        ds = _draws_of(spec_path)
        blocks["worst" if sub == "main" else f"worst-{sub}"] = worst_table(results, ds)
        if sub == "main":  # what drives the ratio: tuned on nothing, read on the main set only
            blocks["drivers"] = drivers_table(results, ds)
        # what each error of the worst draws costs: the default told one part of the plant at a time
        worst = [r.case for r in worst_draws(results, 1 if steps is not None else WORST_K)]
        grid = spec.grid.model_copy(update={
            "case": worst, "controller": ["default", "oracle-tuned", *(n for n, _, _ in ATTRIBUTION)]})
        told = spec.model_copy(update={"name": f"{spec.name}-attribution", "grid": grid,
                                       "controllers": {**spec.controllers, **attribution_controllers()}})
        t0 = time.perf_counter()
        res = run_sweep(told, out / f"attribution-{sub}", workers=workers, resume=True, plots=False)
        wall = time.perf_counter() - t0
        took.append(f"{label}, told one part: {res.n_runs} runs ({res.executed} run in this call, "
                    f"{wall:.0f} s wall)")
        print(took[-1], file=sys.stderr)
        blocks["attribution" if sub == "main" else f"attribution-{sub}"] = attribution_table(
            aggregate(out / f"attribution-{sub}", [t.id for t in expand(told)]), worst)
    blocks["table"] = summary_table(rows)
    blocks["levels"] = levels_table(levels)
    blocks["time"] = "; ".join(took) + f" (load average {os.getloadavg()[0]:.1f})"
    return blocks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/generalisation"),
                    help="the sweeps' output folder (main/ and heldback/ in it); runs on disk are kept")
    ap.add_argument("--workers", type=int, default=2, help="local Dask workers")
    args = ap.parse_args()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    out = Path(tempfile.mkdtemp(prefix="tsmpc-generalisation-")) if steps is not None else args.out
    blocks = generalisation_blocks(out, workers=1 if steps is not None else args.workers, steps=steps)
    for name, body in blocks.items():
        print(f"\n## {name}\n\n{body}")


if __name__ == "__main__":
    main()
