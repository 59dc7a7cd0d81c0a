"""Per-call wall time of ``Cascade.step`` on the built-in circuit (REF, tsmpc's plant, default
noise) and the share of it spent outside the blocks (the cascade's own bookkeeping: measurement
checks, scheduling, fallbacks, event counting), measured in the same run:
overhead = step time − (MPC + MHE + LQR times reported in the Command).

Usage: python benchmarks/cascade_step.py [--json] [--steps 3000]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config
from tsmpc.control.cascade import Cascade, Measurement
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.scenarios import SensorNoise
from tsmpc.vehicle.plant import VehiclePlant


def _stats(t: np.ndarray) -> dict[str, float]:
    return {"median": float(np.median(t)), "p95": float(np.percentile(t, 95)),
            "p99": float(np.percentile(t, 99)), "max": float(t.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--steps", type=int, default=3000)
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    cfg = Config()
    ref = builtin_circuit(dt=cfg.rates.Tc)
    x = np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, ref.omega[0]])
    cas = Cascade(cfg, "ref", ref, x0=x)
    plant = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    plant.reset(x)
    noise = SensorNoise(cfg.noise, 0)
    n = args.steps
    total, blocks = np.empty(n), np.empty(n)
    clock = time.perf_counter
    for i in range(n):
        y = np.array([x[0], x[1], x[2], x[3], x[5]]) + noise.sample()
        m = Measurement.from_array(y)
        t0 = clock()
        cmd = cas.step(i * cfg.rates.Td, m)
        total[i] = clock() - t0
        blocks[i] = cmd.mpc_time_s + cmd.mhe_time_s + cmd.lqr_time_s
        x = plant.step(cmd.u, cfg.rates.Td, 0.9)
    skip = cfg.mhe.N
    over = (total - blocks)[skip:] * 1e3
    res = {"step": _stats(total[skip:] * 1e3), "overhead": _stats(over),
           "overhead_ratio_median": float(np.median(over) / np.median(total[skip:] * 1e3))}
    out = {"unit": "ms per Cascade.step call", "results": res, "steps": n,
           "load_avg_1min": os.getloadavg()[0], "events": cas.events}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"Cascade.step over {n} calls (load {out['load_avg_1min']:.2f}):")
    for k in ("step", "overhead"):
        s = res[k]
        print(f"  {k:9s} median {s['median']:.4f}  p95 {s['p95']:.4f}  p99 {s['p99']:.4f}  "
              f"max {s['max']:.3f} ms")
    print(f"  overhead / step (medians): {res['overhead_ratio_median']:.2f}")


if __name__ == "__main__":
    main()
