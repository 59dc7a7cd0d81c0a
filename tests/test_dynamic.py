"""Dynamic model (SPEC §5): paper entries against the plant, TS vertices, discretisations."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.models.dynamic import (
    Discretization,
    DynamicTS,
    augment_apkarian,
    continuous_matrices,
    discretize,
)
from tsmpc.vehicle.plant import Plant


@pytest.fixture(scope="module")
def linear_plant(cfg: Config) -> Plant:
    return Plant(cfg.vehicle, TyreParams(model=TyreModel.LINEAR), cfg.rates.h)


def _paper_step(cfg: Config, x: np.ndarray, u: np.ndarray, mu_road: float) -> np.ndarray:
    ts = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    v, al = x[0], x[1]
    Ad, Bd = ts.matrices(np.array([u[1], v, al]))
    f_fr = (mu_road - cfg.vehicle.mu_nominal) * cfg.vehicle.mass * cfg.vehicle.g
    return Ad @ x + Bd @ u + ts.E[:, 0] * f_fr


@pytest.mark.parametrize("seed", range(5))
def test_euler_step_of_linear_plant_equals_paper_model(
    cfg: Config, linear_plant: Plant, seed: int
) -> None:
    # At α = 0 the small-angle approximations of the model are exact: this pins every entry
    # that multiplies v, ω, F_xR, δ and F_fr (including the signs of A13 and B12).
    rng = np.random.default_rng(seed)
    v, om = rng.uniform(2.5, 19.0), rng.uniform(-1.0, 1.0)
    u = np.array([rng.uniform(-2000, 10000), rng.uniform(-0.4, 0.4)])
    mu_road = rng.uniform(0.1, 0.9)
    xd = np.array([v, 0.0, om])
    xp = np.array([0.0, 0.0, 0.3, v, 0.0, om])
    plant_euler = xd + cfg.rates.Td * linear_plant.derivatives(xp, u, mu_road)[3:]
    np.testing.assert_allclose(_paper_step(cfg, xd, u, mu_road), plant_euler, rtol=1e-9, atol=0)


def test_alpha_entries_agree_to_second_order(cfg: Config, linear_plant: Plant) -> None:
    # The model neglects F_xR sin α and products of α with δ or ω; with F_xR = δ = ω = 0 the
    # α-entries (A22, A32) must then agree with the plant up to O(α²): halving α quarters the gap.
    def gap(alpha: float) -> float:
        xd = np.array([10.0, alpha, 0.0])
        xp = np.array([0.0, 0.0, 0.0, *xd])
        plant_rate = linear_plant.derivatives(xp, (0.0, 0.0), 0.5)[3:]
        model_rate = (_paper_step(cfg, xd, np.zeros(2), 0.5) - xd) / cfg.rates.Td
        return float(np.max(np.abs(model_rate - plant_rate)))

    g1, g2 = gap(0.04), gap(0.02)
    # v-row: the neglected −F_yF sin(−α) + F_yR sin α = −2C_x α² (≈ 0.12 m/s² at α = 0.04).
    assert g1 <= 1.01 * 2 * cfg.vehicle.cornering_stiffness / cfg.vehicle.mass * 0.04**2
    assert 3.5 < g1 / g2 < 4.5


def test_ts_vertices_and_interpolation(cfg: Config) -> None:
    ts = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    z = ts.premise_box.vertices()
    A, B = ts.ts_matrices(z)
    np.testing.assert_allclose(A, ts.A_vertices, atol=1e-15)
    np.testing.assert_allclose(B, ts.B_vertices, atol=1e-15)
    # α is a premise but does not enter the matrices.
    np.testing.assert_allclose(ts.A_vertices[0], ts.A_vertices[1])
    # Below the box the speed is clipped (documented low-speed behaviour).
    _, n = ts.clip(np.array([0.0, 0.5, 0.0]))
    assert n == 1
    np.testing.assert_allclose(ts.matrices([0.0, 0.5, 0.0])[0], ts.matrices([0.0, 2.0, 0.0])[0])


def test_zoh_stays_stable_at_low_speed_where_euler_does_not(cfg: Config) -> None:
    A, B = continuous_matrices(0.1, 0.0, cfg.vehicle)
    # The continuous lateral/yaw modes are stable (the v-row is a resistance, A11 < 0).
    assert np.max(np.linalg.eigvals(A).real) < 0
    Ae, _ = discretize(A, B, cfg.rates.Td, Discretization.EULER)
    Az, _ = discretize(A, B, cfg.rates.Td, Discretization.ZOH)
    assert np.max(np.abs(np.linalg.eigvals(Ae))) > 1.0
    assert np.max(np.abs(np.linalg.eigvals(Az))) < 1.0
    # ZOH and Euler agree to O(T²) at normal speed.
    A, B = continuous_matrices(10.0, 0.1, cfg.vehicle)
    Ae, _Be = discretize(A, B, 1e-4, Discretization.EULER)
    Az, _Bz = discretize(A, B, 1e-4, Discretization.ZOH)
    assert np.max(np.abs(Ae - Az)) < 1e-4**2 * np.max(np.abs(A @ A))
    ts = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td, Discretization.ZOH)
    Ed = ts.disturbance([0.0, 10.0, 0.0])
    assert Ed[0, 0] < 0 and Ed.shape == (3, 1)


def test_apkarian_augmentation(cfg: Config) -> None:
    A, B = continuous_matrices(np.array([5.0, 10.0]), np.array([0.0, 0.2]), cfg.vehicle)
    Aa, Ba = augment_apkarian(A, B, 10.0)
    assert Aa.shape == (2, 6, 6) and Ba.shape == (6, 2)
    np.testing.assert_allclose(Aa[:, :3, 3:5], B)
    assert Aa[0, 5, 2] == -1.0 and Ba[3, 0] == 10.0 and Aa[0, 4, 4] == -10.0
