"""Monte-Carlo throughput: B paper runs that differ in their noise seed, in one process on one core
(issue 25 item 2's measure: runs per second per core).

Each run goes through ``simulate()`` and therefore through the compiled run engine
(:mod:`tsmpc.sim.engine`: the whole run in one compiled call), with the LMI designs loaded once and
shared, as a sweep worker does. The B runs are stepped one after another: the structure-of-arrays
batch of item 2 (B runs advanced together in one compiled call, vectorised across runs) is not
implemented, so this is its baseline. Reported: runs per second per core (B over the process's CPU
time), the per-run loop time of the engine and everything around it (Cascade set-up, noise draws,
the RunLog), and a few runs of the Python loop for comparison (``--python N``).

Usage: python benchmarks/batch_runs.py [--json] [--B 64] [--method ref] [--python 2]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config, replace
from tsmpc.sim.simulator import simulate

PAPER = Path(__file__).resolve().parents[2] / "shared" / "data" / "paper" / "planner_references_100ms.csv"


def _runs(cfg: Config, scenario, method: str, seeds: range, designs: tuple, engine: bool) -> dict:
    """Run every seed; wall and CPU time of the whole batch, per-run loop and call times."""
    loops, calls = [], []
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for s in seeds:
        t0 = time.perf_counter()
        log = simulate(replace(cfg, seed=s), method, scenario, kinematic_design=designs[0],
                       dynamic_design=designs[1], engine=engine)
        calls.append(time.perf_counter() - t0)
        loops.append(log.wall_s)
        assert log.termination == "completed", log.termination
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    n = len(seeds)
    return {"runs": n, "wall_s": wall, "cpu_s": cpu, "runs_per_s_per_core": n / cpu,
            "runs_per_s_wall": n / wall, "loop_s_median": float(np.median(loops)),
            "call_s_median": float(np.median(calls)),
            "outside_loop_s_median": float(np.median(np.array(calls) - np.array(loops)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--B", type=int, default=64, help="runs (noise seeds 0…B-1)")
    ap.add_argument("--method", default="ref", help="fzn, ref or iter")
    ap.add_argument("--python", type=int, default=2, help="runs of the Python loop for comparison")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as every simulating process (tsmpc.blas)
    from tsmpc.sim import engine
    from tsmpc.sim.compare import load_scenario
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    cfg = Config()
    scenario = load_scenario(cfg, PAPER if PAPER.exists() else None)
    designs = (load_or_design_kinematic(cfg), load_or_design_dynamic(cfg))
    method = args.method.upper()
    simulate(cfg, method, scenario, kinematic_design=designs[0], dynamic_design=designs[1],
             max_steps=2)  # untimed: the kernels' compilation or loading
    out: dict = {"reference": scenario.name, "method": method, "B": args.B,
                 "engine_applies": engine.applicability(cfg, method, scenario) is None,
                 "engine": _runs(cfg, scenario, method, range(args.B), designs, True)}
    if args.python > 0:
        out["python_loop"] = _runs(cfg, scenario, method, range(args.python), designs, False)
    out["target_runs_per_s_per_core"] = 15.0
    out["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{args.B} {method} runs on the {scenario.name}, noise seeds 0…{args.B - 1}, one core "
          f"(load average {out['load_average'][0]:.1f}); engine applies: {out['engine_applies']}")
    for name in ("engine", "python_loop"):
        r = out.get(name)
        if r is not None:
            print(f"{name:12s} {r['runs_per_s_per_core']:6.2f} runs/s per core ({r['runs']} runs, "
                  f"{r['cpu_s']:.1f} s CPU, {r['wall_s']:.1f} s wall); per run: loop "
                  f"{r['loop_s_median']:.3f} s, around it {r['outside_loop_s_median']:.3f} s (medians)")
    print(f"target (issue 25, B = 64): {out['target_runs_per_s_per_core']:.0f} runs/s per core")


if __name__ == "__main__":
    main()
