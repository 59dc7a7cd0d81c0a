"""Per-step wall time of the outer MPCs in a receding-horizon loop on the kinematic error model.

Scheduling + build + solve (everything a vehicle waits for), along the paper's reference
(`tsmpc data fetch paper`, or ../shared/data in a checkout; columns 5…1316) when present, else the
built-in circuit; start from a 2 m / 0.1 rad error. Prints median/p95/p99/max [ms], QP
iterations and the NL/method ratio measured in the same run, for the compiled fast path
(``results``) and the numpy condensed path (``results_numpy``, the kernels' oracle).

Usage: python benchmarks/mpc_step.py [--json] [--steps 1272] [--no-nl] [--no-numpy]
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np

from tsmpc import datasets
from tsmpc.blas import limit_blas_threads
from tsmpc.config import Config, SchedulingMode
from tsmpc.control.nl_mpc import NLMPC
from tsmpc.control.ts_mpc import TSMPC
from tsmpc.models.kinematic import KinematicTS, nonlinear_step
from tsmpc.synthesis.cache import load_or_design_kinematic

#: The paper's reference where tsmpc finds it ($TSMPC_DATA_DIR, `tsmpc data fetch paper`, ../shared), or None.
PAPER = datasets.find("paper")


def _reference():
    if PAPER is not None:
        from tsmpc.planning.paper_format import load_paper_reference

        return load_paper_reference(PAPER), "paper reference"
    from tsmpc.planning.circuit import builtin_circuit

    return builtin_circuit(), "built-in circuit"


def run(ctrl, ref, steps: int, N: int, Tc: float, warmup: int = 100) -> dict[str, float]:
    if warmup:  # untimed pass first: allocator, caches and solver set-up are not per-step costs
        run(ctrl, ref, warmup, N, Tc, warmup=0)
        ctrl.reset()
    e = np.array([0.0, 2.0, 0.1])
    u = np.array([ref.v[0], ref.omega[0]])
    times, its = [], []
    for k in range(min(steps, len(ref) - N - 1)):
        w = ref.window(k, N + 1)
        r = ctrl.step(e, u, w)
        times.append(r.solve_time_s * 1e3)
        its.append(r.qp_iterations)
        u = r.u
        e = nonlinear_step(e, u, w.v[0], w.omega[0], Tc)
    t = np.array(times)
    return {"median": float(np.median(t)), "p95": float(np.percentile(t, 95)),
            "p99": float(np.percentile(t, 99)), "max": float(t.max()),
            "mean_iterations": float(np.mean(its)), "final_error_m": float(np.abs(e[:2]).max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--steps", type=int, default=1272)
    ap.add_argument("--no-nl", action="store_true", help="skip the NL-MPC baseline")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy (no kernels) pass")
    args = ap.parse_args()
    limit_blas_threads()  # one BLAS thread, as the CLI and every simulating process (tsmpc.blas)
    cfg = Config()
    d = load_or_design_kinematic(cfg)
    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    ref, src = _reference()
    res, res_np = {}, {}
    modes = (SchedulingMode.FZN, SchedulingMode.REF, SchedulingMode.ITER)
    for mode in modes:
        res[mode.value.upper()] = run(TSMPC(cfg.mpc, model, d.P, d.S, mode=mode), ref, args.steps,
                                      cfg.mpc.N, cfg.rates.Tc)
    if not args.no_nl:
        res["NL"] = run(NLMPC(cfg.mpc, model, d.P, d.S), ref, args.steps, cfg.mpc.N, cfg.rates.Tc)
    if not args.no_numpy:
        for mode in modes:
            res_np[mode.value.upper()] = run(TSMPC(cfg.mpc, model, d.P, d.S, mode=mode, jit=False), ref,
                                             args.steps, cfg.mpc.N, cfg.rates.Tc)
    out = {"unit": "ms per MPC step", "reference": src, "results": res,
           "load_average": os.getloadavg()}
    if res_np:
        out["results_numpy"] = res_np
        out["speedup_vs_numpy"] = {k: v["median"] / res[k]["median"] for k, v in res_np.items()}
    if "NL" in res:
        out["nl_ratio"] = {k: res["NL"]["median"] / v["median"] for k, v in res.items() if k != "NL"}
        if res_np:
            out["nl_ratio_numpy"] = {k: res["NL"]["median"] / v["median"] for k, v in res_np.items()}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"MPC step on the {src} ({args.steps} steps; ms)")
    print(f"{'method':8s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s} {'QP it':>6s} {'NL/x':>6s}")
    for k, s in res.items():
        ratio = out.get("nl_ratio", {}).get(k, float("nan"))
        print(f"{k:8s} {s['median']:8.3f} {s['p95']:8.3f} {s['p99']:8.3f} {s['max']:8.3f} "
              f"{s['mean_iterations']:6.2f} {ratio:6.1f}")
    for k, s in res_np.items():
        ratio = out.get("nl_ratio_numpy", {}).get(k, float("nan"))
        print(f"{k + ' np':8s} {s['median']:8.3f} {s['p95']:8.3f} {s['p99']:8.3f} {s['max']:8.3f} "
              f"{s['mean_iterations']:6.2f} {ratio:6.1f}   (numpy path; kernel speed-up "
              f"{out['speedup_vs_numpy'][k]:.1f}x)")
    print(f"load average {out['load_average'][0]:.1f}")


if __name__ == "__main__":
    main()
