"""Recovery by design (issue 38 item 1): whatever garbage came before, a run of valid samples
brings the cascade back — the blind stop, the re-anchored reference, the pose gate's
re-initialisation (tsmpc.control.gates, ``[recovery]``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.config import Config, replace
from tsmpc.control.cascade import Cascade, Measurement
from tsmpc.control.gates import blind_stop, jump_run, nearest_sample
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.vehicle.plant import VehiclePlant

NAN_POSE = (math.nan, math.nan, math.nan)


def _lateral(ref, X: float, Y: float) -> float:
    """Distance to the path (nearest reference sample's lateral error): the reference's timing
    moves after a recovery, its path does not."""
    k = int(np.argmin(np.hypot(ref.x - X, ref.y - Y)))
    th = ref.theta[k]
    return -math.sin(th) * (X - ref.x[k]) + math.cos(th) * (Y - ref.y[k])


def _drive(cfg: Config, T: float, *, blind_s: float = 0.0, pose_offset: float = 0.0):
    """The cascade in a loop with tsmpc's plant (examples/cascade_loop.py), started from x0;
    all-NaN samples before ``blind_s``; the cascade's x0 pose ``pose_offset`` m off the car's."""
    ref = builtin_circuit(dt=cfg.rates.Tc)
    x0 = np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, 0.0])
    cas = Cascade(cfg, "ref", ref, x0=x0 + np.array([0.0, pose_offset, 0, 0, 0, 0]))
    car = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    car.reset(x0)
    Td = cfg.rates.Td
    ey, v = [], []
    for i in range(round(T / Td)):
        t = i * Td
        X, Y, th, vv, _, om = car.state
        m = Measurement(NAN_POSE, math.nan, math.nan) if t < blind_s else Measurement((X, Y, th), vv, om)
        cmd = cas.step(t, m)
        car.step([cmd.F_xR, cmd.delta], Td, mu_road=0.9)
        ey.append(abs(_lateral(ref, X, Y)))
        v.append(vv)
    return np.array(ey), np.array(v), cas.events


@pytest.fixture(scope="module")
def undisturbed(cfg: Config):
    return _drive(cfg, 12.0)


def test_a_blind_start_stops_then_resumes_the_plan(cfg: Config, undisturbed) -> None:
    """3 s of all-NaN samples from x0, then clean ones. Measured: the car brakes to a stop within
    the 0.5 s + ~0.3 s it takes (blind stop), resumes; max |e_y| from 5 s after the first clean
    sample 0.007 m (undisturbed over the same time 0.001 m, over its first 12 s 0.001-0.002 m:
    the restart from rest runs the plan's acceleration with saturated force). Bound: 0.02 m.
    Without the recovery the car reversed at -12 m/s, 30 m off the path (issue 38)."""
    ey, v, ev = _drive(cfg, 12.0, blind_s=3.0)
    after = ey[800:]  # from 5 s after the first clean sample
    assert after.max() < 0.02, after.max()
    assert v.min() > -0.1  # never reverses
    assert ev["mhe_rejected"] == 300  # every NaN call counted
    assert ev["blind_steps"] > 200 and ev["recoveries"] == 1
    assert undisturbed[2]["blind_steps"] == 0 and undisturbed[2]["recoveries"] == 0


def test_without_recovery_a_blind_start_locks_the_car_out(cfg: Config) -> None:
    """The switch off (the paper's cascade): the same start leaves the path (what the recovery
    fixes; the test above fails with it off)."""
    off = replace(cfg, recovery=replace(cfg.recovery, enabled=False))
    ey, v, ev = _drive(off, 12.0, blind_s=3.0)
    assert ey.max() > 0.5 or v.min() < -1.0
    assert ev["blind_steps"] == 0


def test_a_wrong_start_pose_is_replaced_by_consistent_measurements(cfg: Config) -> None:
    """x0 30 m off the car: every measured pose is a jump from the dead-reckoned one. After
    pose_reinit_s (2 s) of poses consistent with one another the gate takes them; without the
    recovery only the jump allowance's growth (2 m/s) would, after 14.5 s — a dead reckoning that
    runs away faster than that (an open-loop estimate while blind) is never caught up with."""
    _, _, ev = _drive(cfg, 6.0, pose_offset=30.0)
    assert ev["pose_reinit"] == 1
    assert 150 <= ev["pose_jump_rejected"] <= 210  # 2 s at 100 Hz, then none
    off = replace(cfg, recovery=replace(cfg.recovery, enabled=False))
    _, _, ev_off = _drive(off, 6.0, pose_offset=30.0)
    assert ev_off["pose_jump_rejected"] == 600 and ev_off["pose_reinit"] == 0


def test_the_recovery_blocks_on_their_own(cfg: Config) -> None:
    """The blocks' arithmetic (mutations of it fail here)."""
    from tsmpc.control.gates import GateParams

    g = GateParams(-1.0, 40.0, 4.0, 0.0, 0.0, 0.01)
    # a run of consistent rejected poses is taken after reinit_s, an inconsistent one restarts it
    take, t0 = jump_run(g, 2.0, math.nan, 0, 0, 0, 0, 5.0, 0.0, 0.0, 1.0)
    assert (take, t0) == (False, 1.0)
    take, t0 = jump_run(g, 2.0, 1.0, 5.0, 0.0, 0.0, 1.0, 5.5, 0.0, 0.0, 2.9)
    assert (take, t0) == (False, 1.0)
    take, t0 = jump_run(g, 2.0, 1.0, 5.5, 0.0, 0.0, 2.9, 5.6, 0.0, 0.0, 3.0)
    assert (take, t0) == (True, 1.0)
    take, t0 = jump_run(g, 2.0, 1.0, 5.5, 0.0, 0.0, 2.9, 50.0, 0.0, 0.0, 3.0)  # 44.5 m in 0.1 s
    assert (take, t0) == (False, 3.0)
    # the stop: decel × mass within the limits, no force at rest, the last steering kept
    assert blind_stop(5.0, 0.1, 1000.0, 3.0, -2000.0, 10000.0) == (-2000.0, 0.1)
    assert blind_stop(5.0, 0.1, 500.0, 3.0, -2000.0, 10000.0) == (-1500.0, 0.1)
    assert blind_stop(0.0, -0.2, 500.0, 3.0, -2000.0, 10000.0) == (0.0, -0.2)
    x = np.array([0.0, 1.0, 2.0, 3.0, 2.0])
    assert nearest_sample(x, np.zeros(5), 0, 4, 2.1, 0.0) == 2
    assert nearest_sample(x, np.zeros(5), 3, 4, 2.1, 0.0) == 4  # only [k_lo, k_hi] is searched
    assert nearest_sample(np.array([1.0, 3.0]), np.zeros(2), 0, 1, 2.0, 0.0) == 0  # the first of equals


def test_every_ignored_sample_is_counted(cfg: Config) -> None:
    """A NaN pose on a call where the MPC does not run was counted nowhere (issue 38); now every
    call with a fresh non-finite pose counts under pose_nan."""
    ref = builtin_circuit(dt=cfg.rates.Tc)
    x0 = np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, 0.0])
    cas = Cascade(cfg, "ref", ref, x0=x0)
    n_in = cfg.rates.inner_per_outer
    nan_calls = 0
    for i in range(300):
        nan_pose = i % n_in != 0 and i < 200  # only between the MPC's steps
        nan_calls += nan_pose
        pose = NAN_POSE if nan_pose else (float(x0[0]), float(x0[1]), float(x0[2]))
        cas.step(i * cfg.rates.Td, Measurement(pose, float(x0[3]), 0.0))
    assert nan_calls == 180
    assert cas.events["pose_nan"] == nan_calls  # (the MPC steps: pose_rejected, repeated_rejected)
