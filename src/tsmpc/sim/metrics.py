"""Metrics of a run as the paper reports them, and more (the paper's Table 5 metrics).

Tracking errors are sampled every T_c: vehicle-frame e_x, e_y, e_θ, and v_d − v, ω_d − ω, from the
*true* plant state. RMSE over the run in SI units (the paper's Table 5 columns x, y, θ, v, ω).
Beside it, :func:`paper_run_rmse` is the convention the published run's Table 5 was computed with
(the published run); metrics.json carries both (``rmse``, ``rmse_paper_run``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.errors import DataFormatError
from tsmpc.models.kinematic import pose_to_errors
from tsmpc.sim.comfort import ComfortMetrics, run_comfort
from tsmpc.sim.log import RunLog

__all__ = [
    "PAPER_RUN_POSE_DROP",
    "PAPER_RUN_ZERO_PAD",
    "PAPER_TABLE5",
    "RMSE_KEYS",
    "ControlEffort",
    "ErrorStats",
    "RunMetrics",
    "Timing",
    "TrackingMetrics",
    "compute_metrics",
    "errors_from_arrays",
    "paper_run_rmse",
    "paper_run_rmse_from_arrays",
    "run_metrics",
    "timing_stats",
    "tracking_errors",
    "tracking_metrics",
]

RMSE_KEYS = ("x", "y", "theta", "v", "omega")

#: Paper Table 5 (RMSE; x, y in m, θ in rad, v in m/s, ω in rad/s).
PAPER_TABLE5: dict[str, dict[str, float]] = {
    "FZN": {"x": 0.517, "y": 0.259, "theta": 0.017, "v": 0.258, "omega": 0.014},
    "REF": {"x": 0.501, "y": 0.238, "theta": 0.016, "v": 0.251, "omega": 0.013},
    "NL": {"x": 0.528, "y": 0.225, "theta": 0.015, "v": 0.268, "omega": 0.012},
}

#: The published run's RMSE convention (docs: Table 5 explained): the pose errors are averaged over the first
#: K − PAPER_RUN_POSE_DROP outer steps (1262 of its 1272), the v and ω errors over K entries plus
#: PAPER_RUN_ZERO_PAD zeros (1292). The counts are the published run's, applied to any run length.
PAPER_RUN_POSE_DROP = 10
PAPER_RUN_ZERO_PAD = 20


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


@dataclass(frozen=True)
class ErrorStats:
    """One statistic of the tracking errors, the paper's Table 5 columns (SI units)."""

    x: float  #: longitudinal error e_x [m]
    y: float  #: lateral error e_y [m]
    theta: float  #: heading error e_θ [rad]
    v: float  #: speed error v_d − v [m/s]
    omega: float  #: yaw-rate error ω_d − ω [rad/s]

    def as_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in RMSE_KEYS}


@dataclass(frozen=True)
class Timing:
    """Per-call wall times of a block [ms]."""

    median: float
    p95: float
    p99: float
    max: float
    mean: float

    @classmethod
    def of(cls, seconds: ArrayLike) -> Timing:
        return cls(**timing_stats(seconds))

    def as_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ControlEffort:
    """RMS of the plant inputs and of the outer loop's moves."""

    F_xR_rms_N: float
    delta_rms_rad: float
    dv_ref_rms: float
    domega_ref_rms: float


@dataclass(frozen=True)
class TrackingMetrics:
    """Tracking quality from the true state and the reference alone (any simulator's arrays)."""

    rmse: ErrorStats
    mean: ErrorStats
    max_abs_lateral_m: float


@dataclass(frozen=True)
class RunMetrics:
    """Every metric of one run (:func:`run_metrics`); ``to_dict()`` is its metrics.json entry."""

    tracking: TrackingMetrics
    mpc_ms: Timing
    mhe_ms: Timing
    lqr_ms: Timing
    mpc_iterations_mean: float
    mpc_iterations_max: int
    friction_rmse_N: float  #: F̂_fr − F_fr(true) [N] (NaN when the plant has no such force)
    slip_rmse_rad: float  #: α̂ − α
    speed_estimate_rmse: float  #: v̂ − v [m/s]
    control_effort: ControlEffort
    rmse_paper_run: ErrorStats  #: RMSE under the published run's RMSE convention
    simulated_s: float
    outer_steps: int
    inner_steps: int
    wall_s: float
    realtime_factor: float
    termination: str
    events: dict[str, int]
    comfort: ComfortMetrics | None = None  #: comfort and effort (tsmpc.sim.comfort)
    #: With the speed governor: how far behind the plan's timing the run ended [s]
    #: (:attr:`tsmpc.control.cascade.Cascade.plan_delay`); its errors are measured against the
    #: re-timed reference, so this is the time the slow-downs cost. None without a governor.
    plan_delay_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The metrics.json entry of one method (schema of issue 7, names kept stable)."""
        tr = self.tracking
        return {
            "rmse": tr.rmse.as_dict(),
            "rmse_paper_run": self.rmse_paper_run.as_dict(),
            "mean": tr.mean.as_dict(),
            "max_abs_lateral_m": tr.max_abs_lateral_m,
            "mpc_ms": self.mpc_ms.as_dict(),
            "mhe_ms": self.mhe_ms.as_dict(),
            "lqr_ms": self.lqr_ms.as_dict(),
            "mpc_iterations": {"mean": self.mpc_iterations_mean, "max": self.mpc_iterations_max},
            "friction_rmse_N": self.friction_rmse_N,
            "slip_rmse_rad": self.slip_rmse_rad,
            "speed_estimate_rmse": self.speed_estimate_rmse,
            "control_effort": {f.name: getattr(self.control_effort, f.name)
                               for f in fields(self.control_effort)},
            "simulated_s": self.simulated_s,
            "outer_steps": self.outer_steps,
            "inner_steps": self.inner_steps,
            "wall_s": self.wall_s,
            "realtime_factor": self.realtime_factor,
            "termination": self.termination,
            "events": dict(self.events),
            **({"comfort": self.comfort.as_dict()} if self.comfort is not None else {}),
            **({"plan_delay_s": self.plan_delay_s} if self.plan_delay_s is not None else {}),
        }


def _tracking(err: dict[str, NDArray[np.float64]]) -> TrackingMetrics:
    n = err["y"].size
    return TrackingMetrics(
        rmse=ErrorStats(**{k: _rms(v) for k, v in err.items()}),
        mean=ErrorStats(**{k: float(np.mean(v)) if v.size else float("nan") for k, v in err.items()}),
        max_abs_lateral_m=float(np.max(np.abs(err["y"]))) if n else float("nan"),
    )


def errors_from_arrays(state: ArrayLike, ref: ArrayLike) -> dict[str, NDArray[np.float64]]:
    """Per-sample errors like :func:`tracking_errors`, from plain arrays: the true state (K, 6)
    ``[X, Y, θ, v, α, ω]`` and the reference (K, 5) ``[x_d, y_d, θ_d, v_d, ω_d]`` at the same
    instants (every T_c)."""
    x = np.asarray(state, dtype=float).reshape(-1, 6)
    r = np.asarray(ref, dtype=float).reshape(-1, 5)
    if x.shape[0] != r.shape[0]:
        raise DataFormatError(f"state has {x.shape[0]} rows but the reference {r.shape[0]}")
    e = pose_to_errors(x[:, 0], x[:, 1], x[:, 2], r[:, 0], r[:, 1], r[:, 2]).reshape(-1, 3)
    return {"x": e[:, 0], "y": e[:, 1], "theta": e[:, 2], "v": r[:, 3] - x[:, 3],
            "omega": r[:, 4] - x[:, 5]}


def tracking_metrics(state: ArrayLike, ref: ArrayLike) -> TrackingMetrics:
    """RMSE, mean and max |e_y| from plain arrays (see :func:`errors_from_arrays`)."""
    return _tracking(errors_from_arrays(state, ref))


def tracking_errors(log: RunLog) -> dict[str, np.ndarray]:
    """Per-sample errors (K,) keyed like the RMSE table: e_x, e_y, e_θ, v_d − v, ω_d − ω."""
    return {
        "x": log.errors[:, 0],
        "y": log.errors[:, 1],
        "theta": log.errors[:, 2],
        "v": log.ref[:, 3] - log.state_outer[:, 3],
        "omega": log.ref[:, 4] - log.state_outer[:, 5],
    }


def paper_run_rmse_from_arrays(pose_errors: ArrayLike, ref_vw: ArrayLike, end_vw: ArrayLike, *,
                               pose_drop: int = PAPER_RUN_POSE_DROP,
                               zero_pad: int = PAPER_RUN_ZERO_PAD) -> ErrorStats:
    """RMSE under the published run's RMSE convention (docs: Table 5 explained).

    Args:
        pose_errors: (K, 3) e_x, e_y, e_θ at the *start* of each outer step (plant pose against
            that step's reference sample).
        ref_vw: (K, 2) the reference's [v_d, ω_d] at the start of each step.
        end_vw: (K', 2) the plant's [v, ω] at the *end* of each step, K' ≤ K (a run cut short
            may lack the last ones: the missing entries are left out, not zeroed).
        pose_drop: the pose errors of the last ``pose_drop`` steps are left out.
        zero_pad: that many zeros join the v and ω errors (they count in the mean).
    """
    e = np.asarray(pose_errors, dtype=float).reshape(-1, 3)
    r = np.asarray(ref_vw, dtype=float).reshape(-1, 2)
    x = np.asarray(end_vw, dtype=float).reshape(-1, 2)
    n = min(x.shape[0], r.shape[0])
    pose = e[: max(e.shape[0] - pose_drop, 0)]
    vw = np.vstack([r[:n] - x[:n], np.zeros((zero_pad, 2))]) if n else np.zeros((0, 2))
    return ErrorStats(x=_rms(pose[:, 0]), y=_rms(pose[:, 1]), theta=_rms(pose[:, 2]),
                      v=_rms(vw[:, 0]), omega=_rms(vw[:, 1]))


def paper_run_rmse(log: RunLog) -> ErrorStats:
    """:func:`paper_run_rmse_from_arrays` of a run log: the state at the end of outer step k is the
    logged state at the start of step k + 1, and the simulator's ``final_state`` (``log.meta``)
    after the last step."""
    end = log.state_outer[1:, [3, 5]]
    final = log.meta.get("final_state")
    if final is not None and log.n_outer:
        f = np.asarray(final, dtype=float).reshape(6)
        end = np.vstack([end, f[[3, 5]][None, :]])
    return paper_run_rmse_from_arrays(log.errors, log.ref[:, 3:5], end)


def run_metrics(log: RunLog) -> RunMetrics:
    """Every metric of one run, typed."""
    err = tracking_errors(log)
    n = log.n_outer
    du = np.diff(log.u_c, axis=0) if n > 1 else np.zeros((0, 2))
    sim_s = log.simulated_s
    return RunMetrics(
        tracking=_tracking(err),
        mpc_ms=Timing.of(log.mpc_time_s),
        mhe_ms=Timing.of(log.mhe_time_s),
        lqr_ms=Timing.of(log.lqr_time_s),
        mpc_iterations_mean=float(np.mean(log.mpc_iterations)) if n else float("nan"),
        mpc_iterations_max=int(np.max(log.mpc_iterations)) if n else 0,
        friction_rmse_N=_rms(log.F_fr_hat - log.F_fr_true),
        slip_rmse_rad=_rms(log.estimate[:, 1] - log.state[:, 4]),
        speed_estimate_rmse=_rms(log.estimate[:, 0] - log.state[:, 3]),
        control_effort=ControlEffort(
            F_xR_rms_N=_rms(log.command[:, 0]),
            delta_rms_rad=_rms(log.command[:, 1]),
            dv_ref_rms=_rms(du[:, 0]) if du.size else 0.0,
            domega_ref_rms=_rms(du[:, 1]) if du.size else 0.0,
        ),
        rmse_paper_run=paper_run_rmse(log),
        simulated_s=sim_s,
        outer_steps=n,
        inner_steps=int(log.t_inner.size),
        wall_s=log.wall_s,
        realtime_factor=sim_s / log.wall_s if log.wall_s > 0 else float("inf"),
        termination=log.termination,
        events=dict(log.events),
        comfort=run_comfort(log),
        plan_delay_s=(float(log.meta["plan_delay_s"]) if "plan_delay_s" in log.meta else None),
    )


def compute_metrics(log: RunLog) -> dict[str, Any]:
    """The metrics.json entry of one method (``run_metrics(log).to_dict()``)."""
    return run_metrics(log).to_dict()
