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

One definition (issue 34): the law of a sub-step is the ``@jitable`` block :func:`actuator_substep`
over the records :class:`ActuatorParams` (the gains of a sub-step, :func:`actuator_params`) and
:class:`ActuatorState`; :func:`actuator_start` begins a step and :func:`applied_mean` is the input
the vehicle received over it. :meth:`ActuatedPlant.step` calls them as Python; the run engine
(``tsmpc.kernels.engine``) compiles the same functions around its plant block.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.kernels.jit import jitable
from tsmpc.sim.plant import Plant

__all__ = [
    "ActuatedPlant",
    "ActuatorParams",
    "ActuatorState",
    "Actuators",
    "ForceLag",
    "SteeringServo",
    "actuator_params",
    "actuator_start",
    "actuator_substep",
    "applied_mean",
    "lag_gain",
    "wheel_steering",
]


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


class ActuatorParams(NamedTuple):
    """The actuators' law over one sub-step h (:func:`actuator_params` builds it).

    Attributes:
        force_gain: 1 − e^{−h/τ_F} of the force lag (1: ideal force, the command at once).
        steer_gain: 1 − e^{−h/τ_δ} of the steering servo (1: ideal steering).
        max_steer_step: the servo's rate limit over a sub-step, r h [rad] (inf: none).
        steering_offset: the wheels' offset from the servo's angle [rad] (:func:`wheel_steering`).
        substeps: sub-steps per step.
    """

    force_gain: float
    steer_gain: float
    max_steer_step: float
    steering_offset: float
    substeps: int


class ActuatorState(NamedTuple):
    """What the actuators deliver now, and the sums of the step so far.

    Attributes:
        F: the drive force F_a [N].
        delta: the servo's steering angle δ_a [rad] (what a steering sensor measures).
        F_sum: Σ F_a over this step's sub-steps [N].
        delta_sum: Σ δ_a over this step's sub-steps [rad].
    """

    F: float
    delta: float
    F_sum: float = 0.0
    delta_sum: float = 0.0


@jitable
def lag_gain(tau: float, h: float) -> float:
    """The share 1 − e^{−h/τ} of the gap a first-order lag closes in h (1 when τ = 0: no lag)."""
    return 1.0 if tau <= 0.0 else 1.0 - math.exp(-h / tau)


def actuator_params(steering: SteeringServo | None, force: ForceLag | None, substeps: int, dt: float,
                    steering_offset: float) -> ActuatorParams:
    """The law of a sub-step h = dt / substeps of these actuators (None: ideal)."""
    h = dt / substeps
    return ActuatorParams(lag_gain(force.time_constant_s, h) if force else 1.0,
                          lag_gain(steering.time_constant_s, h) if steering else 1.0,
                          steering.rate_limit * h if steering else math.inf, float(steering_offset),
                          int(substeps))


@jitable
def actuator_start(s: ActuatorState, started: bool, F_c: float, delta_c: float) -> ActuatorState:
    """The state a step begins from: the actuators' own, or (not ``started``: the first step) the
    command itself; the step's sums at zero."""
    if started:
        return ActuatorState(s.F, s.delta, 0.0, 0.0)
    return ActuatorState(F_c, delta_c, 0.0, 0.0)


@jitable
def actuator_substep(p: ActuatorParams, s: ActuatorState, F_c: float, delta_c: float) -> ActuatorState:
    """One sub-step towards the command (F_c, δ_c): the force lag, the servo's lag limited to its
    rate (the module docstring's law); the delivered values added to the step's sums."""
    F = s.F + p.force_gain * (F_c - s.F)
    d = s.delta + min(max(p.steer_gain * (delta_c - s.delta), -p.max_steer_step), p.max_steer_step)
    return ActuatorState(F, d, s.F_sum + F, s.delta_sum + d)


@jitable
def applied_mean(p: ActuatorParams, s: ActuatorState) -> tuple[float, float]:
    """The mean (F_a, δ_a) the vehicle received over the step (``applied_input``)."""
    return s.F_sum / p.substeps, s.delta_sum / p.substeps


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
        self._s: ActuatorState | None = None  # None: no step yet (the next command is the start)
        self._mean = (0.0, 0.0)

    def reset(self, x0: ArrayLike) -> None:
        """Reset the vehicle; the actuators take the next command as their start."""
        self.plant.reset(x0)
        self._s = None
        self._mean = (0.0, 0.0)

    def params(self, dt: float) -> ActuatorParams:
        """The actuators' law per sub-step of a step of ``dt``."""
        return actuator_params(self.steering, self.force, self.substeps, dt, self.steering_offset)

    @property
    def actuator_state(self) -> NDArray[np.float64] | None:
        """[F_a, δ_a] the actuators deliver now (None before the first step)."""
        return None if self._s is None else np.array([self._s.F, self._s.delta])

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        """Hold the command ``u`` for ``dt``; the vehicle gets the actuators' outputs."""
        uc = np.asarray(u, dtype=float).reshape(2)
        F_c, d_c = float(uc[0]), float(uc[1])
        p = self.params(dt)
        h = dt / p.substeps
        started = self._s is not None
        s = actuator_start(self._s if self._s is not None else ActuatorState(0.0, 0.0), started, F_c, d_c)
        x = None
        for _ in range(p.substeps):
            s = actuator_substep(p, s, F_c, d_c)
            x = self.plant.step((s.F, wheel_steering(s.delta, p.steering_offset)), h, mu_road)
        self._s = s  # (a sub-step that raised leaves the actuators where they were)
        self._mean = applied_mean(p, s)
        assert x is not None
        return x

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """Mean [F_xR, δ] the vehicle received over the last step."""
        return np.array(self._mean)

    @property
    def friction_force(self) -> float | None:
        """The wrapped plant's friction force."""
        return self.plant.friction_force
