"""A Monte-Carlo sweep of whole paper runs, timed as a user runs it: ``tsmpc sweep`` of R runs
(noise seeds × plant mass draws, REF, the whole 127.2 s paper reference) on a local cluster of 2
worker processes, the whole command's wall time (cluster start-up, designs and kernels loaded
from the caches, records, the aggregate table; no plots). Issue 25's measure: 1000 runs ≤ 90 s.

By default the sweep sends batches of runs to the workers (tsmpc.sim.batch); ``--baseline`` also
times the same sweep with ``--batch 1`` (each run its own task, through the run engine) in the
same process, for the ratio.

Usage: python benchmarks/sweep_runs.py [--json] [--runs 1000] [--workers 2] [--baseline]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tsmpc import datasets
from tsmpc.blas import limit_blas_threads

#: The paper's reference where tsmpc finds it ($TSMPC_DATA_DIR, `tsmpc data fetch paper`, ../shared), or None.
PAPER = datasets.find("paper")
MASSES = [0.95, 1.0, 1.05, 1.1]


def _tsmpc() -> str:
    here = Path(sys.executable).parent / "tsmpc"
    return str(here) if here.is_file() else "tsmpc"


def _sweep(folder: Path, runs: int, workers: int, batch: int | None) -> dict:
    seeds = list(range(max(1, runs // len(MASSES))))
    f = folder / "sweep.toml"
    f.write_text(f'name = "paper-runs"\n[grid]\nmethod = ["ref"]\ntrack = ["{PAPER}"]\n'
                 f"mass_scale = {MASSES}\nseed = {seeds}\n")
    out = folder / f"out-{batch}"
    cmd = [_tsmpc(), "sweep", str(f), "--out", str(out), "--workers", str(workers), "--no-plots"]
    if batch is not None:
        cmd += ["--batch", str(batch)]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"tsmpc sweep failed (exit {res.returncode}):\n"
                         f"{res.stdout[-2000:]}{res.stderr[-2000:]}")
    recs = [json.loads(p.read_text()) for p in (out / "runs").glob("*.json")]
    n = len(seeds) * len(MASSES)
    completed = sum(r["status"] == "completed" for r in recs)
    return {"runs": n, "records": len(recs), "completed": completed, "wall_s": wall,
            "runs_per_s": n / wall, "batch": batch if batch is not None else "default"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--baseline", action="store_true", help="also time --batch 1 (one run per task)")
    args = ap.parse_args()
    limit_blas_threads()  # as every benchmark (the sweep's processes limit themselves too)
    if PAPER is None:
        raise SystemExit("needs the paper reference: run `tsmpc data fetch paper`")
    subprocess.run([_tsmpc(), "warmup"], check=True, capture_output=True)  # untimed: compile once
    out: dict = {"workers": args.workers, "load_average": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        out["batched"] = _sweep(Path(tmp), args.runs, args.workers, None)
        if args.baseline:
            out["one_run_per_task"] = _sweep(Path(tmp), args.runs, args.workers, 1)
            out["ratio"] = out["one_run_per_task"]["wall_s"] / out["batched"]["wall_s"]
    out["target_wall_s_for_1000"] = 90.0
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"tsmpc sweep of paper runs (REF, noise seeds × {len(MASSES)} mass scales) on "
          f"{args.workers} local workers (load average {out['load_average'][0]:.1f}):")
    for key in ("batched", "one_run_per_task"):
        r = out.get(key)
        if r is not None:
            print(f"  {key:17s} {r['runs']} runs ({r['completed']} completed) in {r['wall_s']:.1f} s "
                  f"wall, {r['runs_per_s']:.1f} runs/s")
    if "ratio" in out:
        print(f"  batched / one run per task: {out['ratio']:.2f}x faster")
    print("target (issue 25): 1000 runs in 90 s")


if __name__ == "__main__":
    main()
