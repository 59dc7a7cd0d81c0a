"""Pure pursuit (issue 26 baseline) against hand-computed cases: the steady-state curvature on a
circle is 1/R, the arc to a look-ahead point on a straight from a lateral offset is 2d/L², the
look-ahead grows with speed, the speed channel and the fallback.

Tolerance on the circle: the window is a polyline of chords ds = v T_c ≤ 0.3 m, whose sagitta
ds²/(8R) ≤ 6e-4 m moves the look-ahead point by at most that: the curvature by ≤ 2·6e-4/L_d²
(≤ 2e-5 1/m for L_d ≥ 9 m), i.e. < 0.1 % of 1/R ≥ 0.0125 1/m.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from _paths import circle_window, straight_window
from tsmpc.config import Config, PurePursuitSettings, replace
from tsmpc.control.geometric import lookahead_point, nearest_point, reference_heading, vehicle_pose
from tsmpc.control.pure_pursuit import PurePursuit
from tsmpc.control.ts_mpc import MPCStatus
from tsmpc.models.kinematic import pose_to_errors

TC = 0.02  # fine sampling: chords ≤ 0.3 m


def _pp(cfg: Config, t_la: float = 1.0, L_min: float = 3.0, L_max: float = 40.0, gain: float = 0.5,
        tangent: bool = True, average: bool = True) -> PurePursuit:
    s = PurePursuitSettings(lookahead_time_s=t_la, lookahead_min_m=L_min, lookahead_max_m=L_max)
    mpc = replace(cfg.mpc, tangent_heading=tangent, step_average_reference=average)
    return PurePursuit(s, mpc, TC, along_track_gain=gain)


def _errors(w, pose) -> np.ndarray:
    """Errors against the window's first sample and θ_d (the default windows carry the tangent)."""
    return pose_to_errors(pose[0], pose[1], pose[2], w.x[0], w.y[0], w.theta[0])


@pytest.mark.parametrize("R", [20.0, 80.0])
@pytest.mark.parametrize("v", [5.0, 15.0])
@pytest.mark.parametrize("left", [True, False])
def test_curvature_on_a_circle_is_one_over_R(cfg: Config, R: float, v: float, left: bool) -> None:
    w = circle_window(R, v, TC, 600, left=left, tangent_convention=False)  # what the MPC sees
    pp = _pp(cfg, t_la=1.0, L_min=9.0)
    x0 = np.zeros(3)  # on the circle, heading along its tangent
    kappa = pp.curvature(x0, w, v)
    assert kappa == pytest.approx((1 if left else -1) / R, rel=1e-3)
    res = pp.step(x0, np.array([v, 0.0]), w)
    assert res.status == MPCStatus.OPTIMAL
    assert res.u[0] == pytest.approx(v)  # no along-track error: v_ref = v_d
    assert res.u[1] == pytest.approx(v * kappa, rel=1e-12)  # the one conversion ω = v κ


def test_the_pose_uses_the_heading_the_errors_were_taken_against(cfg: Config) -> None:
    """The cascade takes the errors against the path tangent (mpc.tangent_heading) or the raw θ_d
    (the paper preset); the law must recover that pose, else its curvature is biased. Default: the
    window carries the tangents (mpc.step_average_reference); paper preset: raw θ_d in both; the
    tangent with raw windows: measured on the window (Reference.tangent_heading)."""
    from tsmpc.planning.reference import Reference

    R, v = 30.0, 10.0
    raw = circle_window(R, v, TC, 600)  # the planner's convention: θ_d lags the tangent
    ref = Reference(np.arange(600) * TC, raw.x, raw.y, raw.theta, raw.v, raw.omega, raw.kappa)
    tan = circle_window(R, v, TC, 600, tangent_convention=False)
    X, Y, th = 0.3, -0.2, 0.05
    for tangent, average, w, th_d in ((True, True, tan, tan.theta[0]), (False, False, raw, raw.theta[0]),
                                      (True, False, ref, ref.tangent_heading()[0])):
        e = pose_to_errors(X, Y, th, w.x[0], w.y[0], th_d)
        heading = reference_heading(w, tangent, average)
        assert vehicle_pose(e, w, heading) == pytest.approx((X, Y, th), abs=1e-12)
        assert _pp(cfg, tangent=tangent, average=average).curvature(
            pose_to_errors(0.0, 0.0, float(tan.theta[0]), w.x[0], w.y[0], th_d), w, v
        ) == pytest.approx(1 / R, rel=1e-3)
    assert abs(tan.theta[0] - raw.theta[0]) > 1e-3  # the two conventions differ here


@pytest.mark.parametrize("d", [-1.0, 0.5, 2.0])
def test_arc_from_a_lateral_offset_on_a_straight(cfg: Config, d: float) -> None:
    """Vehicle d to the right of the x-axis (y = −d), heading along it: the goal at distance L on
    the axis is (√(L² − d²), d) in the vehicle frame, so κ = 2d / L²."""
    v = 10.0
    w = straight_window(v, TC, 600)
    pp = _pp(cfg, t_la=1.0, L_min=3.0)
    L = pp.lookahead(v)
    assert L == pytest.approx(10.0)
    e = _errors(w, (0.0, -d, 0.0))
    assert pp.curvature(e, w, v) == pytest.approx(2 * d / L**2, rel=1e-9)


def test_lookahead_is_speed_scheduled_and_bounded(cfg: Config) -> None:
    pp = _pp(cfg, t_la=0.8, L_min=4.0, L_max=15.0)
    assert pp.lookahead(1.0) == 4.0
    assert pp.lookahead(10.0) == pytest.approx(8.0)
    assert pp.lookahead(30.0) == 15.0


def test_far_from_the_path_the_goal_is_just_ahead_of_the_nearest_point() -> None:
    w = straight_window(10.0, 0.1, 50)
    near = nearest_point(5.0, -12.0, w.x, w.y)
    assert (near.x, near.y, near.offset) == pytest.approx((5.0, 0.0, -12.0))
    gx, gy = lookahead_point(5.0, -12.0, w.x, w.y, near, 3.0)  # 3 m < 12 m off: L grows to 12
    assert gy == 0.0 and gx == pytest.approx(5.0, abs=1e-9)


def test_speed_channel_and_saturation(cfg: Config) -> None:
    v = 10.0
    w = straight_window(v, TC, 600)
    pp = _pp(cfg, gain=0.5)
    res = pp.step(np.array([2.0, 0.0, 0.1]), np.array([v, 0.0]), w)
    assert res.u[0] == pytest.approx(v * math.cos(0.1) + 0.5 * 2.0)  # v_d cos e_θ + k e_x
    pp = _pp(cfg, L_min=3.0, L_max=4.0)
    res = pp.step(np.array([0.0, 3.0, 0.0]), np.array([v, 0.0]), w)  # κ = 2·3/4² = 0.375: ω = 3.75
    assert res.u[1] == pytest.approx(cfg.mpc.u_max[1])  # saturated to Π
    assert np.all(np.isnan(res.x_pred[1:])) and res.u_pred.shape == (cfg.mpc.N, 2)


def test_bad_inputs_give_the_fallback(cfg: Config) -> None:
    w = straight_window(10.0, TC, 600)
    pp = _pp(cfg)
    ok = pp.step(np.zeros(3), np.array([10.0, 0.0]), w)
    bad = pp.step(np.array([np.nan, 0.0, 0.0]), np.array([10.0, 0.0]), w)
    assert ok.success and bad.status == MPCStatus.FALLBACK
    assert np.allclose(bad.u, ok.u)
