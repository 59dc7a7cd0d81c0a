"""Per-step wall time of the published run's inner law (``AsRunLQR``, the ``paper-as-run`` preset,
Python only) next to our TS-LQR (``TSLQR``, compiled and numpy) measured in the same run.

Each law runs its own preset (design, T_d, saturations) on the true state [v, α, ω], closed against
the Pacejka plant at v_ref = 10 m/s with a sinusoidal yaw-rate reference (changing every T_c, as in
the cascade) and the paper's dry-asphalt friction (μ = 0.9). ``as_run_numpy_formula`` times what
the as-run step computed with the public numpy functions before it was written on plain floats
(``AsRunLQR.gains`` + ``model5`` + ``as_run_reference_gain``, at the step's own scheduling point;
the rest of the step not included), the reference the step is tested against.

Usage: python benchmarks/as_run_step.py [--json] [--steps 6000]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config
from tsmpc.control.paper_as_run import AsRunLQR, as_run_reference_gain
from tsmpc.control.ts_lqr import TSLQR
from tsmpc.estimation.mhe_uio import Estimate, EstimatorStatus
from tsmpc.models.dynamic import DynamicTS
from tsmpc.synthesis.cache import load_or_design_dynamic
from tsmpc.vehicle.plant import Plant


def _stats(t: np.ndarray) -> dict[str, float]:
    us = t * 1e6
    return {"median": float(np.median(us)), "p95": float(np.percentile(us, 95)),
            "p99": float(np.percentile(us, 99)), "max": float(us.max())}


def _law(cfg: Config, kind: str) -> Any:
    Td = cfg.rates.Td
    dd = load_or_design_dynamic(cfg)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    bw = cfg.dynamic_lmi.filter_bandwidth
    if kind == "as_run":
        return AsRunLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td, bandwidth=bw)
    return TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td, bandwidth=bw, jit=kind == "ts_lqr")


def measure(cfg: Config, kind: str, steps: int) -> dict[str, dict[str, float]]:
    """Closed loop of ``steps`` inner steps; the law's step timed (and, for the as-run law, the
    numpy formula of K and N̄ at the same point, outside the loop's state)."""
    law = _law(cfg, kind)
    plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    t_law, t_formula = np.empty(steps), np.empty(steps)
    formula: Callable[[], object] | None = None
    if kind == "as_run":
        shift = cfg.lqr.scheduling_speed_shift
        bias = cfg.lqr.steering_bias_rad

        def formula() -> object:
            d = law.state[1] - bias
            K = law.gains((d, float(x[3]) + shift, float(x[4])))
            return as_run_reference_gain(law.model5(d, float(x[3])), law.B5, K)

    clock = time.perf_counter
    for k in range(steps):
        est = Estimate(x[3:6].copy(), 0.0, 0.0, EstimatorStatus.OK, 0.0)  # the true state
        w_ref = 0.15 * np.sin(0.3 * (k // cfg.rates.inner_per_outer) * cfg.rates.Tc)
        t0 = clock()
        cmd = law.step(est, 10.0, w_ref)
        t1 = clock()
        if formula is not None:
            formula()
            t_formula[k] = clock() - t1
        x = plant.step(x, np.array([cmd.F_xR, cmd.delta]), 0.9, cfg.rates.plant_per_inner)
        t_law[k] = t1 - t0
    skip = min(100, steps // 10)
    out = {kind: _stats(t_law[skip:])}
    if formula is not None:
        out["as_run_numpy_formula"] = _stats(t_formula[skip:])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--steps", type=int, default=6000)
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    as_run, ours = Config.preset("paper-as-run"), Config()
    runs = ((as_run, "as_run"), (ours, "ts_lqr"), (ours, "ts_lqr_numpy"))
    for cfg, kind in runs:
        measure(cfg, kind, 200)  # untimed: designs and kernels loaded, caches warm
    res: dict[str, dict[str, float]] = {}
    for cfg, kind in runs:
        res.update(measure(cfg, kind, args.steps))
    a = res["as_run"]["median"]
    out = {"unit": "µs per inner step", "results": res,
           "ratio_as_run_to_ts_lqr": a / res["ts_lqr"]["median"],
           "ratio_as_run_to_ts_lqr_numpy": a / res["ts_lqr_numpy"]["median"],
           "load_average": os.getloadavg()}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{'law':22s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s}   (µs per step)")
    for k, s in res.items():
        print(f"{k:22s} {s['median']:8.1f} {s['p95']:8.1f} {s['p99']:8.1f} {s['max']:8.1f}")
    print(f"as-run / TS-LQR median: {out['ratio_as_run_to_ts_lqr']:.1f}x (compiled), "
          f"{out['ratio_as_run_to_ts_lqr_numpy']:.1f}x (numpy)")
    print(f"load average {out['load_average'][0]:.1f}")


if __name__ == "__main__":
    main()
