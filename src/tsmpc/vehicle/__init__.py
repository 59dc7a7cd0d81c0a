"""The vehicle a controller drives: tsmpc's nonlinear single-track plant with its
tyre models, the actuator dynamics in front of it, and CommonRoad's vehicle models (the
``[commonroad]`` extra, loaded on first use).

What users import is re-exported here, by name (``from tsmpc.vehicle import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.vehicle.actuators import ActuatedPlant, Actuators, ForceLag, SteeringServo
    from tsmpc.vehicle.commonroad import CommonRoadPlant, commonroad_config
    from tsmpc.vehicle.plant import INPUT_NAMES, STATE_NAMES, VehiclePlant
    from tsmpc.vehicle.single_track import PlantParams, plant_params, plant_rhs

#: public name → the submodule that defines it
_EXPORTS = {
    "ActuatedPlant": "actuators",
    "Actuators": "actuators",
    "CommonRoadPlant": "commonroad",
    "ForceLag": "actuators",
    "INPUT_NAMES": "plant",
    "PlantParams": "single_track",
    "STATE_NAMES": "plant",
    "SteeringServo": "actuators",
    "VehiclePlant": "plant",
    "commonroad_config": "commonroad",
    "plant_params": "single_track",
    "plant_rhs": "single_track",
}

__all__ = [
    "INPUT_NAMES", "STATE_NAMES", "ActuatedPlant", "Actuators", "CommonRoadPlant", "ForceLag",
    "PlantParams", "SteeringServo", "VehiclePlant", "commonroad_config", "plant_params", "plant_rhs",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
