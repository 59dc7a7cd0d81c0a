"""Cost of one 1 ms RK4 plant step (Pacejka and linear tyres), in microseconds.

Usage: python benchmarks/plant_step.py [--json] [--n 20000]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.vehicle.plant import Plant


def _stats(samples_us: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(samples_us)),
        "p95": float(np.percentile(samples_us, 95)),
        "p99": float(np.percentile(samples_us, 99)),
        "max": float(np.max(samples_us)),
    }


def measure(tyre: TyreModel, n: int, substeps: int) -> dict[str, float]:
    cfg = Config()
    plant = Plant(cfg.vehicle, TyreParams(model=tyre), cfg.rates.h)
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
    args = ap.parse_args()
    res = {
        f"{tyre.value}_{label}": measure(tyre, args.n // sub, sub)
        for tyre in (TyreModel.PACEJKA, TyreModel.LINEAR)
        for label, sub in (("1step", 1), ("10steps_per_call", 10))
    }
    base = res["pacejka_1step"]["median"]
    out = {"unit": "us per 1 ms plant step", "results": res,
           "paper_run_plant_s": base * 127_200 * 1e-6}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{'case':34s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s}  (µs/step)")
    for k, s in res.items():
        print(f"{k:34s} {s['median']:8.2f} {s['p95']:8.2f} {s['p99']:8.2f} {s['max']:8.1f}"
              f"   ratio to pacejka_1step {s['median'] / base:5.2f}")
    print(f"127.2 s paper run (127200 steps, one step per call): {out['paper_run_plant_s']:.2f} s")


if __name__ == "__main__":
    main()
