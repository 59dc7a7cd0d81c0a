"""Stanley's law (issue 26 baseline) against hand-computed cases: a lateral offset on a straight,
a heading error on a straight, the steady state on a circle with and without the curvature
feed-forward, the steering saturation and the conversion ω = v tan δ / L.

Tolerance on the circle: chords of ≤ 0.1 m (sagitta ≤ 6e-5 m at R = 20 m) and the interpolated
tangent (error O(Δφ²) ≈ 1e-5 rad) bound the steering error well below 1e-4 rad.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from _paths import circle_window, straight_window
from tsmpc.config import Config, StanleySettings
from tsmpc.control.stanley import Stanley
from tsmpc.control.ts_mpc import MPCStatus
from tsmpc.models.kinematic import pose_to_errors

TC = 0.01
K, KS = 2.5, 1.0


def _st(cfg: Config, ff: bool = True, delta_max: float = math.radians(25), kpsi: float = 1.0) -> Stanley:
    s = StanleySettings(gain=K, softening_speed=KS, curvature_feedforward=ff, heading_gain=kpsi)
    return Stanley(s, cfg.mpc, TC, cfg.vehicle, delta_max=delta_max,
                   along_track_gain=0.5)


def _errors(w, pose) -> np.ndarray:
    """Errors against the window's first sample and θ_d (the default windows carry the tangent)."""
    return pose_to_errors(pose[0], pose[1], pose[2], w.x[0], w.y[0], w.theta[0])


@pytest.mark.parametrize("d", [1.0, -0.5])
def test_lateral_offset_on_a_straight(cfg: Config, d: float) -> None:
    """Front axle d to the right of the path, heading along it: δ = atan(k d / (k_soft + v))."""
    v = 10.0
    w = straight_window(v, TC, 400)
    st = _st(cfg)
    e = _errors(w, (0.0, -d, 0.0))
    delta = math.atan(K * d / (KS + v))
    assert st.steering(e, w, v) == pytest.approx(delta, abs=1e-12)
    res = st.step(e, np.array([v, 0.0]), w)
    L = cfg.vehicle.wheelbase
    assert res.u[1] == pytest.approx(res.u[0] * math.tan(delta) / L, rel=1e-12)
    assert res.status == MPCStatus.OPTIMAL


@pytest.mark.parametrize("kpsi", [1.0, 0.6])
def test_heading_error_on_a_straight(cfg: Config, kpsi: float) -> None:
    """On the path, heading ψ0 to the right: ψ_e = ψ0 and the front axle sits a sin ψ0 right of
    the path: δ = k_ψ ψ0 + atan(k a sin ψ0 / (k_soft + v))."""
    v, psi0 = 8.0, 0.1
    w = straight_window(v, TC, 400)
    a = cfg.vehicle.a
    e = _errors(w, (0.0, 0.0, -psi0))
    want = kpsi * psi0 + math.atan(K * a * math.sin(psi0) / (KS + v))
    assert _st(cfg, kpsi=kpsi).steering(e, w, v) == pytest.approx(want, abs=1e-12)


@pytest.mark.parametrize("left", [True, False])
@pytest.mark.parametrize("ff", [True, False])
@pytest.mark.parametrize("kpsi", [1.0, 0.5])
def test_steady_state_on_a_circle(cfg: Config, left: bool, ff: bool, kpsi: float) -> None:
    """CoG on a circle of radius R, heading along it. The front axle lies at √(R² + a²) from the
    centre, √(R² + a²) − R outside the path, and the path's tangent at its nearest point is turned
    by atan(a/R): δ = k_ψ atan(a/R) + atan(k (√(R² + a²) − R) / (k_soft + v))
    [+ atan(L/R) − k_ψ atan(a/R)]."""
    R, v = 20.0, 10.0
    a, L = cfg.vehicle.a, cfg.vehicle.wheelbase
    w = circle_window(R, v, TC, 400, left=left, tangent_convention=False)  # what the MPC sees
    cross = math.atan(K * (math.hypot(R, a) - R) / (KS + v))
    want = (math.atan(L / R) if ff else kpsi * math.atan(a / R)) + cross
    sgn = 1.0 if left else -1.0
    st = _st(cfg, ff=ff, kpsi=kpsi)
    assert st.steering(np.zeros(3), w, v) == pytest.approx(sgn * want, abs=1e-4)


def test_steering_saturates(cfg: Config) -> None:
    v = 10.0
    w = straight_window(v, TC, 400)
    e = _errors(w, (0.0, -20.0, 0.0))
    st = _st(cfg, delta_max=0.3)
    assert st.steering(e, w, v) == pytest.approx(0.3)


def test_bad_inputs_give_the_fallback(cfg: Config) -> None:
    w = straight_window(10.0, TC, 400)
    st = _st(cfg)
    ok = st.step(np.zeros(3), np.array([10.0, 0.0]), w)
    bad = st.step(np.array([0.0, np.nan, 0.0]), np.array([10.0, 0.0]), w)
    assert ok.success and bad.status == MPCStatus.FALLBACK
