"""Cost of one 1 ms RK4 plant step (Pacejka and linear tyres), in microseconds.

``results`` use the compiled block (tsmpc.kernels.plant), ``results_numpy`` the float closure
(--no-numpy skips it); ``block_10steps_ms`` is the cost of one T_d = 10 ms block (10 RK4 steps,
one call), the unit the cascade calls.

Usage: python benchmarks/plant_step.py [--json] [--n 20000] [--no-numpy]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.vehicle.plant import Plant


def _stats(samples_us: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(samples_us)),
        "p95": float(np.percentile(samples_us, 95)),
        "p99": float(np.percentile(samples_us, 99)),
        "max": float(np.max(samples_us)),
    }


def measure(tyre: TyreModel, n: int, substeps: int, jit: bool = True) -> dict[str, float]:
    cfg = Config()
    plant = Plant(cfg.vehicle, TyreParams(model=tyre), cfg.rates.h, jit=jit)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.01, 0.05])
    u = (6500.0, 0.03)
    times = np.empty(n)
    clock = time.perf_counter
    for i in range(n):
        t0 = clock()
        x = plant.step(x, u, 0.9, substeps)
        times[i] = (clock() - t0) / substeps
    return _stats(times * 1e6)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true", help="print JSON")
    ap.add_argument("--n", type=int, default=20000, help="timed calls per case")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy (float closure) pass")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    measure(TyreModel.PACEJKA, 200, 10)  # untimed: kernels loaded

    def table(jit: bool) -> dict[str, dict[str, float]]:
        return {
            f"{tyre.value}_{label}": measure(tyre, args.n // sub, sub, jit)
            for tyre in (TyreModel.PACEJKA, TyreModel.LINEAR)
            for label, sub in (("1step", 1), ("10steps_per_call", 10))
        }

    res = table(True)
    base = res["pacejka_1step"]["median"]
    out = {"unit": "us per 1 ms plant step", "results": res,
           "paper_run_plant_s": base * 127_200 * 1e-6,
           "block_10steps_ms": {t: res[f"{t}_10steps_per_call"]["median"] * 10 * 1e-3
                                for t in ("pacejka", "linear")},
           "paper_run_plant_blocks_s": res["pacejka_10steps_per_call"]["median"] * 127_200 * 1e-6,
           "load_average": os.getloadavg()}
    if not args.no_numpy:
        res_np = table(False)
        out["results_numpy"] = res_np
        out["block_10steps_ms_numpy"] = {t: res_np[f"{t}_10steps_per_call"]["median"] * 10 * 1e-3
                                         for t in ("pacejka", "linear")}
        out["speedup_vs_numpy"] = {k: v["median"] / res[k]["median"] for k, v in res_np.items()}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{'case':34s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s}  (µs/step)")
    for k, s in res.items():
        print(f"{k:34s} {s['median']:8.2f} {s['p95']:8.2f} {s['p99']:8.2f} {s['max']:8.1f}"
              f"   ratio to pacejka_1step {s['median'] / base:5.2f}")
    for k, s in out.get("results_numpy", {}).items():
        print(f"{k + ' (numpy)':34s} {s['median']:8.2f} {s['p95']:8.2f} {s['p99']:8.2f} {s['max']:8.1f}"
              f"   kernel speed-up {out['speedup_vs_numpy'][k]:5.1f}x")
    print("10-step block (one T_d): " + ", ".join(f"{t} {v * 1e3:.1f} µs"
                                                    for t, v in out["block_10steps_ms"].items()))
    print(f"127.2 s paper run (127200 steps, one step per call): {out['paper_run_plant_s']:.2f} s; "
          f"in 10-step blocks: {out['paper_run_plant_blocks_s']:.2f} s")
    print(f"load average {out['load_average'][0]:.1f}")


if __name__ == "__main__":
    main()
