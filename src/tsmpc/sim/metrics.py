"""Metrics of a run as the paper reports them, and more (SPEC §11).

Tracking errors are sampled every T_c: vehicle-frame e_x, e_y, e_θ, and v_d − v, ω_d − ω, from the
*true* plant state. RMSE over the run in SI units (the paper's Table 5 columns x, y, θ, v, ω).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tsmpc.sim.log import RunLog

__all__ = ["PAPER_TABLE5", "RMSE_KEYS", "compute_metrics", "timing_stats", "tracking_errors"]

RMSE_KEYS = ("x", "y", "theta", "v", "omega")

#: Paper Table 5 (RMSE; x, y in m, θ in rad, v in m/s, ω in rad/s).
PAPER_TABLE5: dict[str, dict[str, float]] = {
    "FZN": {"x": 0.517, "y": 0.259, "theta": 0.017, "v": 0.258, "omega": 0.014},
    "REF": {"x": 0.501, "y": 0.238, "theta": 0.016, "v": 0.251, "omega": 0.013},
    "NL": {"x": 0.528, "y": 0.225, "theta": 0.015, "v": 0.268, "omega": 0.012},
}


def _rms(a: ArrayLike) -> float:
    a = np.asarray(a, dtype=float)
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


def timing_stats(seconds: ArrayLike) -> dict[str, float]:
    """median / p95 / p99 / max / mean of per-call times, in milliseconds."""
    ms = np.asarray(seconds, dtype=float) * 1e3
    if ms.size == 0:
        return {k: float("nan") for k in ("median", "p95", "p99", "max", "mean")}
    return {
        "median": float(np.median(ms)),
        "p95": float(np.percentile(ms, 95)),
        "p99": float(np.percentile(ms, 99)),
        "max": float(ms.max()),
        "mean": float(ms.mean()),
    }


def tracking_errors(log: RunLog) -> dict[str, np.ndarray]:
    """Per-sample errors (K,) keyed like the RMSE table: e_x, e_y, e_θ, v_d − v, ω_d − ω."""
    return {
        "x": log.errors[:, 0],
        "y": log.errors[:, 1],
        "theta": log.errors[:, 2],
        "v": log.ref[:, 3] - log.state_outer[:, 3],
        "omega": log.ref[:, 4] - log.state_outer[:, 5],
    }


def compute_metrics(log: RunLog) -> dict[str, Any]:
    """The metrics.json entry of one method (schema of issue 7, names kept stable)."""
    err = tracking_errors(log)
    n = log.n_outer
    du = np.diff(log.u_c, axis=0) if n > 1 else np.zeros((0, 2))
    sim_s = log.simulated_s
    return {
        "rmse": {k: _rms(v) for k, v in err.items()},
        "mean": {k: float(np.mean(v)) if v.size else float("nan") for k, v in err.items()},
        "max_abs_lateral_m": float(np.max(np.abs(err["y"]))) if n else float("nan"),
        "mpc_ms": timing_stats(log.mpc_time_s),
        "mhe_ms": timing_stats(log.mhe_time_s),
        "lqr_ms": timing_stats(log.lqr_time_s),
        "mpc_iterations": {"mean": float(np.mean(log.mpc_iterations)) if n else float("nan"),
                           "max": int(np.max(log.mpc_iterations)) if n else 0},
        "friction_rmse_N": _rms(log.F_fr_hat - log.F_fr_true),
        "slip_rmse_rad": _rms(log.estimate[:, 1] - log.state[:, 4]),
        "speed_estimate_rmse": _rms(log.estimate[:, 0] - log.state[:, 3]),
        "control_effort": {
            "F_xR_rms_N": _rms(log.command[:, 0]),
            "delta_rms_rad": _rms(log.command[:, 1]),
            "dv_ref_rms": _rms(du[:, 0]) if du.size else 0.0,
            "domega_ref_rms": _rms(du[:, 1]) if du.size else 0.0,
        },
        "simulated_s": sim_s,
        "outer_steps": n,
        "inner_steps": int(log.t_inner.size),
        "wall_s": log.wall_s,
        "realtime_factor": sim_s / log.wall_s if log.wall_s > 0 else float("inf"),
        "termination": log.termination,
        "events": dict(log.events),
    }
