"""Whole-run cost of the cascade: the simulation loop of a method on the paper reference
(../shared/data/paper/planner_references_100ms.csv, columns 5…1316; else the built-in circuit),
with the per-block medians/p99 *inside* the loop (MPC, MHE-UIO, TS-LQR and the plant block of
T_d/h RK4 steps), the loop time and the real-time factor — compiled kernels and numpy in the same
run (``--no-numpy`` skips the numpy pass).

Usage: python benchmarks/cascade_run.py [--json] [--methods ref] [--no-numpy] [--steps K]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config
from tsmpc.sim.simulator import default_plant, simulate

PAPER = Path(__file__).resolve().parents[2] / "shared" / "data" / "paper" / "planner_references_100ms.csv"


class TimedPlant:
    """Wraps a plant and times each ``step`` (the T_d/h RK4 block)."""

    def __init__(self, plant) -> None:
        self.plant = plant
        self.times: list[float] = []

    def step(self, u, dt, mu):
        t0 = time.perf_counter()
        x = self.plant.step(u, dt, mu)
        self.times.append(time.perf_counter() - t0)
        return x

    def __getattr__(self, name):
        return getattr(self.plant, name)


def _stats(t_s: np.ndarray) -> dict[str, float]:
    t = np.asarray(t_s) * 1e3
    return {"median": float(np.median(t)), "p95": float(np.percentile(t, 95)),
            "p99": float(np.percentile(t, 99)), "max": float(t.max())}


def run(cfg: Config, scenario, method: str, steps: int | None) -> dict:
    plant = TimedPlant(default_plant(cfg, scenario))
    cpu0 = time.process_time()
    log = simulate(cfg, method, scenario, plant=plant, max_steps=steps)
    cpu = time.process_time() - cpu0  # the whole simulate() call; on a busy machine wall > CPU
    sim_s = len(log.t_outer) * cfg.rates.Tc
    return {
        "loop_s": float(log.wall_s), "simulate_cpu_s": cpu, "simulated_s": sim_s,
        "realtime_factor": sim_s / log.wall_s,
        "termination": log.termination,
        "ms": {"mpc": _stats(log.mpc_time_s), "mhe": _stats(log.mhe_time_s), "lqr": _stats(log.lqr_time_s),
               "plant_block": _stats(np.array(plant.times))},
        "rmse": {k: float(np.sqrt(np.mean(v ** 2))) for k, v in
                 (("x", log.errors[:, 0]), ("y", log.errors[:, 1]), ("theta", log.errors[:, 2]))},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--methods", default="ref", help="comma-separated: fzn,ref,iter,nl")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy (TSMPC_NO_JIT) pass")
    ap.add_argument("--steps", type=int, default=None, help="outer steps (default: the whole run)")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    from tsmpc import kernels
    from tsmpc.sim.compare import load_scenario

    cfg = Config()
    scenario = load_scenario(cfg, PAPER if PAPER.exists() else None)
    t0 = time.perf_counter()
    kernels.warmup()
    load_s = time.perf_counter() - t0
    out: dict = {"unit": "ms per call inside the cascade; loop_s in s", "reference": scenario.name,
                 "kernel_load_s": load_s, "results": {}, "results_numpy": {}}
    methods = [m.strip().upper() for m in args.methods.split(",") if m.strip()]
    for m in methods:
        simulate(cfg, m, scenario, max_steps=20)  # untimed: designs, solver set-up
        out["results"][m] = run(cfg, scenario, m, args.steps)
    if not args.no_numpy:
        os.environ["TSMPC_NO_JIT"] = "1"
        for m in methods:
            out["results_numpy"][m] = run(cfg, scenario, m, args.steps)
        os.environ.pop("TSMPC_NO_JIT")
        out["speedup_loop"] = {m: out["results_numpy"][m]["loop_s"] / out["results"][m]["loop_s"]
                               for m in methods}
    out["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"Cascade run on the {scenario.name} (kernel load {load_s:.2f} s; load average "
          f"{out['load_average'][0]:.1f})")
    print(f"{'method':6s} {'path':6s} {'loop s':>7s} {'CPU s':>6s} {'RT x':>6s} "
          + " ".join(f"{b + ' med/p99':>17s}" for b in ("mpc", "mhe", "lqr", "plant_block")))
    for path in ("results", "results_numpy"):
        for m, r in out[path].items():
            cells = " ".join(f"{r['ms'][b]['median']:8.4f}/{r['ms'][b]['p99']:8.4f}"
                             for b in ("mpc", "mhe", "lqr", "plant_block"))
            print(f"{m:6s} {'numba' if path == 'results' else 'numpy':6s} {r['loop_s']:7.2f} "
                  f"{r['simulate_cpu_s']:6.2f} {r['realtime_factor']:6.0f} {cells}")
    for m, s in out.get("speedup_loop", {}).items():
        print(f"{m}: loop speed-up numba vs numpy {s:.1f}x")


if __name__ == "__main__":
    main()
