"""The actuators' block (issue 34, one definition): the sub-step law of the steering servo and the
force lag (tsmpc.vehicle.actuators.actuator_substep and its companions), called by
ActuatedPlant.step as Python and by the run engine compiled.

By hand, as Python and compiled (the engine's way): the lag's gain, the rate limit in both
directions, the start at the first command, the step's mean and the wheels' offset; Python =
compiled to the bit on random inputs; and ActuatedPlant.step through the block against the law
written out here, so a mutation of the block's arithmetic fails in both ways."""

from __future__ import annotations

import math

import numpy as np
import pytest

from test_actuators import _Recorder as _Inputs  # a plant that records its inputs
from tsmpc import kernels
from tsmpc.vehicle.actuators import (
    ActuatedPlant,
    ActuatorParams,
    ActuatorState,
    ForceLag,
    SteeringServo,
    actuator_params,
    actuator_start,
    actuator_substep,
    applied_mean,
    lag_gain,
    wheel_steering,
)

#: gains 0.25 (force) and 0.5 (steering), a rate limit of 0.01 rad per sub-step, 4 sub-steps
P = ActuatorParams(force_gain=0.25, steer_gain=0.5, max_steer_step=0.01, steering_offset=0.0, substeps=4)



def test_lag_gain_by_hand(way) -> None:
    f = way(lag_gain)
    assert f(0.05, 0.001) == 1.0 - math.exp(-0.02)
    assert f(0.0, 0.001) == 1.0  # no lag: the command at once
    assert f(-1.0, 0.001) == 1.0


def test_force_lag_and_servo_lag_by_hand(way) -> None:
    f = way(actuator_substep)
    s = f(P, ActuatorState(100.0, 0.001, 7.0, 0.5), 500.0, 0.005)
    assert s.F == 100.0 + 0.25 * 400.0 == 200.0  # the force lag closes a quarter of the gap
    assert s.delta == 0.001 + 0.5 * 0.004  # within the rate limit: the servo's lag alone
    assert s.F_sum == 7.0 + 200.0 and s.delta_sum == 0.5 + s.delta  # the step's sums


def test_rate_limit_in_both_directions(way) -> None:
    f = way(actuator_substep)
    up = f(P, ActuatorState(0.0, 0.0), 0.0, 0.2)  # the lag asks for 0.1 rad: limited to 0.01
    assert up.delta == 0.01
    down = f(P, ActuatorState(0.0, 0.0), 0.0, -0.2)
    assert down.delta == -0.01
    free = f(P._replace(max_steer_step=math.inf), ActuatorState(0.0, 0.0), 0.0, -0.2)
    assert free.delta == -0.1


def test_start_mean_and_offset(way) -> None:
    start = way(actuator_start)
    s = start(ActuatorState(1.0, 0.2, 9.0, 9.0), True, 500.0, 0.1)
    assert tuple(s) == (1.0, 0.2, 0.0, 0.0)  # the actuators' own state, the sums restarted
    s = start(ActuatorState(1.0, 0.2, 9.0, 9.0), False, 500.0, 0.1)
    assert tuple(s) == (500.0, 0.1, 0.0, 0.0)  # the first step starts at the command
    assert way(applied_mean)(P, ActuatorState(0.0, 0.0, 10.0, 0.2)) == (2.5, 0.05)
    assert way(wheel_steering)(0.1, 0.02) == 0.1 + 0.02
    assert way(wheel_steering)(-0.0, 0.0) == 0.0 and math.copysign(1.0, way(wheel_steering)(-0.0, 0.0)) < 0


def test_compiled_equals_python_to_the_bit() -> None:
    if kernels.load("plant") is None:
        pytest.skip("compiled kernels unavailable")
    from _blocks import compiled

    nb_step, nb_mean = compiled(actuator_substep), compiled(applied_mean)
    rng = np.random.default_rng(11)
    for _ in range(300):
        p = ActuatorParams(float(rng.uniform(0, 1)), float(rng.uniform(0, 1)),
                           float(rng.choice([rng.uniform(0, 0.01), math.inf])), 0.0, int(rng.integers(1, 20)))
        s = ActuatorState(*(float(v) for v in rng.normal(0, [1000, 0.2, 1000, 1])))
        Fc, dc = float(rng.normal(0, 3000)), float(rng.normal(0, 0.3))
        assert tuple(nb_step(p, s, Fc, dc)) == tuple(actuator_substep(p, s, Fc, dc))
        assert nb_mean(p, s) == applied_mean(p, s)




def test_actuated_plant_runs_the_law() -> None:
    """ActuatedPlant.step through the block, against the law written out (4 sub-steps of 2.5 ms:
    gains 1 − e^{−h/τ}, a rate limit of r h), the wheels' offset and the step's mean."""
    rec = _Inputs()
    tau_d, tau_f, r, h = 0.05, 0.1, 0.4, 0.0025
    plant = ActuatedPlant(rec, SteeringServo(tau_d, r), ForceLag(tau_f), substeps=4, steering_offset=0.003)
    assert plant.params(0.01) == actuator_params(SteeringServo(tau_d, r), ForceLag(tau_f), 4, 0.01, 0.003)
    assert plant.params(0.01) == (1.0 - math.exp(-h / tau_f), 1.0 - math.exp(-h / tau_d), r * h, 0.003, 4)
    plant.reset(np.zeros(6))
    plant.step([200.0, 0.0], 0.01, 0.9)  # the start: the command held
    assert rec.inputs == [(200.0, 0.003)] * 4
    assert list(plant.applied_input) == [200.0, 0.0]
    plant.step([1200.0, 0.05], 0.01, 0.9)
    F, d, Fs, ds = 200.0, 0.0, 0.0, 0.0
    for i in range(4):
        F += (1.0 - math.exp(-h / tau_f)) * (1200.0 - F)
        d += min(max((1.0 - math.exp(-h / tau_d)) * (0.05 - d), -r * h), r * h)
        Fs, ds = Fs + F, ds + d
        assert rec.inputs[4 + i] == (F, d + 0.003)
    assert d == 4 * r * h  # the servo's lag asks for more: it moved at its rate limit
    assert list(plant.actuator_state) == [F, d]
    assert list(plant.applied_input) == [Fs / 4, ds / 4]
