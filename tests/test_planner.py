"""Planner (SPEC §10): integration convention, limits, continuity, on random waypoint sets."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import PlannerSettings
from tsmpc.errors import DataFormatError
from tsmpc.planning.planner import JERK_MAX, path_geometry, plan_path
from tsmpc.planning.reference import Reference

SETTINGS = PlannerSettings()


def _closed_waypoints(rng: np.random.Generator) -> np.ndarray:
    ang = np.sort(rng.uniform(0, 2 * np.pi, 10))
    rad = rng.uniform(80, 200, 10)
    return np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)


def _open_waypoints(rng: np.random.Generator) -> np.ndarray:
    heading = np.cumsum(rng.uniform(-0.6, 0.6, 9))
    step = rng.uniform(30, 70, 9)
    pts = np.cumsum(np.stack([step * np.cos(heading), step * np.sin(heading)], axis=1), axis=0)
    return np.vstack([[0.0, 0.0], pts])


def _check(ref: Reference, settings: PlannerSettings, v_start: float | None = None) -> None:
    dt = ref.dt
    # The paper's integration convention reproduces the pose (0.05 m / 1e-3 rad).
    th = ref.theta[0] + np.concatenate([[0.0], np.cumsum(ref.omega[1:] * dt)])
    x = ref.x[0] + np.concatenate([[0.0], np.cumsum(ref.v[1:] * np.cos(th[1:]) * dt)])
    y = ref.y[0] + np.concatenate([[0.0], np.cumsum(ref.v[1:] * np.sin(th[1:]) * dt)])
    assert np.max(np.abs(th - ref.theta)) <= 1e-3
    assert np.max(np.hypot(x - ref.x, y - ref.y)) <= 0.05
    # ω = v κ and every limit.
    np.testing.assert_allclose(ref.omega, ref.v * ref.kappa, atol=1e-9)
    assert ref.v.max() <= settings.v_max + 1e-6
    assert np.max(np.abs(ref.v**2 * ref.kappa)) <= settings.a_lat_max * 1.01
    a = np.diff(ref.v) / dt
    assert a.max() <= settings.a_lon_max + 0.02 and a.min() >= -settings.a_brake_max - 0.02
    # Continuity: bounded steps of v and of dv/dt (jerk bound, small sampling tolerance).
    assert np.max(np.abs(np.diff(ref.v))) <= max(settings.a_lon_max, settings.a_brake_max) * dt + 0.02
    assert np.max(np.abs(np.diff(a))) / dt <= JERK_MAX * 1.1
    if v_start is not None:
        assert ref.v[0] == pytest.approx(v_start, abs=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_closed_random(seed: int) -> None:
    wp = _closed_waypoints(np.random.default_rng(seed))
    ref = plan_path(wp, SETTINGS, closed=True)
    assert ref.closed
    _check(ref, SETTINGS)
    # The lap closes: the step after the last sample lands on the first (a whole number of samples).
    geo = path_geometry(wp, closed=True)
    x_next = ref.x[-1] + ref.v[0] * np.cos(ref.theta[-1] + ref.omega[0] * ref.dt) * ref.dt
    y_next = ref.y[-1] + ref.v[0] * np.sin(ref.theta[-1] + ref.omega[0] * ref.dt) * ref.dt
    assert np.hypot(x_next - ref.x[0], y_next - ref.y[0]) < 0.1
    assert np.sum(ref.v[1:] * ref.dt) + ref.v[0] * ref.dt == pytest.approx(geo.length, rel=2e-3)


@pytest.mark.parametrize("seed", range(4))
def test_open_random(seed: int) -> None:
    wp = _open_waypoints(np.random.default_rng(100 + seed))
    ref = plan_path(wp, SETTINGS, tail_s=3.0)
    assert not ref.closed
    _check(ref, SETTINGS, v_start=SETTINGS.v_start)
    # Stays on the geometric path: the end of the path is reached (before the tail) within 0.3 m.
    n_tail = 30
    end = ref.slice(0, len(ref) - n_tail)
    assert np.min(np.hypot(end.x - wp[-1, 0], end.y - wp[-1, 1])) < 0.3 + end.v[-1] * end.dt


def test_tighter_limits_and_options() -> None:
    wp = _closed_waypoints(np.random.default_rng(7))
    st = PlannerSettings(v_max=8.0, a_lat_max=1.0, a_lon_max=1.0, a_brake_max=1.5)
    ref = plan_path(wp, st, closed=True, laps=2, dt=0.05, omega_max=0.2)
    _check(ref, st)
    assert np.abs(ref.omega).max() <= 0.2 + 1e-6
    lap = len(ref) // 2
    np.testing.assert_allclose(ref.v[:lap], ref.v[lap:], atol=1e-9)
    capped = plan_path(wp, SETTINGS, closed=True, v_cap=np.full(len(wp), 6.0))
    assert capped.v.max() <= 6.0 + 1e-6


def test_rejects_bad_input() -> None:
    with pytest.raises(DataFormatError, match="waypoints"):
        plan_path(np.array([[0.0, 0.0], [np.nan, 1.0]]), SETTINGS)
    with pytest.raises(DataFormatError, match="laps"):
        plan_path(np.array([[0.0, 0.0], [10.0, 0.0]]), SETTINGS, laps=2)
    with pytest.raises(DataFormatError, match="distinct"):
        plan_path(np.array([[0.0, 0.0], [0.0, 0.0]]), SETTINGS)
