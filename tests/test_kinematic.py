"""Kinematic error model (SPEC §4): TS exactness and agreement with the nonlinear model."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, KinematicBox
from tsmpc.models.kinematic import (
    A_c,
    KinematicTS,
    nonlinear_step,
    pose_to_errors,
    reference_input,
    sinc,
    wrap_angle,
)


@pytest.fixture(params=["default", "paper_text"])
def ts(request: pytest.FixtureRequest, cfg: Config) -> KinematicTS:
    box = cfg.kinematic_box if request.param == "default" else KinematicBox.paper_text()
    return KinematicTS(box, cfg.rates.Tc)


def _random_rho(ts: KinematicTS, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    b = ts.box
    return np.stack(
        [rng.uniform(*b.omega, n), rng.uniform(*b.v_d, n), rng.uniform(*b.e_theta, n)], axis=-1
    )


def test_sinc_handles_zero() -> None:
    assert sinc(0.0) == 1.0
    np.testing.assert_allclose(sinc([1e-9, 0.3]), [1.0, np.sin(0.3) / 0.3], rtol=1e-15)


def test_ts_is_exact_on_10000_points(ts: KinematicTS) -> None:
    rho = _random_rho(ts, 10_000)
    rho[:5, 2] = 0.0  # sinc(0) inside the sample
    z = ts.premises(rho[:, 0], rho[:, 1], rho[:, 2])
    mu = ts.memberships(z)
    assert np.all(mu >= 0.0)
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, rtol=0, atol=1e-14)
    exact = A_c(rho[:, 0], rho[:, 1], rho[:, 2], ts.Tc)
    np.testing.assert_allclose(ts.A(z), exact, rtol=0, atol=1e-12)


def test_ts_prediction_equals_nonlinear_euler(ts: KinematicTS) -> None:
    rng = np.random.default_rng(3)
    n = 2000
    rho = _random_rho(ts, n, seed=4)
    x = np.stack([rng.normal(0, 1, n), rng.normal(0, 1, n), rho[:, 2]], axis=-1)
    u = np.stack([rng.uniform(0, 18, n), rho[:, 0]], axis=-1)  # ω = u[1] is the premise
    v_d, omega_d = rho[:, 1], rng.uniform(-0.5, 0.5, n)
    z = ts.premises(u[:, 1], v_d, x[:, 2])
    r = reference_input(v_d, omega_d, x[:, 2])  # r_c with the same cos e_θ
    np.testing.assert_allclose(
        ts.predict(x, u, z, r), nonlinear_step(x, u, v_d, omega_d, ts.Tc), rtol=0, atol=1e-12
    )


def test_clipping_is_counted(ts: KinematicTS) -> None:
    z = ts.premises([0.0, 2.0, 0.0], [5.0, 5.0, 30.0], [0.0, 0.0, 0.0])
    _, n = ts.clip(z)
    assert n == 2


def test_pose_to_errors_rotates_into_vehicle_frame() -> None:
    # Reference 1 m ahead and 2 m to the left of a car heading north.
    e = pose_to_errors(0.0, 0.0, np.pi / 2, -2.0, 1.0, np.pi / 2 + 0.1)
    np.testing.assert_allclose(e, [1.0, 2.0, 0.1], atol=1e-12)
    assert wrap_angle(3 * np.pi) == pytest.approx(-np.pi)
    # e_θ is wrapped across ±π.
    assert pose_to_errors(0, 0, 3.1, 0, 0, -3.1)[2] == pytest.approx(2 * np.pi - 6.2)
