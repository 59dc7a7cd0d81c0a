"""Re-timing a reference for a vehicle's force budget (issue 21; tsmpc.planning.retime)."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, TyreParams, replace
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference
from tsmpc.planning.retime import force_budget_acceleration, retime


def _straight_with_a_hard_start(dt: float = 0.1) -> Reference:
    """Along x: 1 → 15 m/s at 5 m/s² (paper convention x(k) = x(k−1) + v(k) T), then cruise."""
    n = 200
    t = np.arange(n) * dt
    v = np.minimum(1.0 + 5.0 * t, 15.0)
    x = np.cumsum(v) * dt
    z = np.zeros(n)
    return Reference(t, x, z, z, v, z, z)


def test_retime_caps_the_acceleration_and_keeps_the_path() -> None:
    ref = _straight_with_a_hard_start()
    out = retime(ref, lambda v: 2.0)
    acc = np.diff(out.v) / out.dt
    assert acc.max() <= 2.0 * 1.05  # per-sample discretisation of v² = v0² + 2 a s
    assert acc.max() >= 1.8
    assert out.duration > ref.duration  # slower, so longer
    # the path: every new point lies on the old line, ends at the same place
    assert np.all(out.y == 0.0)
    assert out.x[-1] == pytest.approx(ref.x[-1], abs=15.0 * ref.dt)
    assert out.v[-1] == pytest.approx(15.0)  # cruise speed unchanged once reached
    assert np.all(np.diff(out.x) >= 0)


def test_a_feasible_reference_is_returned_unchanged() -> None:
    ref = _straight_with_a_hard_start()
    assert retime(ref, lambda v: 6.0) is ref


def test_braking_is_never_harder_than_the_original() -> None:
    ref0 = _straight_with_a_hard_start()
    v = np.array(ref0.v)
    v[120:] = np.maximum(15.0 - 3.0 * (ref0.t[120:] - ref0.t[120]), 5.0)  # brake at 3 m/s²
    x = np.cumsum(v) * ref0.dt
    z = np.zeros_like(v)
    ref = Reference(ref0.t, x, z, z, v, z, z)
    out = retime(ref, lambda s: 2.0)
    assert (np.diff(out.v) / out.dt).min() >= -3.0 * 1.05


def test_force_budget_is_the_force_left_after_resistance_and_drag(cfg: Config) -> None:
    p = replace(cfg.vehicle, mass=1.2 * cfg.vehicle.mass)
    a = force_budget_acceleration(p, cfg.lqr, 0.9, limits_vehicle=cfg.vehicle)  # the controllers' limits
    expect = (0.9 * 10000.0 - 0.9 * p.mass * p.g - p.drag_factor * 100.0) / p.mass
    assert a(10.0) == pytest.approx(expect)
    # with a friction ellipse the driven axle's grip also caps the traction
    tyre = TyreParams(combined_slip=True)
    a2 = force_budget_acceleration(cfg.vehicle, cfg.lqr, 0.9, tyre=tyre)
    grip = 0.9 * tyre.mu_tyre * cfg.vehicle.static_loads[1]
    assert a2(0.0) == pytest.approx(grip / cfg.vehicle.mass)
    with pytest.raises(ConfigError, match="force limit"):
        force_budget_acceleration(replace(cfg.vehicle, mass=1500.0), cfg.lqr, 0.9, limits_vehicle=cfg.vehicle)
