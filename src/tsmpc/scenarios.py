"""Scenarios (the paper's scenario): what a run tracks and the conditions it meets, as data — the
:class:`Scenario` itself, road-friction profiles μ(road) by time or path distance (with the friction
events of a config's ``[scenario]`` section), the seeded sensor-noise model and the sensor faults.

The data types sit below the simulator and the modules that build scenarios
(:mod:`tsmpc.robustness`, :mod:`tsmpc.conditions`, :mod:`tsmpc.sim.compare`): the simulator and
its compiled engine read them, the builders fill them in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import TyreParams, VehicleParams
from tsmpc.errors import ConfigError
from tsmpc.kernels.jit import jitable
from tsmpc.planning.reference import Reference
from tsmpc.sensors import (  # the sensors' data types, importable from here as before
    DropoutFault,
    NaNBurstFault,
    SensorFault,
    SensorModel,
    SensorNoise,
    _in_burst,  # noqa: F401 (importable from here as before)
)
from tsmpc.vehicle.actuators import Actuators

__all__ = [
    "ConstantFriction",
    "DropoutFault",
    "EventFriction",
    "FrictionProfile",
    "NaNBurstFault",
    "PaperFriction",
    "PatchFriction",
    "ResolvedEvent",
    "Scenario",
    "SensorFault",
    "SensorModel",
    "SensorNoise",
    "SurfacePatch",
    "apply_events",
    "event_weight",
    "mu_array",
    "paper_friction_profile",
    "paper_mu",
    "patch_mu",
]


@runtime_checkable
class FrictionProfile(Protocol):
    """μ(road) [-] at run time t [s] and travelled path distance s [m]."""

    def mu(self, t: float, s: float = 0.0) -> float: ...


def mu_array(profile: FrictionProfile, t: ArrayLike, s: ArrayLike | None = None) -> NDArray[np.float64]:
    """Evaluate a profile on arrays of t (and s)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    s = np.zeros_like(t) if s is None else np.broadcast_to(np.asarray(s, dtype=float), t.shape)
    return np.array([profile.mu(float(a), float(b)) for a, b in zip(t, s, strict=True)])


@dataclass(frozen=True)
class ConstantFriction:
    """Constant μ(road)."""

    value: float = 0.9

    def mu(self, t: float, s: float = 0.0) -> float:
        return self.value


@dataclass(frozen=True)
class PaperFriction:
    """μ(road) of the paper's 127.2 s run, by time (the paper's scenario).

    Dry asphalt ``dry + ripple sin(0.5 t)``; linear ramp to dry earth 0.68 over 15–16 s, held to
    39 s, ramp back over 39–40 s; ice 0.1 for 70.0–70.1 s; ramp to wet asphalt 0.6 over
    110.1–111.1 s, held to 119 s, ramp back over 119–120 s.
    """

    dry: float = 0.9
    ripple: float = 0.002
    earth: float = 0.68
    ice: float = 0.1
    wet: float = 0.6

    def mu(self, t: float, s: float = 0.0) -> float:
        return paper_mu(t, self.dry, self.ripple, self.earth, self.ice, self.wet)


@jitable
def _ramp(t: float, a: float, b: float, c: float, d: float, base: float, level: float) -> float:
    """``level`` on [b, c], linear ramps from/to ``base`` on [a, b] and [c, d]."""
    if t < b:
        w = (t - a) / (b - a)
    elif t <= c:
        w = 1.0
    else:
        w = (d - t) / (d - c)
    return (1.0 - w) * base + w * level


@jitable
def paper_mu(t: float, dry: float, ripple: float, earth: float, ice: float, wet: float) -> float:
    """μ(road) of :class:`PaperFriction` at time ``t`` (the block's one definition,
    :mod:`tsmpc.kernels.jit`)."""
    d = dry + ripple * math.sin(0.5 * t)
    if 15.0 <= t < 40.0:
        return _ramp(t, 15.0, 16.0, 39.0, 40.0, d, earth)
    if 70.0 <= t < 70.1:
        return ice
    if 110.1 <= t < 120.0:
        return _ramp(t, 110.1, 111.1, 119.0, 120.0, d, wet)
    return d


@jitable
def patch_mu(s: float, base: float, lap: float, patches: NDArray[np.float64]) -> float:
    """μ(road) of :class:`PatchFriction` at path distance ``s``; ``patches`` rows (start [m],
    end [m], μ, ramp [m])."""
    if lap > 0:
        s = s % lap
    for i in range(patches.shape[0]):
        p0, p1, pm, pr = patches[i, 0], patches[i, 1], patches[i, 2], patches[i, 3]
        if p0 <= s < p1:
            r = max(pr, 1e-9)
            w = min(1.0, (s - p0) / r, (p1 - s) / r)
            return (1.0 - w) * base + w * pm
    return base


@jitable
def event_weight(x: float, start: float, ramp: float, end: float) -> float:
    """Weight of a friction event at ``x`` (its time or distance): 0 before ``start``, ramps to 1
    over ``ramp``, 1 until ``end``, back to 0 over ``ramp`` after."""
    if x < start:
        return 0.0
    if x < end:
        return 1.0 if ramp <= 0.0 or x >= start + ramp else (x - start) / ramp
    if ramp <= 0.0 or x >= end + ramp:
        return 0.0
    return 1.0 - (x - end) / ramp


@jitable
def apply_events(m: float, t: float, s: float, events: NDArray[np.float64]) -> float:
    """μ after the friction ``events`` (rows [by time, start, ramp, end, μ]), applied in order:
    each blends from the μ in force before it — the base's or an earlier event's — to its own."""
    for i in range(events.shape[0]):
        w = event_weight(t if events[i, 0] != 0.0 else s, events[i, 1], events[i, 2], events[i, 3])
        if w > 0.0:
            m = (1.0 - w) * m + w * events[i, 4]
    return m


def paper_friction_profile() -> PaperFriction:
    """The paper scenario's friction profile (the paper's scenario)."""
    return PaperFriction()


@dataclass(frozen=True)
class SurfacePatch:
    """A surface of friction ``mu`` between path distances start_m and end_m, with linear
    transitions of length ramp_m on both sides (inside the patch)."""

    start_m: float
    end_m: float
    mu: float
    ramp_m: float = 5.0

    def __post_init__(self) -> None:
        if not (self.end_m > self.start_m and self.mu >= 0 and self.ramp_m >= 0):
            raise ConfigError(f"bad surface patch {self}: need end_m > start_m, mu >= 0, ramp_m >= 0")


@dataclass(frozen=True)
class PatchFriction:
    """μ(road) by path distance: a base value with surface patches (for any track).

    ``lap_length_m`` > 0 makes the patches repeat every lap.
    """

    base: float = 0.9
    patches: Sequence[SurfacePatch] = ()
    lap_length_m: float = 0.0

    @property
    def table(self) -> NDArray[np.float64]:
        """The patches as rows [start, end, μ, ramp] (what :func:`patch_mu` reads)."""
        return np.array([[p.start_m, p.end_m, p.mu, p.ramp_m] for p in self.patches],
                        dtype=float).reshape(-1, 4)

    def mu(self, t: float, s: float = 0.0) -> float:
        return patch_mu(s, self.base, self.lap_length_m, _table_of(self))


@dataclass(frozen=True)
class ResolvedEvent:
    """A friction event on one axis: time [s] (``by_time``) or travelled distance [m]."""

    by_time: bool
    start: float
    ramp: float
    end: float  #: end of the surface (inf: to the end of the run)
    mu: float

    def weight(self, t: float, s: float) -> float:
        """0 before, ramps to 1 over ``ramp``, 1 until ``end``, back to 0 over ``ramp`` after."""
        return event_weight(t if self.by_time else s, self.start, self.ramp, self.end)


@dataclass(frozen=True)
class EventFriction:
    """μ(road) of a base profile with events applied in order: each blends
    from the μ before it to its own with its weight (a step takes effect at its start)."""

    base: FrictionProfile
    events: tuple[ResolvedEvent, ...]

    @property
    def table(self) -> NDArray[np.float64]:
        """The events as rows [by time, start, ramp, end, μ] (what :func:`apply_events` reads)."""
        return np.array([[1.0 if e.by_time else 0.0, e.start, e.ramp, e.end, e.mu]
                         for e in self.events], dtype=float).reshape(-1, 5)

    def mu(self, t: float, s: float = 0.0) -> float:
        return apply_events(self.base.mu(t, s), t, s, _table_of(self))


def _table_of(profile: Any) -> NDArray[np.float64]:
    """``profile.table``, computed once and kept beside the frozen dataclass's fields."""
    cached = profile.__dict__.get("_table_cache")
    if cached is None:
        cached = profile.table
        object.__setattr__(profile, "_table_cache", cached)
    return cached


@dataclass(frozen=True)
class Scenario:
    """What a run tracks and in which conditions.

    Attributes:
        name: label used in outputs.
        reference: reference sampled at T_c, including the N-step look-ahead at its end.
        friction: μ(road) as a function of time and travelled distance.
        initial_error: (lateral offset [m], heading offset [rad]) of the start pose.
        plant_vehicle: plant-only vehicle parameters (model mismatch); None = the config's.
        plant_tyre: plant-only tyre parameters (model mismatch); None = the config's.
        actuators: steering servo / force lag in front of the default plant; None = ideal.
        measured_steering: the platform measures the steering angle the vehicle really
            received (the plant's ``applied_input``) and gives it to the cascade (the MHE then
            uses it instead of the command).
        measured_force: the same for the drive force.
        sensor_fault: measurement corruption (dropouts, NaN bursts); None = healthy sensors.
        divergence_bound_m: end the run as diverged when |e_y| exceeds it (e.g. a track's
            half-width); None = ``cfg.divergence_bound_m``.
        meta: free-form facts written to metrics.json (source file, window, ...).
    """

    name: str
    reference: Reference
    friction: FrictionProfile = field(default_factory=paper_friction_profile)
    initial_error: tuple[float, float] = (0.0, 0.0)
    plant_vehicle: VehicleParams | None = None
    plant_tyre: TyreParams | None = None
    actuators: Actuators | None = None
    measured_steering: bool = False
    measured_force: bool = False
    sensor_fault: SensorFault | None = None
    divergence_bound_m: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)
