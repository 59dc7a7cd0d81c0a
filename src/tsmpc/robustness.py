"""Named robustness scenarios (issue 8; the paper's scenario): conditions the controllers were not designed
for, applied on top of any reference. Usable from configs, sweeps and the library::

    case = robustness_scenario("ice_patch", cfg, reference)      # a fresh scenario on a reference
    cfg, sc = apply_robustness("ice_patch", cfg, scenario)        # on top of an existing scenario

Every scenario is deterministic given the run's seed; sensor faults are small stateful objects
created per run (a run owns its fault, so runs in parallel never share state).
"""

from __future__ import annotations

from dataclasses import replace as dc_replace
from typing import NamedTuple

import numpy as np

from tsmpc.config import Config, replace
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference
from tsmpc.scenarios import DropoutFault, NaNBurstFault, PatchFriction, Scenario, SurfacePatch
from tsmpc.vehicle.actuators import Actuators, ForceLag, SteeringServo

__all__ = [
    "ROBUSTNESS_SCENARIOS",
    "DropoutFault",
    "NaNBurstFault",
    "RobustnessCase",
    "apply_robustness",
    "path_length",
    "robustness_scenario",
]

#: Scenario name → one-line description (the names accepted by sweeps and configs).
ROBUSTNESS_SCENARIOS: dict[str, str] = {
    "nominal": "no change (the comparison's conditions)",
    "ice_patch": "30 m of ice (μ = 0.1) a third of the way along; the tyre grip scales with μ(road)",
    "wet_section": "μ(road) = 0.6 from 30 % to 70 % of the path",
    "noise_x10": "every sensor-noise σ × 10",
    "sensor_dropout": "every 5 s all measurements freeze for 0.2 s (last value held)",
    "nan_bursts": "every 7 s all measurements are NaN for 50 ms",
    "mass_stiffness_mismatch": "plant mass +20 % and cornering stiffness −20 % (controllers unchanged)",
    "stiffness_mismatch": "plant cornering stiffness −20 % on both axles, mass unchanged (controllers "
    "unchanged)",
    "actuator_lag": "steering servo (50 ms lag, 0.4 rad/s) and 50 ms drive-force lag; the applied "
    "steering angle is measured and given to the MHE (the delivered force is not)",
    "offset_start": "start 2 m left of the path with a 0.2 rad (11.5°) heading error: the e_θ premise "
    "leaves its ±5° box and the outer-loop methods schedule the transient differently",
}


class RobustnessCase(NamedTuple):
    """A robustness scenario ready to simulate: ``simulate(case.config, method, case.scenario)``.

    Both parts are needed because sensor noise lives in the config (``noise.scale``) while the
    plant, surface and sensor faults live in the :class:`Scenario`. A NamedTuple so that
    ``cfg, sc = apply_robustness(...)`` unpacks it.
    """

    config: Config
    scenario: Scenario


def path_length(ref: Reference, until_s: float | None = None) -> float:
    """Length [m] of a reference's path (∑ v_d T), over its first ``until_s`` seconds if given."""
    v = ref.v if until_s is None else ref.v[: max(1, round(until_s / ref.dt))]
    return float(np.sum(np.abs(v)) * ref.dt)


def robustness_scenario(
    name: str, cfg: Config, reference: Reference, *, until_s: float | None = None
) -> RobustnessCase:
    """The named robustness scenario on ``reference`` (paper friction profile by time, healthy
    nominal plant otherwise): :func:`apply_robustness` on a fresh :class:`Scenario`."""
    case = apply_robustness(name, cfg, Scenario(name, reference), until_s=until_s)
    return RobustnessCase(case.config, dc_replace(case.scenario, name=name))


def apply_robustness(
    name: str, cfg: Config, scenario: Scenario, until_s: float | None = None
) -> RobustnessCase:
    """(config, scenario) with the named robustness condition applied (see ROBUSTNESS_SCENARIOS).

    Surface patches are placed relative to the part of the path driven in the first ``until_s``
    seconds (the whole reference if None), so shortened runs meet them too.
    Raises ValueError for an unknown name (the message lists the allowed ones).
    """
    if name not in ROBUSTNESS_SCENARIOS:
        raise ConfigError(f"unknown robustness scenario {name!r}; allowed: {', '.join(ROBUSTNESS_SCENARIOS)}")
    label = scenario.name if name == "nominal" else f"{scenario.name}+{name}"
    meta = {**scenario.meta, "robustness": name}
    sc = dc_replace(scenario, name=label, meta=meta)
    L = path_length(scenario.reference, until_s)
    if name == "ice_patch":
        start = L / 3.0
        length = min(30.0, L / 3.0)
        friction = PatchFriction(0.9, (SurfacePatch(start, start + length, 0.1, ramp_m=2.0),))
        tyre = replace(cfg.tyre, scale_grip_with_road=True)
        return RobustnessCase(cfg, dc_replace(sc, friction=friction, plant_tyre=tyre))
    if name == "wet_section":
        friction = PatchFriction(0.9, (SurfacePatch(0.3 * L, 0.7 * L, 0.6, ramp_m=10.0),))
        return RobustnessCase(cfg, dc_replace(sc, friction=friction))
    if name == "noise_x10":
        return RobustnessCase(replace(cfg, noise=replace(cfg.noise, scale=cfg.noise.scale * 10.0)), sc)
    if name == "sensor_dropout":
        return RobustnessCase(cfg, dc_replace(sc, sensor_fault=DropoutFault()))
    if name == "nan_bursts":
        return RobustnessCase(cfg, dc_replace(sc, sensor_fault=NaNBurstFault()))
    if name == "mass_stiffness_mismatch":
        base = scenario.plant_vehicle or cfg.vehicle
        veh = replace(base.with_stiffness_scaled(0.8), mass=base.mass * 1.2)
        return RobustnessCase(cfg, dc_replace(sc, plant_vehicle=veh))
    if name == "stiffness_mismatch":
        base = scenario.plant_vehicle or cfg.vehicle
        return RobustnessCase(cfg, dc_replace(sc, plant_vehicle=base.with_stiffness_scaled(0.8)))
    if name == "actuator_lag":
        act = Actuators(SteeringServo(0.05, 0.4), ForceLag(0.05))
        return RobustnessCase(cfg, dc_replace(sc, actuators=act, measured_steering=True))
    if name == "offset_start":
        return RobustnessCase(cfg, dc_replace(sc, initial_error=(2.0, 0.2)))
    return RobustnessCase(cfg, sc)
