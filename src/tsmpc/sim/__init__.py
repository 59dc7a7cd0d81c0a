"""Closed-loop simulation and its results: :func:`simulate` drives a plant with a
controller over a reference under a scenario's conditions, :func:`prepare` builds the run of
``tsmpc compare`` / ``tsmpc run`` from a config, and the metrics, logs and run folders follow.

What users import is re-exported here, by name (``from tsmpc.sim import …``); the submodules
load on first use. The modules not re-exported are implementation (the run engine and the batch
bridges).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.sim.batch import simulate_batch
    from tsmpc.sim.comfort import ComfortMetrics, comfort_metrics
    from tsmpc.sim.compare import CompareResult, load_scenario
    from tsmpc.sim.experiment import Experiment, prepare
    from tsmpc.sim.log import RunLog
    from tsmpc.sim.metrics import RunMetrics, TrackingMetrics, compute_metrics, paper_run_rmse
    from tsmpc.sim.plant import Plant
    from tsmpc.sim.run_dir import RunDir, load_run
    from tsmpc.sim.simulator import Method, Scenario, default_plant, simulate

#: public name → the submodule that defines it
_EXPORTS = {
    "ComfortMetrics": "comfort",
    "CompareResult": "compare",
    "Experiment": "experiment",
    "Method": "simulator",
    "Plant": "plant",
    "RunDir": "run_dir",
    "RunLog": "log",
    "RunMetrics": "metrics",
    "Scenario": "simulator",
    "TrackingMetrics": "metrics",
    "comfort_metrics": "comfort",
    "compute_metrics": "metrics",
    "default_plant": "simulator",
    "load_run": "run_dir",
    "load_scenario": "compare",
    "paper_run_rmse": "metrics",
    "prepare": "experiment",
    "simulate": "simulator",
    "simulate_batch": "batch",
}

__all__ = [
    "ComfortMetrics", "CompareResult", "Experiment", "Method", "Plant", "RunDir", "RunLog", "RunMetrics",
    "Scenario", "TrackingMetrics", "comfort_metrics", "compute_metrics", "default_plant", "load_run",
    "load_scenario", "paper_run_rmse", "prepare", "simulate", "simulate_batch",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
