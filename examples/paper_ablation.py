"""The README's ablation on the paper reference: the paper preset, then each mechanism beyond the
paper added one at a time, then the oracle; and the speed-mode time constants of the inner loop
per vertex of the dynamic design (README, "Why the paper's inner loop lags").

    python examples/paper_ablation.py [REFERENCE] [--figure speed_mode.png]

REFERENCE defaults to ../shared/data/paper/planner_references_100ms.csv (the paper's file, not
bundled). Every row is a full REF run of the paper window (≈ 6–10 s of CPU each).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from tsmpc.config import Config, replace
from tsmpc.control.speed_mode import speed_modes
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import Method, simulate
from tsmpc.synthesis.cache import load_or_design_dynamic

PAPER_REF = (0.501, 0.238, 0.016, 0.251, 0.013)  #: paper Table 5, REF row


def ablation_rows() -> list[tuple[str, Config, bool, str]]:
    """(label, config, oracle, what changed) of each row, in order."""
    paper = Config.preset("paper")
    fb = replace(paper, lqr=replace(paper.lqr, speed_feedback=True))
    return [
        ("paper preset", paper, False,
         "TS-LQR (LMI) + static reference gain N̄, compensation with the paper's one-step UIO F̂"),
        ("+ speed-error feedback", fb, False, "adds M (v_ref − v̂)/τ, τ = 0.3 s"),
        ("+ MHE-window friction estimate", replace(fb, lqr=replace(fb.lqr, friction_estimate="window")),
         False, "compensates the MHE's window fit of F_fr instead of the one-step formula"),
        ("+ slip-aware outer loop, tangent heading, step-average reference",
         replace(Config(), fusion=paper.fusion), False,
         "MPC errors of the velocity pose θ + α̂ against the path tangent θ_d + ω_d T_c/2"),
        ("+ fusion and adaptation (= default)", Config(), False,
         "stalled samples rejected, lost poses dead-reckoned, slip / speed offset / stiffness "
         "fitted to the course over ground, mass error's inertia separated (fusion.*)"),
        ("oracle (default, true state, no compensation)", Config(), True,
         "inner loop gets the plant state; F̂_fr not added"),
    ]


def run_row(cfg: Config, oracle: bool, reference: Path) -> dict:
    """Metrics of one REF run on the paper window, plus the force-command roughness."""
    sc = load_scenario(cfg, reference)
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None  # shortened runs (tests)
    log = simulate(cfg, Method.REF, sc, oracle=oracle, max_steps=steps)
    m = compute_metrics(log)
    m["dF_std"] = float(np.std(np.diff(log.command[:, 0])))  # N per T_d
    m["F_err_rms"] = float(np.sqrt(np.mean((log.F_fr_hat - log.F_fr_true) ** 2)))
    m["events"] = log.events
    m["termination"] = log.termination
    return m


def speed_mode_table(cfg: Config) -> str:
    dd = load_or_design_dynamic(cfg)
    from tsmpc.synthesis.dynamic import _premise_box

    verts = _premise_box(cfg.dynamic_box).vertices()
    lines = ["| vertex (δ, v, α) | design model | feed-forward at the reference (old) "
             "| N̄ at the measured speed (paper preset) | + speed-error feedback (default) "
             "| design closed-loop poles 1/|Re s| [s] |",
             "|---|---|---|---|---|---|"]
    lam, tau = cfg.dynamic_lmi.filter_bandwidth, cfg.lqr.speed_time_constant
    for s in speed_modes(dd.K, verts, cfg.vehicle, lam, tau):
        poles = ", ".join(f"{t:.3g}" for t in s.design_poles_tau)
        lines.append(f"| {s.vertex}: ({np.degrees(s.delta):+.0f}°, {s.v:g}, {s.alpha:+.1f}) "
                     f"| {s.design:.2f} | {s.reference_scheduled:.2f} | {s.static_gain:.2f} "
                     f"| {s.with_speed_feedback:.2f} | {poles} |")
    return "\n".join(lines)


def speed_mode_figure(cfg: Config, path: Path) -> None:
    """63 % speed-step time against speed (gains blended at δ = 0) for the four laws."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tsmpc.synthesis.dynamic import _premise_box

    dd = load_or_design_dynamic(cfg)
    pb = _premise_box(cfg.dynamic_box)
    v = np.linspace(cfg.dynamic_box.v[0], cfg.dynamic_box.v[1], 37)
    z = np.stack([np.zeros_like(v), v, np.zeros_like(v)], axis=-1)
    K = np.tensordot(pb.memberships(z), dd.K, axes=(1, 0))
    modes = speed_modes(K, z, cfg.vehicle, cfg.dynamic_lmi.filter_bandwidth, cfg.lqr.speed_time_constant)
    fig, ax = plt.subplots(figsize=(7, 4))
    for attr, label, style in (
        ("reference_scheduled", "feed-forward scheduled at the reference (exact equilibrium)", "r--"),
        ("design", "LMI design model (rolling resistance as −μ_o g/v · v)", "k:"),
        ("static_gain", "static reference gain N̄ at the measured speed (paper preset)", "b-"),
        ("with_speed_feedback", "+ speed-error feedback, τ = 0.3 s (default)", "g-"),
    ):
        ax.plot(v, [getattr(m, attr) for m in modes], style, label=label)
    ax.set_xlabel("speed v [m/s]")
    ax.set_ylabel("63 % time of a v_ref step [s]")
    ax.set_yscale("log")
    ax.axhline(cfg.rates.Tc, color="0.6", lw=0.8)
    ax.text(v[-1], cfg.rates.Tc * 1.1, "T_c (what the MPC assumes)", ha="right", fontsize=8, color="0.4")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Speed mode of the inner loop (paper's LQR weights, δ = 0)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", nargs="?", default="../shared/data/paper/planner_references_100ms.csv")
    ap.add_argument("--figure", type=Path, default=None, help="write the speed-mode figure here")
    ap.add_argument("--skip-runs", action="store_true", help="only the speed-mode table / figure")
    args = ap.parse_args()
    cfg = Config()
    print(speed_mode_table(cfg))
    if args.figure:
        speed_mode_figure(cfg, args.figure)
        print(f"wrote {args.figure}")
    if args.skip_runs:
        return
    print("\n| row | x | y | θ | v | ω | max \\|e_y\\| | soft / fallback | σ(ΔF_xR) [N] | what changed |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, c, oracle, what in ablation_rows():
        m = run_row(c, oracle, Path(args.reference))
        r = m["rmse"]
        ev = m["events"]
        rm = " | ".join(f"{r[k]:.4f}" if k in ("theta", "omega") else f"{r[k]:.3f}"
                        for k in ("x", "y", "theta", "v", "omega"))
        tail = "" if m["termination"] == "completed" else f" ({m['termination']})"
        print(f"| {label} | {rm} | {m['max_abs_lateral_m']:.2f} | {ev['mpc_soft']} / {ev['mpc_fallback']} "
              f"| {m['dF_std']:.0f} | {what} |{tail}", flush=True)
    paper = " | ".join(f"{x:g}" for x in PAPER_REF)
    print(f"| paper, Table 5 REF | {paper} | — | — | — | as published |")


if __name__ == "__main__":
    main()
