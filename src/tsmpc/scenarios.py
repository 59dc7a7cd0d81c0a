"""Scenarios (the paper's scenario): road-friction profiles μ(road) by time or path distance, and the seeded
sensor-noise model."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import NoiseSettings
from tsmpc.errors import ConfigError

__all__ = [
    "ConstantFriction",
    "FrictionProfile",
    "PaperFriction",
    "PatchFriction",
    "SensorNoise",
    "SurfacePatch",
    "mu_array",
    "paper_friction_profile",
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
        dry = self.dry + self.ripple * math.sin(0.5 * t)
        if 15.0 <= t < 40.0:
            return _ramp(t, 15.0, 16.0, 39.0, 40.0, dry, self.earth)
        if 70.0 <= t < 70.1:
            return self.ice
        if 110.1 <= t < 120.0:
            return _ramp(t, 110.1, 111.1, 119.0, 120.0, dry, self.wet)
        return dry


def _ramp(t: float, a: float, b: float, c: float, d: float, base: float, level: float) -> float:
    """``level`` on [b, c], linear ramps from/to ``base`` on [a, b] and [c, d]."""
    if t < b:
        w = (t - a) / (b - a)
    elif t <= c:
        w = 1.0
    else:
        w = (d - t) / (d - c)
    return (1.0 - w) * base + w * level


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

    def mu(self, t: float, s: float = 0.0) -> float:
        if self.lap_length_m > 0:
            s = s % self.lap_length_m
        for p in self.patches:
            if p.start_m <= s < p.end_m:
                r = max(p.ramp_m, 1e-9)
                w = min(1.0, (s - p.start_m) / r, (p.end_m - s) / r)
                return (1.0 - w) * self.base + w * p.mu
        return self.base


class SensorNoise:
    """Zero-mean Gaussian noise of [X, Y, θ, v, ω], seeded (the paper's scenario defaults × scale)."""

    def __init__(self, settings: NoiseSettings, seed: int) -> None:
        s = settings
        self.sigma = s.scale * np.array([s.position, s.position, s.theta, s.v, s.omega])
        self._rng = np.random.default_rng(seed)
        self._buf = np.empty((0, 5))
        self._i = 0

    def sample(self) -> NDArray[np.float64]:
        """One draw (5,) = noise of [X, Y, θ, v, ω]. Drawn in blocks for speed; the sequence
        depends only on the seed."""
        if self._i >= self._buf.shape[0]:
            self._buf = self._rng.standard_normal((4096, 5)) * self.sigma
            self._i = 0
        out = self._buf[self._i]
        self._i += 1
        return out
