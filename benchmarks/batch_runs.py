"""Monte-Carlo throughput: B paper runs that differ in their noise seed, in one process on one core
(issue 25 item 2's measure: runs per second per core, target 15 at B = 64).

Three ways, in the same process, with the LMI designs loaded once and shared (as a sweep worker
does):

* ``batch``: :func:`tsmpc.sim.batch.simulate_batch` steps the B runs together, the plant's RK4 and
  the MHE window solves vectorised across runs (what ``tsmpc sweep`` sends to its workers);
* ``engine``: the B runs one after another through ``simulate()``, i.e. the compiled run engine
  (one compiled call per run) — the baseline;
* ``python_loop``: a few runs of the Python loop, for comparison (``--python N``).

Reported: runs per second per core (B over the process's CPU time), per-run loop time and the
time around it (Cascade set-up, noise draws, the RunLog), the ratio batch / engine, and the
largest state difference between a batched run and the same run by the engine (rounding of the
vectorised plant's polynomial transcendentals).

Usage: python benchmarks/batch_runs.py [--json] [--B 64] [--method ref] [--python 2] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from tsmpc import datasets
from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config, replace
from tsmpc.sim.simulator import simulate

#: The paper's reference where tsmpc finds it ($TSMPC_DATA_DIR, `tsmpc data fetch paper`, ../shared), or None.
PAPER = datasets.find("paper")


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


def _batched(cfg: Config, scenario, method: str, seeds: range, designs: tuple) -> dict:
    from tsmpc.sim import batch

    cpu0, wall0 = time.process_time(), time.perf_counter()
    logs = batch.simulate_batch(cfg, method, scenario, seeds=list(seeds), kinematic_design=designs[0],
                                dynamic_design=designs[1])
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    assert batch.LAST_BATCH["batched"] == len(seeds), batch.LAST_BATCH["single"]
    assert all(log.termination == "completed" for log in logs)
    n = len(seeds)
    facts = batch.LAST_BATCH
    return {"runs": n, "wall_s": wall, "cpu_s": cpu, "runs_per_s_per_core": n / cpu,
            "runs_per_s_wall": n / wall, "loop_s_per_run": facts["loop_s"] / n,
            "outside_loop_s_per_run": (wall - facts["loop_s"]) / n,
            "plant_s_per_run": facts.get("plant_s", float("nan")) / n,
            "mhe_s_per_run": facts.get("mhe_s", float("nan")) / n,
            "setup_s_per_run": facts["setup_s"] / n, "logs_s_per_run": facts["logs_s"] / n,
            "slow_paths": dict(facts["slow_paths"]), "logs": logs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--B", type=int, default=64, help="runs (noise seeds 0…B-1)")
    ap.add_argument("--method", default="ref", help="fzn, ref or iter")
    ap.add_argument("--python", type=int, default=2, help="runs of the Python loop for comparison")
    ap.add_argument("--repeat", type=int, default=5, help="batches timed (the median is reported)")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as every simulating process (tsmpc.blas)
    from tsmpc.sim import batch, engine
    from tsmpc.sim.compare import load_scenario
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    cfg = Config()
    scenario = load_scenario(cfg, PAPER)
    designs = (load_or_design_kinematic(cfg), load_or_design_dynamic(cfg))
    method = args.method.upper()
    simulate(cfg, method, scenario, kinematic_design=designs[0], dynamic_design=designs[1],
             max_steps=2)  # untimed: the kernels' compilation or loading
    batch.warmup()
    seeds = range(args.B)
    one = simulate(replace(cfg, seed=seeds[-1]), method, scenario, kinematic_design=designs[0],
                   dynamic_design=designs[1])
    tries = []
    for _ in range(max(1, args.repeat)):  # as a sweep worker: each batch's logs dropped after use
        r = _batched(cfg, scenario, method, seeds, designs)
        r["max_state_diff"] = float(np.max(np.abs(r.pop("logs")[-1].state - one.state)))
        tries.append(r)
    best = sorted(tries, key=lambda r: r["cpu_s"])[len(tries) // 2]  # the median batch
    out: dict = {"reference": scenario.name, "method": method, "B": args.B,
                 "engine_applies": engine.applicability(cfg, method, scenario) is None,
                 "batch": best, "batch_runs_per_s_per_core_all": [r["runs_per_s_per_core"] for r in tries],
                 "engine": _runs(cfg, scenario, method, seeds, designs, True)}
    out["batch_vs_engine_max_state_diff"] = max(r["max_state_diff"] for r in tries)
    out["ratio_batch_over_engine"] = (best["runs_per_s_per_core"]
                                      / out["engine"]["runs_per_s_per_core"])
    if args.python > 0:
        out["python_loop"] = _runs(cfg, scenario, method, range(args.python), designs, False)
    out["target_runs_per_s_per_core"] = 15.0
    out["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{args.B} {method} runs on the {scenario.name}, noise seeds 0…{args.B - 1}, one core "
          f"(load average {out['load_average'][0]:.1f}); engine applies: {out['engine_applies']}")
    b = out["batch"]
    print(f"{'batch':12s} {b['runs_per_s_per_core']:6.2f} runs/s per core (median of "
          f"{len(tries)} batches: {', '.join(f'{x:.2f}' for x in out['batch_runs_per_s_per_core_all'])}); "
          f"per run: loop {b['loop_s_per_run']:.3f} s (plant {b['plant_s_per_run']:.3f}, MHE windows "
          f"{b['mhe_s_per_run']:.3f}), around it {b['outside_loop_s_per_run']:.3f} s")
    for name in ("engine", "python_loop"):
        r = out.get(name)
        if r is not None:
            print(f"{name:12s} {r['runs_per_s_per_core']:6.2f} runs/s per core ({r['runs']} runs, "
                  f"{r['cpu_s']:.1f} s CPU, {r['wall_s']:.1f} s wall); per run: loop "
                  f"{r['loop_s_median']:.3f} s, around it {r['outside_loop_s_median']:.3f} s (medians)")
    print(f"batch / engine: {out['ratio_batch_over_engine']:.2f}x; largest state difference of run "
          f"{seeds[-1]}, batch vs engine: {out['batch_vs_engine_max_state_diff']:.1e}")
    print(f"target (issue 25, B = 64): {out['target_runs_per_s_per_core']:.0f} runs/s per core")


if __name__ == "__main__":
    main()
