"""Sweep throughput on 1 and 2 Dask workers: the same sweep (REF and FZN × four robustness
scenarios × seeds, 15 simulated seconds each) on a LocalCluster of 1, then 2 worker processes.
Prints the wall time of each (cluster start-up excluded), runs per second and the speed-up.

Usage: python benchmarks/sweep_scaling.py [--json] [--seeds 2] [--duration 15]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from tsmpc.blas import limit_blas_threads
from tsmpc.sweep import load_sweep, run_sweep

SWEEP = """
name = "scaling"
duration_s = {duration}
[grid]
method = ["ref", "fzn"]
scenario = ["nominal", "noise_x10", "nan_bursts", "mass_stiffness_mismatch"]
seed = {seeds}
"""


def _timed(spec, workers: int, root: Path) -> float:
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as cluster:
        # Warm every worker (imports, design cache) so start-up is not charged to the sweep.
        warm = load_sweep_text(SWEEP.format(duration=0.1, seeds=list(range(100, 100 + workers))), root)
        run_sweep(warm, root / f"warm{workers}", scheduler=cluster.scheduler_address, plots=False)
        t0 = time.perf_counter()
        run_sweep(spec, root / f"w{workers}", scheduler=cluster.scheduler_address, plots=False)
        return time.perf_counter() - t0


def load_sweep_text(text: str, root: Path):
    path = root / f"s{abs(hash(text))}.toml"
    path.write_text(text)
    return load_sweep(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--duration", type=float, default=15.0)
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        seeds = list(range(1, args.seeds + 1))
        spec = load_sweep_text(SWEEP.format(duration=args.duration, seeds=seeds), root)
        n = 8 * args.seeds
        walls = {w: _timed(spec, w, root) for w in (1, 2)}
    out = {"runs": n, "simulated_s_per_run": args.duration, "wall_s": walls,
           "runs_per_s": {w: n / t for w, t in walls.items()}, "speedup_2_over_1": walls[1] / walls[2]}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"sweep of {n} runs × {args.duration:g} s simulated")
    print(f"{'workers':>8s} {'wall [s]':>9s} {'runs/s':>8s}")
    for w, t in walls.items():
        print(f"{w:8d} {t:9.2f} {n / t:8.2f}")
    print(f"speed-up 2 workers / 1 worker: {out['speedup_2_over_1']:.2f}×")


if __name__ == "__main__":
    main()
