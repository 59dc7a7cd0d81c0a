"""The documented search behind the baselines' defaults (issue 26; tsmpc.config.BaselineSettings).

    python examples/tune_baselines.py [--out tuning.md]

Tuned on the built-in circuit only (tsmpc.planning.circuit: its waypoints) — never on the
evaluation cases of the README's baseline table (the paper reference, the race tracks, the
mismatch cases). Each candidate runs the whole cascade (same inner loop, MHE, plant, noise seed)
on three tuning runs:

* ``nominal``: the built-in circuit (≤ 14.7 m/s), from the path;
* ``offset``: its first 40 s from 2 m / 0.2 rad off the path (the ``offset_start`` scenario);
* ``fast``: the same waypoints with their speed caps and yaw-rate limit × 1.5, planned at
  v_max = 22 m/s, a_lat = 5 m/s² (the evaluation tracks' planner limits, not their geometry):
  up to 22 m/s, a law tuned only at ≤ 14.7 m/s would be tuned outside the speeds it is judged at.
  The scheduling boxes are widened and the designs re-certified as ``tsmpc compare`` does.

Objective (smaller is better), each term relative to the TS-MPC (REF, default config, not tuned)
on the same run, so that the terms weigh alike and J = 6 means "as good as REF overall"::

    J_lat = Σ_runs RMSE_y / RMSE_y(REF) + RMS lateral jerk / RMS lateral jerk(REF)
    J_lon = Σ_runs RMSE_x / RMSE_x(REF) + RMS longitudinal jerk / RMS longitudinal jerk(REF)

A run that diverges scores +inf. A coordinate search, repeated until a pass changes nothing:
(1) the pure pursuit's look-ahead (time × speed, floor) and (2) Stanley's gain, softening speed,
heading gain and curvature feed-forward by J_lat (the first pass with the along-track gain at 0.5 1/s);
(3) the along-track gain of the speed channel by J_lon, with the tuned pure pursuit (the channel
is the same law for both geometric methods). J_lon flattens at high gains while the longitudinal
jerk keeps growing, so the smallest gain within 5 % of the minimum is taken. The pure pursuit's
longest look-ahead (40 m) is not searched: it only caps L_d above 67 m/s. The kinematic LQR (the
LMI design's gains) and the LTV-MPC (the TS-MPC's weights) are not tuned: their gains are fixed by
what they are. ``TSMPC_EXAMPLE_STEPS`` shortens every run and every grid to its first two values
(the CI smoke run).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import Any

from tsmpc.config import Config, Method, PlannerSettings, replace
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.planning.reference import Reference
from tsmpc.robustness import robustness_scenario
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import simulate
from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

#: The search grids (documented in the output).
PP_GRID = {"lookahead_time_s": (0.3, 0.45, 0.6, 0.8, 1.0), "lookahead_min_m": (3.0, 5.0, 8.0)}
STANLEY_GRID = {"gain": (1.0, 2.0, 3.0), "softening_speed": (2.0, 4.0, 8.0, 16.0),
                "heading_gain": (0.2, 0.3, 0.4, 1.0), "curvature_feedforward": (True, False)}
ALONG_TRACK_GRID = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0)
OFFSET_S = 40.0
#: Speed caps and yaw-rate limit of the built-in circuit × this, for the ``fast`` run.
FAST_SCALE = 1.5
#: J_lon flattens at high along-track gains while the longitudinal jerk keeps growing: the smallest
#: gain within this fraction of the minimum is taken (the gentler law among near-equals).
FLAT = 0.05
#: The speed channel's gain during the first lateral search (before it is tuned) [1/s].
PRIOR_ALONG_TRACK_GAIN = 0.5
#: Passes of the coordinate search (lateral laws, then speed channel) at most.
MAX_PASSES = 3


def fast_circuit(cfg: Config) -> Reference:
    """The built-in circuit's waypoints at FAST_SCALE × its speed caps, planned at 22 m/s, 5 m/s²."""
    from tsmpc.planning.circuit import CIRCUIT_OMEGA_MAX, CIRCUIT_WAYPOINTS, TAIL_S
    from tsmpc.planning.planner import plan_path

    return plan_path(CIRCUIT_WAYPOINTS[:, :2], PlannerSettings(v_max=22.0, a_lat_max=5.0),
                     dt=cfg.rates.Tc, tail_s=TAIL_S, omega_max=CIRCUIT_OMEGA_MAX * FAST_SCALE,
                     v_cap=CIRCUIT_WAYPOINTS[:, 2] * FAST_SCALE)


def tuning_runs(cfg: Config) -> dict[str, tuple[Config, Any, int | None, tuple]]:
    """(config, scenario, max_steps, designs) of the three tuning runs."""
    from tsmpc.envelope import fit_envelope
    from tsmpc.scenarios import paper_friction_profile
    from tsmpc.sim.simulator import Scenario

    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None
    nominal = load_scenario(cfg)
    off = robustness_scenario("offset_start", cfg, builtin_circuit(dt=cfg.rates.Tc), until_s=OFFSET_S)
    off_steps = round(OFFSET_S / cfg.rates.Tc)
    fast = Scenario("fast", fast_circuit(cfg), paper_friction_profile())
    fast_cfg = fit_envelope(cfg, fast.reference).config

    def designs(c: Config) -> tuple:
        return load_or_design_kinematic(c), load_or_design_dynamic(c)

    return {"nominal": (cfg, nominal, steps, designs(cfg)),
            "offset": (off.config, dc_replace(off.scenario, name="offset"),
                       min(off_steps, steps) if steps else off_steps, designs(off.config)),
            "fast": (fast_cfg, fast, steps, designs(fast_cfg))}


def score(cfg: Config, method: Method, runs: dict) -> dict[str, dict[str, float]]:
    """RMSE_x, RMSE_y and RMS jerks of ``method`` with ``cfg``'s baseline settings on each run."""
    out = {}
    for name, (rc, sc, steps, designs) in runs.items():
        c = replace(rc, baselines=cfg.baselines)
        log = simulate(c, method, sc, kinematic_design=designs[0], dynamic_design=designs[1],
                       max_steps=steps)
        m = compute_metrics(log)
        ok = m["termination"] == "completed"
        inf = float("inf")
        out[name] = {"x": m["rmse"]["x"] if ok else inf, "y": m["rmse"]["y"] if ok else inf,
                     "jy": m["comfort"]["lat_jerk_rms"] if ok else inf,
                     "jx": m["comfort"]["lon_jerk_rms"] if ok else inf}
    return out


def objective(s: dict, ref: dict, keys: tuple[str, str]) -> float:
    return sum(s[r][k] / max(ref[r][k], 1e-12) for r in s for k in keys)


def _fmt(v: float) -> str:
    return "diverged" if math.isinf(v) else f"{v:.3f}"


def _head(runs: dict, what: tuple[str, str]) -> str:
    return " | ".join(f"{w} {r}" for w in what for r in runs)


def _cells(s: dict, keys: tuple[str, str]) -> str:
    return " | ".join(_fmt(s[r][k]) for k in keys for r in s)


def _smoke(values: tuple) -> tuple:
    """The grid itself, or its first two values in the CI smoke run (TSMPC_EXAMPLE_STEPS set)."""
    return values[:2] if os.environ.get("TSMPC_EXAMPLE_STEPS") else values


def search(method: Method, section: str, grid: dict[str, tuple], base: Config, runs: dict,
           ref: dict) -> tuple[dict, list[str]]:
    """Grid search of one geometric law's lateral parameters by J_lat; (best, Markdown lines)."""
    rows, best, best_j = [], {}, float("inf")
    for values in itertools.product(*(_smoke(v) for v in grid.values())):
        params = dict(zip(grid, values, strict=True))
        sub = replace(getattr(base.baselines, section), **params)
        cfg = replace(base, baselines=replace(base.baselines, **{section: sub}))
        s = score(cfg, method, runs)
        j = objective(s, ref, ("y", "jy"))
        rows.append(f"| {', '.join(f'{k}={v}' for k, v in params.items())} | "
                    + _cells(s, ("y", "jy")) + f" | {_fmt(j)} |")
        if j < best_j:
            best, best_j = params, j
    head = [f"#### {method.value}: J_lat over {len(rows)} candidates "
            f"(along_track_gain = {base.baselines.along_track_gain})", "",
            "| parameters | " + _head(runs, ("RMSE_y [m]", "RMS jerk_y [m/s³]")) + " | J_lat |",
            "|---|" + "---|" * (2 * len(runs) + 1)]
    return best, [*head, *rows, "", f"best: {best} (J_lat = {best_j:.3f})", ""]


def search_along_track(base: Config, runs: dict, ref: dict) -> tuple[float, list[str]]:
    """The along-track gain by J_lon with ``base``'s pure pursuit; (gain, Markdown lines)."""
    lon = ["#### along-track gain of the speed channel (pure pursuit "
           f"{base.baselines.pure_pursuit.model_dump()}): J_lon", "",
           "| gain [1/s] | " + _head(runs, ("RMSE_x [m]", "RMS jerk_x [m/s³]")) + " | J_lon |",
           "|---|" + "---|" * (2 * len(runs) + 1)]
    scores = []
    for g in _smoke(ALONG_TRACK_GRID):
        cfg = replace(base, baselines=replace(base.baselines, along_track_gain=g))
        s = score(cfg, Method.PURE_PURSUIT, runs)
        j = objective(s, ref, ("x", "jx"))
        scores.append((g, j))
        lon.append(f"| {g} | " + _cells(s, ("x", "jx")) + f" | {_fmt(j)} |")
    j_min = min(j for _, j in scores)
    gain, j = next((g, j) for g, j in scores if j <= (1.0 + FLAT) * j_min)
    lon += ["", f"best: along_track_gain = {gain} (J_lon = {j:.3f}; the smallest gain within "
            f"{FLAT:.0%} of the minimum {j_min:.3f})", ""]
    return gain, lon


def tuning_text() -> str:
    """Run the search; return its tables and the chosen settings (Markdown; the docs generator's
    section ``baseline-tuning``)."""
    cfg0 = Config()
    runs = tuning_runs(cfg0)
    ref = score(cfg0, Method.REF, runs)
    lines = ["REF (normalisation, default config): " + ", ".join(
        f"{r}: RMSE_y {v['y']:.4f} m, RMSE_x {v['x']:.4f} m, RMS jerk_y {v['jy']:.3f}, jerk_x {v['jx']:.3f}"
        for r, v in ref.items()), ""]
    # Coordinate search from the prior (BaselineSettings' fields before tuning), independent of
    # the current defaults: lateral laws, then the speed channel, repeated until nothing changes.
    bs = replace(cfg0.baselines, along_track_gain=PRIOR_ALONG_TRACK_GAIN)
    chosen = None
    for n in range(1, MAX_PASSES + 1):
        base = replace(cfg0, baselines=bs)
        pp_best, pp_lines = search(Method.PURE_PURSUIT, "pure_pursuit", PP_GRID, base, runs, ref)
        st_best, st_lines = search(Method.STANLEY, "stanley", STANLEY_GRID, base, runs, ref)
        bs = replace(bs, pure_pursuit=replace(bs.pure_pursuit, **pp_best),
                     stanley=replace(bs.stanley, **st_best))
        gain, lon = search_along_track(replace(cfg0, baselines=bs), runs, ref)
        bs = replace(bs, along_track_gain=gain)
        lines += [f"### pass {n}", "", *pp_lines, *st_lines, *lon]
        if (pp_best, st_best, gain) == chosen:
            break
        chosen = (pp_best, st_best, gain)
    lines.append("Tuned defaults (tsmpc.config.BaselineSettings): "
                 f"pure_pursuit {pp_best}, stanley {st_best}, along_track_gain {gain}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="also write the tables (Markdown) here")
    args = ap.parse_args()
    text = tuning_text()
    print(text)
    if args.out:
        args.out.write_text(text + "\n", encoding="utf-8")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
