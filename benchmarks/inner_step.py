"""Per-step wall time of the inner loop: MHE-UIO step (window update + build + solve) and TS-LQR
step, closed against the Pacejka plant at 10 m/s with a sinusoidal yaw-rate reference and the
paper's dry-asphalt friction (μ = 0.9). Also times the plant block (T_d/h RK4 steps) in the same
loop, and repeats everything on the numpy implementations (``results_numpy``) unless --no-numpy.

Usage: python benchmarks/inner_step.py [--json] [--steps 6000] [--no-numpy]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config
from tsmpc.control.ts_lqr import TSLQR
from tsmpc.estimation.mhe_uio import MHEUIO
from tsmpc.models.dynamic import DynamicTS
from tsmpc.scenarios import SensorNoise
from tsmpc.synthesis.cache import load_or_design_dynamic
from tsmpc.vehicle.plant import Plant


def _stats(t: np.ndarray) -> dict[str, float]:
    return {"median": float(np.median(t)), "p95": float(np.percentile(t, 95)),
            "p99": float(np.percentile(t, 99)), "max": float(t.max())}


def measure(cfg: Config, steps: int, jit: bool) -> dict[str, dict[str, float]]:
    Td = cfg.rates.Td
    dd = load_or_design_dynamic(cfg)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    lqr = TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td, jit=jit)
    plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h, jit=jit)
    noise = SensorNoise(cfg.noise, 0)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, Td, x[3:6], jit=jit)
    u = np.zeros(2)
    t_mhe, t_lqr, t_pl = np.empty(steps), np.empty(steps), np.empty(steps)
    clock = time.perf_counter
    for k in range(steps):
        y = np.array([x[3], x[5]]) + noise.sample()[3:5]
        t0 = clock()
        e = mhe.step(y, u)
        t1 = clock()
        k_out = k // cfg.rates.inner_per_outer  # references change every T_c, as in the cascade
        cmd = lqr.step(e, 10.0, 0.15 * np.sin(0.3 * k_out * cfg.rates.Tc))
        t2 = clock()
        u = np.array([cmd.F_xR, cmd.delta])
        x = plant.step(x, u, 0.9, cfg.rates.plant_per_inner)
        t3 = clock()
        t_mhe[k], t_lqr[k], t_pl[k] = t1 - t0, t2 - t1, t3 - t2
    skip = cfg.mhe.N  # after the warm-up window
    return {"mhe": _stats(t_mhe[skip:] * 1e3), "lqr": _stats(t_lqr[skip:] * 1e3),
            "plant_block": _stats(t_pl[skip:] * 1e3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--steps", type=int, default=6000)
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy (no kernels) pass")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    cfg = Config()
    measure(cfg, 200, True)  # untimed: kernels loaded, caches warm
    res = measure(cfg, args.steps, True)
    out = {"unit": "ms per inner step", "results": res,
           "ratio_mhe_to_lqr": res["mhe"]["median"] / res["lqr"]["median"],
           "load_average": os.getloadavg()}
    if not args.no_numpy:
        res_np = measure(cfg, args.steps, False)
        out["results_numpy"] = res_np
        out["speedup_vs_numpy"] = {k: v["median"] / res[k]["median"] for k, v in res_np.items()}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{'block':12s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s}   (ms)")
    for key in ("results", "results_numpy"):
        for k, s in out.get(key, {}).items():
            name = k if key == "results" else k + " np"
            print(f"{name:12s} {s['median']:8.4f} {s['p95']:8.4f} {s['p99']:8.4f} {s['max']:8.4f}")
    print(f"MHE / LQR median ratio: {out['ratio_mhe_to_lqr']:.1f}")
    for k, v in out.get("speedup_vs_numpy", {}).items():
        print(f"{k}: kernel speed-up {v:.1f}x")
    print(f"load average {out['load_average'][0]:.1f}")


if __name__ == "__main__":
    main()
