"""The conditions a run meets, from the ``[scenario]`` section of a config (issue 21; the schema is
:class:`~tsmpc.config.ScenarioSettings`): the plant's parameters, μ(road) events, sensor faults
and actuators, written in TOML or on the command line (``--set scenario.plant.mass_scale=1.2``)
without Python::

    [scenario.plant]
    mass_scale = 1.2                 # a loaded car
    cornering_rear_scale = 0.7       # other tyres at the back
    [scenario.sensors]
    dropout_probability = 0.05       # 5 % of the samples lost, at random (seeded)
    v_bias = 0.2                     # the speed sensor reads 0.2 m/s high
    [[scenario.friction]]
    at_corner = 2                    # μ(road) drops to 0.3 at the apex of the second corner
    mu = 0.3

:func:`apply_conditions` turns them into the run's :class:`~tsmpc.scenarios.Scenario` (and,
for ``oracle_tuned``, the controllers' config). Everything is deterministic given the run's seed;
the stateful parts (sensor faults) restart when a run starts again at t = 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace as dc_replace

import numpy as np

from tsmpc.config import (
    Config,
    FrictionEvent,
    KnownPart,
    ScenarioSettings,
    SensorFaults,
    TyreParams,
    VehicleParams,
    replace,
)
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference
from tsmpc.robustness import RobustnessCase
from tsmpc.scenarios import ConstantFriction, EventFriction, ResolvedEvent, Scenario, SensorModel

__all__ = [
    "EventFriction",
    "ResolvedEvent",
    "SensorModel",
    "apply_conditions",
    "controller_vehicle",
    "corner_apexes",
    "plant_tyre",
    "plant_vehicle",
    "resolve_events",
    "told",
]


def plant_vehicle(cfg: Config, base: VehicleParams | None = None) -> VehicleParams:
    """The plant's vehicle: ``base`` (default: the config's) with ``cfg.scenario.plant``'s scales.
    Raises :class:`ConfigError` when the CoG would leave the wheelbase."""
    p = cfg.scenario.plant
    v = base or cfg.vehicle
    a = v.a * p.cog_to_front_scale
    b = v.a + v.b - a
    if b < 0.05 * (v.a + v.b):
        raise ConfigError(f"scenario.plant.cog_to_front_scale = {p.cog_to_front_scale:g}: the CoG "
                          f"would sit {a:.3f} m behind the front axle of a {v.a + v.b:.3f} m wheelbase")
    return replace(v, mass=v.mass * p.mass_scale, inertia=v.inertia * p.inertia_scale, a=a, b=b,
                   cornering_stiffness_front=v.C_f * p.cornering_front_scale,
                   cornering_stiffness_rear=v.C_r * p.cornering_rear_scale)


#: Each part of the vehicle the controllers can be told (``scenario.known``): (its plant scales,
#: its vehicle fields).
_PARTS: dict[KnownPart, tuple[tuple[str, ...], tuple[str, ...]]] = {
    KnownPart.MASS: (("mass_scale",), ("mass",)),
    KnownPart.INERTIA: (("inertia_scale",), ("inertia",)),
    KnownPart.CORNERING_STIFFNESS: (("cornering_front_scale", "cornering_rear_scale"),
                                    ("cornering_stiffness_front", "cornering_stiffness_rear")),
    KnownPart.COG: (("cog_to_front_scale",), ("a", "b"))}


def told(sc: ScenarioSettings) -> frozenset[KnownPart]:
    """What the controllers are told of the plant: ``sc.known``, everything with ``oracle_tuned``."""
    return frozenset(KnownPart) if sc.oracle_tuned else frozenset(sc.known)


def controller_vehicle(cfg: Config, plant: VehicleParams | None = None) -> VehicleParams:
    """The controllers' vehicle: the config's, with the parts ``cfg.scenario`` tells them
    (:func:`told`) taken from the ``plant``'s (default: :func:`plant_vehicle`); the plant's whole
    with ``oracle_tuned``."""
    known = told(cfg.scenario)
    if not known & _PARTS.keys():
        return cfg.vehicle
    p = plant or plant_vehicle(cfg)
    if cfg.scenario.oracle_tuned:
        return p
    return replace(cfg.vehicle, **{f: getattr(p, f) for part, (_, fields) in _PARTS.items() if part in known
                                   for f in fields})


def plant_tyre(cfg: Config, base: TyreParams | None = None) -> TyreParams:
    """The plant's tyre: ``base`` (default: the config's) with ``cfg.scenario.plant``'s grip."""
    p = cfg.scenario.plant
    t = base or cfg.tyre
    changes: dict[str, object] = {}
    if p.mu_tyre is not None:
        changes["mu_tyre"] = p.mu_tyre
    if p.combined_slip:
        changes["combined_slip"] = True
    if p.grip_scales_with_road:
        changes["scale_grip_with_road"] = True
    return replace(t, **changes) if changes else t


def corner_apexes(ref: Reference) -> list[int]:
    """Sample indices of the reference's corner apexes: each run of samples with |ω_d| above half
    the largest |ω_d|, at its largest |ω_d| (the ``at_corner`` trigger)."""
    w = np.abs(np.asarray(ref.omega, dtype=float))
    if w.size == 0 or not np.max(w) > 0.0:
        return []
    inside = w > 0.5 * float(np.max(w))
    out, k, n = [], 0, w.size
    while k < n:
        if inside[k]:
            j = k
            while j < n and inside[j]:
                j += 1
            out.append(k + int(np.argmax(w[k:j])))
            k = j
        else:
            k += 1
    return out


def resolve_events(events: Sequence[FrictionEvent], ref: Reference) -> tuple[ResolvedEvent, ...]:
    """The events on their axes; ``at_corner`` becomes the apex's time since the reference's start.
    Raises :class:`ConfigError` for a corner the reference does not have."""
    out = []
    apexes: list[int] | None = None
    for i, e in enumerate(events):
        if e.at_m is not None:
            length = math.inf if e.length_m is None else e.length_m
            out.append(ResolvedEvent(False, e.at_m, e.ramp_m or 0.0, e.at_m + length, e.mu))
            continue
        if e.at_corner is not None:
            apexes = corner_apexes(ref) if apexes is None else apexes
            if e.at_corner > len(apexes):
                raise ConfigError(f"scenario.friction[{i}].at_corner = {e.at_corner}: the reference "
                                  f"has {len(apexes)} corner(s)")
            start = apexes[e.at_corner - 1] * ref.dt
        else:
            assert e.at_s is not None
            start = e.at_s
        dur = math.inf if e.duration_s is None else e.duration_s
        out.append(ResolvedEvent(True, start, e.ramp_s or 0.0, start + dur, e.mu))
    return tuple(out)


def _budget_mu(scenario: Scenario, cfg: Config, duration: float) -> float:
    """The highest μ(road) of the base profile (sampled every T_c; events aside): the largest road
    resistance, and the grip the planner plans with (it plans for the dry road, not the ice)."""
    if cfg.scenario.base_mu is not None:
        return cfg.scenario.base_mu
    ts = np.arange(0.0, max(duration, cfg.rates.Tc), cfg.rates.Tc)
    return float(max(scenario.friction.mu(float(t), 0.0) for t in ts))


def apply_conditions(cfg: Config, scenario: Scenario) -> RobustnessCase:
    """(config, scenario) with ``cfg.scenario`` applied; unchanged when it is the default.

    Plant scales and tyre options act on the scenario's plant (on top of a plant the scenario
    already changed); friction events on its μ(road) profile (``base_mu`` replaces the profile);
    sensor faults after its own; actuators in front of the plant. ``oracle_tuned`` gives the
    controllers the plant's vehicle; ``replan_for_force_budget`` re-times the reference for it
    (:func:`tsmpc.planning.retime.retime_for_force_budget`). Raises :class:`ConfigError` for
    conditions that cannot be applied (a corner the reference does not have, a CoG off the car).
    """
    sc: ScenarioSettings = cfg.scenario
    if sc == ScenarioSettings():
        return RobustnessCase(cfg, scenario)
    changes: dict[str, object] = {}
    veh = plant_vehicle(cfg, scenario.plant_vehicle)
    if veh != (scenario.plant_vehicle or cfg.vehicle):
        changes["plant_vehicle"] = veh
    tyre = plant_tyre(cfg, scenario.plant_tyre)
    if tyre != (scenario.plant_tyre or cfg.tyre):
        changes["plant_tyre"] = tyre
    ref = scenario.reference
    friction = scenario.friction if sc.base_mu is None else ConstantFriction(sc.base_mu)
    if sc.replan_for_force_budget:
        from tsmpc.planning.retime import retime_for_force_budget

        mu = _budget_mu(dc_replace(scenario, friction=friction), cfg, ref.duration)
        ref = retime_for_force_budget(ref, veh, cfg.lqr, mu, tyre=tyre,  # the actuators' limits
                                      limits_vehicle=cfg.vehicle)
        changes["reference"] = ref
    if sc.friction:
        friction = EventFriction(friction, resolve_events(sc.friction, ref))
    if friction is not scenario.friction:
        changes["friction"] = friction
    faults = sc.sensors
    known = told(sc)
    if KnownPart.SENSOR_BIASES in known:  # calibrated sensors: known offsets and drifts removed
        faults = replace(faults, v_bias=0.0, omega_bias=0.0, theta_bias=0.0, v_drift=0.0,
                         omega_drift=0.0, theta_drift=0.0, x_bias=0.0, y_bias=0.0, position_scale=1.0,
                         v_scale=1.0, omega_scale=1.0)
    if faults != SensorFaults():
        changes["sensor_fault"] = SensorModel(faults, cfg.rates.Td,
                                              cfg.noise.position * cfg.noise.scale, cfg.seed,
                                              inner=scenario.sensor_fault)
    act = sc.actuators
    # the oracle's steering is calibrated: it commands the offset away (the wheels steer as commanded)
    offset = 0.0 if KnownPart.STEERING_OFFSET in known else sc.plant.steering_offset_rad
    if act.active or offset != 0.0:
        from tsmpc.vehicle.actuators import Actuators, ForceLag, SteeringServo

        steer = None
        if act.steering_time_constant_s > 0 or act.steering_rate_limit is not None:
            steer = SteeringServo(act.steering_time_constant_s,
                                  math.inf if act.steering_rate_limit is None else act.steering_rate_limit)
        force = ForceLag(act.force_time_constant_s) if act.force_time_constant_s > 0 else None
        changes["actuators"] = Actuators(steer, force, steering_offset_rad=offset)
    if act.measured_steering:
        changes["measured_steering"] = True
    told_vehicle = controller_vehicle(cfg, veh)
    if sc.oracle_tuned or told_vehicle != cfg.vehicle:
        # the scales told are now in the vehicle: reset, so the config re-runs alike
        unit = {f: 1.0 for part, (scales, _) in _PARTS.items() if part in known for f in scales}
        # the actuators are the car's: knowing its true mass does not give it another engine, so
        # the force limits stay those of the config's vehicle (absolute; per kg they would follow)
        lo, hi = cfg.lqr.force_limits(cfg.vehicle)
        lqr = replace(cfg.lqr, force_min=lo, force_max=hi, force_min_per_kg=None, force_max_per_kg=None)
        cfg = replace(cfg, vehicle=told_vehicle, lqr=lqr,
                      scenario=replace(sc, plant=replace(sc.plant, **unit)))
    meta = {**scenario.meta, "conditions": sc.model_dump(mode="json", exclude_defaults=True)}
    return RobustnessCase(cfg, dc_replace(scenario, meta=meta, **changes))  # type: ignore[arg-type]
