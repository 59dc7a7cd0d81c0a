"""Whole-run cost of the cascade: the simulation loop of a method on the paper reference
(`tsmpc data fetch paper`, or ../shared/data in a checkout; columns 5…1316; else the built-in circuit),
with the per-block medians/p99 *inside* the loop (MPC, MHE-UIO, TS-LQR and the plant block of
T_d/h RK4 steps), the loop time and the real-time factor — the Python loop with the compiled
kernels, the same with the numpy blocks (``--no-numpy`` skips it) and the compiled run engine
(:mod:`tsmpc.sim.engine`: the whole loop in one compiled call; ``--no-engine`` skips it), all in
the same run. The engine's loop time is the median of ``--repeat`` runs; its logs are compared
with the Python loop's (largest state difference, events, termination, RMSE).

Usage: python benchmarks/cascade_run.py [--json] [--methods ref] [--no-numpy] [--no-engine]
       [--repeat 5] [--steps K]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from tsmpc import datasets
from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config
from tsmpc.sim.simulator import default_plant, simulate

#: The paper's reference where tsmpc finds it ($TSMPC_DATA_DIR, `tsmpc data fetch paper`, ../shared), or None.
PAPER = datasets.find("paper")


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


def _rmse(log) -> dict[str, float]:
    return {k: float(np.sqrt(np.mean(v ** 2))) for k, v in
            (("x", log.errors[:, 0]), ("y", log.errors[:, 1]), ("theta", log.errors[:, 2]))}


def run(cfg: Config, scenario, method: str, steps: int | None, logs: dict | None = None) -> dict:
    """The Python loop (the timed plant is not tsmpc's own plant object: no engine)."""
    plant = TimedPlant(default_plant(cfg, scenario))
    cpu0 = time.process_time()
    log = simulate(cfg, method, scenario, plant=plant, max_steps=steps, engine=False)
    cpu = time.process_time() - cpu0  # the whole simulate() call; on a busy machine wall > CPU
    sim_s = len(log.t_outer) * cfg.rates.Tc
    if logs is not None:
        logs[method] = log
    return {
        "loop_s": float(log.wall_s), "simulate_cpu_s": cpu, "simulated_s": sim_s,
        "realtime_factor": sim_s / log.wall_s,
        "termination": log.termination,
        "ms": {"mpc": _stats(log.mpc_time_s), "mhe": _stats(log.mhe_time_s), "lqr": _stats(log.lqr_time_s),
               "plant_block": _stats(np.array(plant.times))},
        "rmse": _rmse(log),
    }


def run_engine(cfg: Config, scenario, method: str, steps: int | None, repeat: int, python_log) -> dict:
    """The compiled run engine, ``repeat`` runs (median loop time), against the Python loop's log."""
    from tsmpc.sim import engine

    why = engine.applicability(cfg, method, scenario)
    if why is not None:
        return {"applies": False, "reason": why}
    loops, cpus = [], []
    for _ in range(repeat):
        cpu0 = time.process_time()
        log = simulate(cfg, method, scenario, max_steps=steps)
        cpus.append(time.process_time() - cpu0)
        loops.append(float(log.wall_s))
    sim_s = len(log.t_outer) * cfg.rates.Tc
    loop = float(np.median(loops))
    same_shape = log.state.shape == python_log.state.shape
    diff = (max(float(np.max(np.abs(log.state - python_log.state))),
                float(np.max(np.abs(log.state_outer - python_log.state_outer)))) if same_shape else np.inf)
    return {
        "applies": True, "loop_s": loop, "loop_s_runs": loops, "simulate_cpu_s": float(np.median(cpus)),
        "simulated_s": sim_s, "realtime_factor": sim_s / loop, "termination": log.termination,
        "ms": {"mpc": _stats(log.mpc_time_s), "mhe": _stats(log.mhe_time_s), "lqr": _stats(log.lqr_time_s)},
        "rmse": _rmse(log), "slow_path_steps": engine.LAST_RUN.get("slow_paths"),
        "vs_python": {"max_abs_state_diff": diff, "events_equal": log.events == python_log.events,
                      "termination_equal": log.termination == python_log.termination,
                      "rmse_equal": _rmse(log) == _rmse(python_log),
                      "loop_speedup": float(python_log.wall_s) / loop},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--methods", default="ref", help="comma-separated: fzn,ref,iter,nl")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy (TSMPC_NO_JIT) pass")
    ap.add_argument("--no-engine", action="store_true", help="skip the compiled run engine pass")
    ap.add_argument("--repeat", type=int, default=5, help="engine runs per method (median loop time)")
    ap.add_argument("--steps", type=int, default=None, help="outer steps (default: the whole run)")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    from tsmpc import kernels
    from tsmpc.sim.compare import load_scenario

    cfg = Config()
    scenario = load_scenario(cfg, PAPER)
    t0 = time.perf_counter()
    kernels.warmup()
    load_s = time.perf_counter() - t0
    out: dict = {"unit": "ms per call inside the cascade; loop_s in s", "reference": scenario.name,
                 "kernel_load_s": load_s, "results": {}, "results_numpy": {}, "results_engine": {}}
    methods = [m.strip().upper() for m in args.methods.split(",") if m.strip()]
    python_logs: dict = {}
    for m in methods:
        simulate(cfg, m, scenario, max_steps=20, engine=False)  # untimed: designs, solver set-up
        out["results"][m] = run(cfg, scenario, m, args.steps, python_logs)
    if not args.no_engine:
        for m in methods:
            simulate(cfg, m, scenario, max_steps=2)  # untimed: the engine's compilation or loading
            out["results_engine"][m] = run_engine(cfg, scenario, m, args.steps, max(args.repeat, 1),
                                                  python_logs[m])
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
    for m, r in out["results_engine"].items():
        if not r["applies"]:
            print(f"{m:6s} engine does not apply: {r['reason']}")
            continue
        cells = " ".join(f"{r['ms'][b]['median']:8.4f}/{r['ms'][b]['p99']:8.4f}"
                         for b in ("mpc", "mhe", "lqr"))
        print(f"{m:6s} {'engine':6s} {r['loop_s']:7.3f} {r['simulate_cpu_s']:6.2f} "
              f"{r['realtime_factor']:6.0f} {cells}  (median of {len(r['loop_s_runs'])})")
    for m, s in out.get("speedup_loop", {}).items():
        print(f"{m}: loop speed-up numba vs numpy {s:.1f}x")
    for m, r in out["results_engine"].items():
        if r["applies"]:
            v = r["vs_python"]
            print(f"{m}: engine loop {r['loop_s']:.3f} s vs Python loop {out['results'][m]['loop_s']:.3f} s "
                  f"({v['loop_speedup']:.1f}x); max |state difference| {v['max_abs_state_diff']:.1e}; "
                  f"events {'equal' if v['events_equal'] else 'DIFFER'}; termination "
                  f"{'equal' if v['termination_equal'] else 'DIFFERS'}; RMSE "
                  f"{'equal' if v['rmse_equal'] else 'DIFFER'}; slow-path steps {r['slow_path_steps']}")


if __name__ == "__main__":
    main()
