"""The plant interface of a closed-loop simulation: anything that integrates a vehicle.

:func:`tsmpc.sim.simulator.simulate` drives any object with this protocol: tsmpc's own nonlinear
single-track plant (:class:`tsmpc.vehicle.plant.VehiclePlant`), the actuator wrappers of
:mod:`tsmpc.vehicle.actuators`, CommonRoad's models (:mod:`tsmpc.vehicle.commonroad`), or a
user's model. States use tsmpc's convention ``x = [X, Y, θ, v, α, ω]`` (global CoG position [m],
heading [rad], CoG speed [m/s], body slip angle [rad], yaw rate [rad/s]) and inputs
``u = [F_xR, δ]`` (rear drive force [N], front steering [rad]).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Plant"]


@runtime_checkable
class Plant(Protocol):
    """A vehicle the simulator can drive.

    ``step`` may raise :class:`tsmpc.errors.NonFiniteError` (or return a non-finite state) when
    the integration blows up: the run then ends early with that reason.
    """

    def reset(self, x0: ArrayLike) -> None:
        """Put the vehicle in state ``x0`` (6,) with no input history."""
        ...

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        """Apply the command ``u`` (2,) for ``dt`` seconds on a road of friction μ(road) [-];
        return the state (6,) at the end."""
        ...

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """[F_xR, δ] the vehicle actually received over the last step (its mean over the step;
        differs from the command behind actuators)."""
        ...

    @property
    def friction_force(self) -> float | None:
        """The friction disturbance F_fr [N] this plant applied over the last step, as the
        control models define it (resistance beyond μ_o M g), or None if it has no such notion."""
        ...
