"""The start of a run (the paper's scenario): the outer steps it tracks, the start state on the
reference and the default plant of a :class:`~tsmpc.scenarios.Scenario`. One definition for both
ways of running it: the Python loop (:func:`tsmpc.sim.simulator.simulate`) and the compiled engine
(:mod:`tsmpc.sim.engine`) import it from here, below both.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config
from tsmpc.planning.reference import Reference
from tsmpc.scenarios import Scenario
from tsmpc.sim.plant import Plant
from tsmpc.vehicle.plant import VehiclePlant

__all__ = ["default_plant", "tracked_steps"]


def tracked_steps(ref: Reference, N: int) -> int:
    """Outer steps a run tracks: a closed lap to its end (its look-ahead wraps into the next lap,
    see :meth:`Reference.window`); an open reference keeps its last N samples as look-ahead."""
    return len(ref) if ref.closed else len(ref) - N


def _start_state(ref: Reference, initial_error: tuple[float, float]) -> NDArray[np.float64]:
    """Start pose on the reference, optionally offset laterally and in heading."""
    th0 = float(ref.theta[0])
    lat, dth = initial_error
    return np.array([ref.x[0] - lat * np.sin(th0), ref.y[0] + lat * np.cos(th0), th0 + dth,
                     max(float(ref.v[0]), 0.0), 0.0, float(ref.omega[0])])


def default_plant(cfg: Config, scenario: Scenario) -> Plant:
    """tsmpc's nonlinear plant with the scenario's plant parameters (the config's if None),
    behind the scenario's actuators if any."""
    plant = VehiclePlant(scenario.plant_vehicle or cfg.vehicle, scenario.plant_tyre or cfg.tyre,
                         cfg.rates.h)
    return plant if scenario.actuators is None else scenario.actuators.wrap(
        plant, substeps=cfg.rates.plant_per_inner)
