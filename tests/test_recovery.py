"""Recovery by design (issue 38 item 1): whatever garbage came before, a run of valid samples
brings the cascade back — the blind stop, the re-anchored reference, the restart's speed-bounded
yaw rate, the pose gate's re-initialisation (tsmpc.control.gates, ``[recovery]``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.config import Config, replace
from tsmpc.control.cascade import Cascade, Measurement
from tsmpc.control.gates import blind_stop, jump_run, nearest_sample, speed_bounded_yaw_rate
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


def _off(cfg: Config, **recovery) -> Config:
    return replace(cfg, recovery=replace(cfg.recovery, **recovery))


def test_a_blind_start_stops_then_resumes_the_plan(cfg: Config, undisturbed) -> None:
    """3 s of all-NaN samples from x0, then clean ones: the car brakes to a stop within the 0.5 s +
    ~0.3 s it takes (blind stop) and resumes. The issue's acceptance: within 5 s of the first
    clean sample back within 1.5x the undisturbed |e_y| (over the same window, [8 s, 12 s]).
    Measured: max |e_y| 0.00016 m there against the undisturbed 0.00021 m (0.8x); over the
    restart's first 5 s 0.00006 m. With recovery.yaw_rate_bound off (the car asked to turn in
    place, the steering at full lock before it rolls): 0.0069 m (33x), 0.0082 m over the first
    5 s — this test fails (test below). Without the recovery at all the car reversed at -12 m/s,
    30 m off the path (issue 38)."""
    ey, v, ev = _drive(cfg, 12.0, blind_s=3.0)
    after, calm = ey[800:], undisturbed[0][800:]  # from 5 s after the first clean sample
    assert after.max() <= 1.5 * calm.max(), (after.max(), calm.max())
    # and no transient on the way: from the first clean sample on, within 1.5x the undisturbed
    # run's worst over its own 12 s (its start included)
    assert ey[300:].max() <= 1.5 * undisturbed[0].max(), (ey[300:].max(), undisturbed[0].max())
    assert v.min() > -0.1  # never reverses
    assert ev["mhe_rejected"] == 300  # every NaN call counted
    assert ev["blind_steps"] > 200 and ev["recoveries"] == 1
    assert undisturbed[2]["blind_steps"] == 0 and undisturbed[2]["recoveries"] == 0


def test_without_the_yaw_rate_bound_the_restart_carries_a_heading_error(cfg: Config, undisturbed) -> None:
    """recovery.yaw_rate_bound off: the kinematic MPC turns in place at v = 0, the TS-LQR swings
    the steering before the car rolls, and the car starts off with that heading error (measured
    0.0069 m over [8 s, 12 s], 33x the undisturbed run; the switch must switch it)."""
    ey, _, ev = _drive(_off(cfg, yaw_rate_bound=False), 12.0, blind_s=3.0)
    assert ey[800:].max() > 5.0 * undisturbed[0][800:].max(), ey[800:].max()
    assert ev["recoveries"] == 1


def test_a_car_at_rest_is_not_asked_to_turn_in_place(cfg: Config) -> None:
    """The restart from rest, the car standing 0.3 m beside the path after a 1 s blind start: 0.5 s
    of clean samples, the first 0.2 s without a pose (no plant: the samples say it stands).
    Bounded by its speed the yaw-rate reference is 0 and the steering stays straight (measured
    |delta| 6e-4 rad; bound 0.01 rad); unbounded the MPC asks 0.9 rad/s (three steps of its
    rate limit once it has the pose) and the TS-LQR swings the steering to 0.41 rad, near full
    lock (0.436), with the car standing."""
    ref = builtin_circuit(dt=cfg.rates.Tc)
    th = float(ref.theta[0])
    X, Y = ref.x[0] - 0.3 * math.sin(th), ref.y[0] + 0.3 * math.cos(th)
    for c, bounded in ((cfg, True), (_off(cfg, yaw_rate_bound=False), False)):
        cas = Cascade(c, "ref", ref, x0=[ref.x[0], ref.y[0], th, 0.0, 0.0, 0.0])
        w, d = [], []
        for i in range(150):
            t = i * c.rates.Td
            if t < 1.0:
                cas.step(t, Measurement(NAN_POSE, math.nan, math.nan))
                continue
            pose = NAN_POSE if t < 1.2 else (X, Y, th)  # speeds first: re-anchored at the first pose
            cmd = cas.step(t, Measurement(pose, 0.0, 0.0, stamp=t))
            w.append(abs(cmd.omega_ref))
            d.append(abs(cmd.delta))
        assert cas.events["recoveries"] == 1
        if bounded:
            assert max(w) == 0.0 and max(d) < 0.01, (max(w), max(d))
        else:
            assert max(w) > 0.5 and max(d) > 0.3, (max(w), max(d))


def test_the_yaw_rate_bound_is_the_restarts_only(cfg: Config) -> None:
    """Outside the restart the bound does not act: a moving car asked for more yaw rate than it
    can have saturates its steering, which is what a large error needs. Bounded always, the
    robustness case "initial offset" (2 m, 0.2 rad at 1 m/s) bound from its first step and got
    worse (paper reference: max |e_y| after 5 s 0.34 m against 0.06 m). Its first 2 s with the
    switch on and off: the same run, bit for bit (the Python loop: the engine has no restart)."""
    from dataclasses import replace as dc_replace

    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.simulator import simulate

    sc = dc_replace(load_scenario(cfg), initial_error=(2.0, 0.2))
    on = simulate(cfg, "REF", sc, engine=False, max_steps=20)
    off = simulate(_off(cfg, yaw_rate_bound=False), "REF", sc, engine=False, max_steps=20)
    assert np.array_equal(on.command, off.command) and np.array_equal(on.state, off.state)


def test_without_recovery_a_blind_start_locks_the_car_out(cfg: Config) -> None:
    """The switch off (the paper's cascade, without the speed governor too: slowing the reference
    after the blind start's saturated spin-like estimate, it kept this car on the path, max |e_y|
    0.21 m): the same start leaves the path (what the recovery fixes; the test above fails with it
    off)."""
    off = replace(cfg, recovery=replace(cfg.recovery, enabled=False),
                  governor=replace(cfg.governor, enabled=False))
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
    # the yaw rate a car at speed v can have: |omega| <= max(v, 0) kappa_max
    k = math.tan(cfg.lqr.delta_max) / cfg.vehicle.wheelbase  # 0.26 1/m
    assert speed_bounded_yaw_rate(0.3, 0.0, k) == 0.0  # at rest: no turning in place
    assert speed_bounded_yaw_rate(-0.3, -0.02, k) == 0.0  # rolling back (noise): none either
    assert speed_bounded_yaw_rate(0.3, 0.5, k) == 0.5 * k
    assert speed_bounded_yaw_rate(-0.3, 0.5, k) == -0.5 * k
    assert speed_bounded_yaw_rate(0.1, 0.5, k) == 0.1  # within: the same float (never binds, no change)
    assert speed_bounded_yaw_rate(0.3, math.nan, k) == 0.3  # no speed to bound it by


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
