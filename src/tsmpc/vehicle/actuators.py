"""Actuator dynamics as plant wrappers: a steering servo (first-order lag + rate limit) and a
drive-force lag between the controller's command and the vehicle.

Real steering is a position servo: the wheel angle follows the command with a time constant
(≈ 50 ms) and a maximum rate; the drive force follows the torque request with a lag. The
controllers were designed for a plant that applies the command at once, so actuators are a
model mismatch. :class:`ActuatedPlant` wraps any :class:`~tsmpc.sim.plant.Plant`, integrates the
actuator states on sub-steps of T_d, and reports the input the vehicle really received
(``applied_input``, its mean over the step) so a platform that measures it can feed the MHE.

Discrete servo law per sub-step h (exact for the lag, then rate-limited)::

    δ_a⁺ = δ_a + clip((1 − e^{−h/τ_δ}) (δ_c − δ_a), −r h, r h)
    F_a⁺ = F_a + (1 − e^{−h/τ_F}) (F_c − F_a)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.kernels.jit import jitable
from tsmpc.sim.plant import Plant

__all__ = ["ActuatedPlant", "Actuators", "ForceLag", "SteeringServo", "wheel_steering"]


@dataclass(frozen=True)
class SteeringServo:
    """Steering position servo.

    Attributes:
        time_constant_s: first-order lag τ_δ [s] (servo gain k = 1/τ_δ [1/s]).
        rate_limit: maximum steering rate r [rad/s] (inf = none).
    """

    time_constant_s: float = 0.05
    rate_limit: float = 0.4

    def __post_init__(self) -> None:
        if not (self.time_constant_s >= 0 and math.isfinite(self.time_constant_s)):
            raise ValueError(f"SteeringServo.time_constant_s must be >= 0, got {self.time_constant_s}")
        if not self.rate_limit > 0:
            raise ValueError(f"SteeringServo.rate_limit must be > 0, got {self.rate_limit}")


@dataclass(frozen=True)
class ForceLag:
    """Drive-force lag.

    Attributes:
        time_constant_s: first-order lag τ_F [s].
    """

    time_constant_s: float = 0.1

    def __post_init__(self) -> None:
        if not (self.time_constant_s >= 0 and math.isfinite(self.time_constant_s)):
            raise ValueError(f"ForceLag.time_constant_s must be >= 0, got {self.time_constant_s}")


@dataclass(frozen=True)
class Actuators:
    """The actuators of a scenario's plant.

    Attributes:
        steering: steering servo, None = ideal steering.
        force: drive-force lag, None = ideal force.
        steering_offset_rad: the wheels stand this far off the steering the servo delivers [rad]
            (a misaligned steering; :func:`wheel_steering`).
    """

    steering: SteeringServo | None = SteeringServo()
    force: ForceLag | None = None
    steering_offset_rad: float = 0.0

    def wrap(self, plant: Plant, substeps: int = 10) -> ActuatedPlant:
        """``plant`` behind these actuators."""
        return ActuatedPlant(plant, self.steering, self.force, substeps,
                             steering_offset=self.steering_offset_rad)


def _gain(tau: float, h: float) -> float:
    return 1.0 if tau <= 0.0 else 1.0 - math.exp(-h / tau)


@jitable
def wheel_steering(delta: float, offset: float) -> float:
    """The steering angle the wheels apply [rad] for the servo's ``delta`` [rad]: plus the
    steering offset (a misalignment the steering sensor does not see); ``delta`` itself (the same
    float) without one."""
    return delta if offset == 0.0 else delta + offset


class ActuatedPlant:
    """A :class:`~tsmpc.sim.plant.Plant` behind a steering servo and a force lag.

    Args:
        plant: the vehicle.
        steering: the steering servo (None = ideal steering).
        force: the drive-force lag (None = ideal force).
        substeps: actuator sub-steps per ``step`` call (the wrapped plant is stepped with each
            sub-step's actuator output; its own ``step`` must accept ``dt / substeps``).
        steering_offset: the wheels' offset from the servo's angle [rad] (:func:`wheel_steering`);
            ``applied_input`` is the servo's angle (what a steering sensor measures).

    The actuators start at the first command (a servo already holding the wheel where the
    controller first asks for it), so a run does not begin with an artificial step.
    """

    def __init__(self, plant: Plant, steering: SteeringServo | None = SteeringServo(),
                 force: ForceLag | None = None, substeps: int = 10, steering_offset: float = 0.0) -> None:
        if substeps < 1:
            raise ValueError(f"ActuatedPlant.substeps must be >= 1, got {substeps}")
        self.plant = plant
        self.steering = steering
        self.force = force
        self.substeps = int(substeps)
        self.steering_offset = float(steering_offset)
        self._a: NDArray[np.float64] | None = None
        self._mean = np.zeros(2)

    def reset(self, x0: ArrayLike) -> None:
        """Reset the vehicle; the actuators take the next command as their start."""
        self.plant.reset(x0)
        self._a = None
        self._mean = np.zeros(2)

    @property
    def actuator_state(self) -> NDArray[np.float64] | None:
        """[F_a, δ_a] the actuators deliver now (None before the first step)."""
        return None if self._a is None else self._a.copy()

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        """Hold the command ``u`` for ``dt``; the vehicle gets the actuators' outputs."""
        uc = np.asarray(u, dtype=float).reshape(2)
        if self._a is None:
            self._a = uc.copy()
        n = self.substeps
        h = dt / n
        sv, fl = self.steering, self.force
        gd = _gain(sv.time_constant_s, h) if sv else 1.0
        rmax = sv.rate_limit * h if sv else math.inf
        gf = _gain(fl.time_constant_s, h) if fl else 1.0
        F, d = float(self._a[0]), float(self._a[1])
        Fc, dc = float(uc[0]), float(uc[1])
        acc = np.zeros(2)
        x = None
        for _ in range(n):
            F += gf * (Fc - F)
            d += min(max(gd * (dc - d), -rmax), rmax)
            x = self.plant.step((F, wheel_steering(d, self.steering_offset)), h, mu_road)
            acc += (F, d)
        self._a = np.array([F, d])
        self._mean = acc / n
        assert x is not None
        return x

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """Mean [F_xR, δ] the vehicle received over the last step."""
        return self._mean.copy()

    @property
    def friction_force(self) -> float | None:
        """The wrapped plant's friction force."""
        return self.plant.friction_force
