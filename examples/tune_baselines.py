"""The documented search behind the baselines' defaults (issue 26; tsmpc.config.BaselineSettings).

    python examples/tune_baselines.py [--out tuning.md]

Tuned on the built-in circuit only (tsmpc.planning.circuit.builtin_circuit, 1.3 km, ≤ 14.7 m/s) —
never on the evaluation cases of the README's baseline table (the paper reference, the race
tracks, the mismatch cases). Each candidate runs the whole cascade (same inner loop, MHE, plant,
noise seed) on two tuning runs:

* ``nominal``: the whole circuit from the path;
* ``offset``: its first 40 s from 2 m / 0.2 rad off the path (the ``offset_start`` scenario).

Objective (smaller is better), each term relative to the TS-MPC (REF, default config, not tuned)
on the same run, so that the terms weigh alike and J = 4 means "as good as REF overall"::

    J_lat = Σ_runs RMSE_y / RMSE_y(REF) + RMS lateral jerk / RMS lateral jerk(REF)
    J_lon = Σ_runs RMSE_x / RMSE_x(REF) + RMS longitudinal jerk / RMS longitudinal jerk(REF)

A run that diverges scores +inf. A coordinate search, repeated until a pass changes nothing:
(1) the pure pursuit's look-ahead (time × speed, floor) and (2) Stanley's gain, softening speed
and curvature feed-forward by J_lat (the first pass with the along-track gain at 0.5 1/s);
(3) the along-track gain of the speed channel by J_lon, with the tuned pure pursuit (the channel
is the same law for both geometric methods). J_lon flattens at high gains while the longitudinal
jerk keeps growing, so the smallest gain within 5 % of the minimum is taken. The pure pursuit's
longest look-ahead (40 m) is not searched: it only caps L_d above 67 m/s. The kinematic LQR (the
LMI design's gains) and the LTV-MPC (the TS-MPC's weights) are not tuned: their gains are fixed by
what they are. ``TSMPC_EXAMPLE_STEPS`` shortens every run (the CI smoke run).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import Any

from tsmpc.config import Config, Method, replace
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.robustness import robustness_scenario
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import simulate
from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

#: The search grids (documented in the output).
PP_GRID = {"lookahead_time_s": (0.3, 0.45, 0.6, 0.8, 1.0), "lookahead_min_m": (3.0, 5.0, 8.0)}
STANLEY_GRID = {"gain": (1.0, 2.0, 3.0, 5.0, 8.0), "softening_speed": (2.0, 4.0, 8.0, 16.0, 32.0),
                "curvature_feedforward": (True, False)}
ALONG_TRACK_GRID = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0)
OFFSET_S = 40.0
#: J_lon flattens at high along-track gains while the longitudinal jerk keeps growing: the smallest
#: gain within this fraction of the minimum is taken (the gentler law among near-equals).
FLAT = 0.05
#: The speed channel's gain during the first lateral search (before it is tuned) [1/s].
PRIOR_ALONG_TRACK_GAIN = 0.5
#: Passes of the coordinate search (lateral laws, then speed channel) at most.
MAX_PASSES = 3


def tuning_runs(cfg: Config) -> dict[str, tuple[Config, Any, int | None]]:
    """(config, scenario, max_steps) of the two tuning runs on the built-in circuit."""
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None
    nominal = load_scenario(cfg)
    off = robustness_scenario("offset_start", cfg, builtin_circuit(dt=cfg.rates.Tc), until_s=OFFSET_S)
    off_steps = round(OFFSET_S / cfg.rates.Tc)
    return {"nominal": (cfg, nominal, steps),
            "offset": (off.config, dc_replace(off.scenario, name="offset"),
                       min(off_steps, steps) if steps else off_steps)}


def score(cfg: Config, method: Method, runs: dict, designs: tuple) -> dict[str, dict[str, float]]:
    """RMSE_x, RMSE_y and RMS jerks of ``method`` with ``cfg``'s baseline settings on each run."""
    out = {}
    for name, (rc, sc, steps) in runs.items():
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
    return sum(s[r][k] / ref[r][k] for r in s for k in keys)


def _fmt(v: float) -> str:
    return "diverged" if math.isinf(v) else f"{v:.3f}"


def search(method: Method, section: str, grid: dict[str, tuple], base: Config, runs: dict, ref: dict,
           designs: tuple) -> tuple[dict, list[str]]:
    """Grid search of one geometric law's lateral parameters by J_lat; (best, Markdown lines)."""
    rows, best, best_j = [], {}, float("inf")
    for values in itertools.product(*grid.values()):
        params = dict(zip(grid, values, strict=True))
        sub = replace(getattr(base.baselines, section), **params)
        cfg = replace(base, baselines=replace(base.baselines, **{section: sub}))
        s = score(cfg, method, runs, designs)
        j = objective(s, ref, ("y", "jy"))
        rows.append(f"| {', '.join(f'{k}={v}' for k, v in params.items())} | "
                    f"{_fmt(s['nominal']['y'])} | {_fmt(s['offset']['y'])} | {_fmt(s['nominal']['jy'])} "
                    f"| {_fmt(s['offset']['jy'])} | {_fmt(j)} |")
        if j < best_j:
            best, best_j = params, j
    head = [f"#### {method.value}: J_lat over {len(rows)} candidates "
            f"(along_track_gain = {base.baselines.along_track_gain})", "",
            "| parameters | RMSE_y nominal [m] | RMSE_y offset [m] | RMS jerk_y nominal | "
            "RMS jerk_y offset | J_lat |", "|---|---|---|---|---|---|"]
    return best, [*head, *rows, "", f"best: {best} (J_lat = {best_j:.3f})", ""]


def search_along_track(base: Config, runs: dict, ref: dict, designs: tuple) -> tuple[float, list[str]]:
    """The along-track gain by J_lon with ``base``'s pure pursuit; (gain, Markdown lines)."""
    lon = ["#### along-track gain of the speed channel (pure pursuit "
           f"{base.baselines.pure_pursuit.model_dump()}): J_lon", "",
           "| gain [1/s] | RMSE_x nominal [m] | RMSE_x offset [m] | RMS jerk_x nominal | RMS jerk_x offset "
           "| J_lon |", "|---|---|---|---|---|---|"]
    scores = []
    for g in ALONG_TRACK_GRID:
        cfg = replace(base, baselines=replace(base.baselines, along_track_gain=g))
        s = score(cfg, Method.PURE_PURSUIT, runs, designs)
        j = objective(s, ref, ("x", "jx"))
        scores.append((g, j))
        lon.append(f"| {g} | {_fmt(s['nominal']['x'])} | {_fmt(s['offset']['x'])} "
                   f"| {_fmt(s['nominal']['jx'])} | {_fmt(s['offset']['jx'])} | {_fmt(j)} |")
    j_min = min(j for _, j in scores)
    gain, j = next((g, j) for g, j in scores if j <= (1.0 + FLAT) * j_min)
    lon += ["", f"best: along_track_gain = {gain} (J_lon = {j:.3f}; the smallest gain within "
            f"{FLAT:.0%} of the minimum {j_min:.3f})", ""]
    return gain, lon


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="also write the tables (Markdown) here")
    args = ap.parse_args()
    cfg0 = Config()
    designs = (load_or_design_kinematic(cfg0), load_or_design_dynamic(cfg0))
    runs = tuning_runs(cfg0)
    ref = score(cfg0, Method.REF, runs, designs)
    lines = ["REF (normalisation, default config): " + ", ".join(
        f"{r}: RMSE_y {v['y']:.4f} m, RMSE_x {v['x']:.4f} m, RMS jerk_y {v['jy']:.3f}, jerk_x {v['jx']:.3f}"
        for r, v in ref.items()), ""]
    # Coordinate search from the prior (BaselineSettings' fields before tuning), independent of
    # the current defaults: lateral laws, then the speed channel, repeated until nothing changes.
    bs = replace(cfg0.baselines, along_track_gain=PRIOR_ALONG_TRACK_GAIN)
    chosen = None
    for n in range(1, MAX_PASSES + 1):
        base = replace(cfg0, baselines=bs)
        pp_best, pp_lines = search(Method.PURE_PURSUIT, "pure_pursuit", PP_GRID, base, runs, ref, designs)
        st_best, st_lines = search(Method.STANLEY, "stanley", STANLEY_GRID, base, runs, ref, designs)
        bs = replace(bs, pure_pursuit=replace(bs.pure_pursuit, **pp_best),
                     stanley=replace(bs.stanley, **st_best))
        gain, lon = search_along_track(replace(cfg0, baselines=bs), runs, ref, designs)
        bs = replace(bs, along_track_gain=gain)
        lines += [f"### pass {n}", "", *pp_lines, *st_lines, *lon]
        if (pp_best, st_best, gain) == chosen:
            break
        chosen = (pp_best, st_best, gain)
    lines.append("Tuned defaults (tsmpc.config.BaselineSettings): "
                 f"pure_pursuit {pp_best}, stanley {st_best}, along_track_gain {gain}")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n", encoding="utf-8")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
