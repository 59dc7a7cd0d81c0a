"""Plant (SPEC §3): RK4 accuracy against scipy, input validation, low speed, tyres."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.errors import NonFiniteError
from tsmpc.vehicle.plant import Plant


def _inputs(t: float) -> tuple[float, float]:
    # Accelerate, then hold speed while steering a slalom.
    return (9000.0 if t < 4.0 else 6800.0), 0.08 * np.sin(0.8 * t) if t > 2.0 else 0.0


@pytest.mark.parametrize("tyre", [TyreModel.PACEJKA, TyreModel.LINEAR])
def test_rk4_matches_solve_ivp(cfg: Config, tyre: TyreModel) -> None:
    plant = Plant(cfg.vehicle, TyreParams(model=tyre), h=0.001)
    x0 = np.array([0.0, 0.0, 0.2, 3.0, 0.0, 0.0])
    Td, n = 0.01, 1000  # 10 s, inputs held over each 10 ms
    x = x0.copy()
    ref = x0.copy()
    for k in range(n):
        u = _inputs(k * Td)
        x = plant.step(x, u, 0.9, n_steps=10)
        sol = solve_ivp(
            lambda _t, s, u=u: plant.derivatives(s, u, 0.9), (0, Td), ref,
            method="RK45", rtol=1e-10, atol=1e-10,
        )
        ref = sol.y[:, -1]
    assert x[3] > 10.0  # the manoeuvre really accelerates
    assert np.hypot(x[0] - ref[0], x[1] - ref[1]) < 1e-5
    np.testing.assert_allclose(x[2:], ref[2:], atol=1e-7)


def test_non_finite_inputs_are_rejected(cfg: Config) -> None:
    plant = Plant(cfg.vehicle, cfg.tyre)
    x = np.array([0, 0, 0, 5.0, 0, 0])
    with pytest.raises(NonFiniteError, match="input"):
        plant.step(x, (np.nan, 0.0), 0.9)
    with pytest.raises(NonFiniteError, match="state"):
        plant.step(x + np.array([0, np.inf, 0, 0, 0, 0]), (0.0, 0.0), 0.9)
    with pytest.raises(NonFiniteError, match="mu_road"):
        plant.step(x, (0.0, 0.0), float("nan"))


@pytest.mark.parametrize("tyre", [TyreModel.PACEJKA, TyreModel.LINEAR])
def test_stays_finite_at_and_near_standstill(cfg: Config, tyre: TyreModel) -> None:
    plant = Plant(cfg.vehicle, TyreParams(model=tyre))
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for u in [(0.0, 0.3), (-2000.0, -0.4), (300.0, 0.4)]:
        for _ in range(300):
            x = plant.step(x, u, 0.9, n_steps=10)
            assert np.all(np.isfinite(x))
    # Resistance does not drive a stopped car backwards.
    assert x[3] > -0.05


def test_pacejka_matches_linear_at_small_slip_and_saturates(cfg: Config) -> None:
    lin = Plant(cfg.vehicle, TyreParams(model=TyreModel.LINEAR))
    pac = Plant(cfg.vehicle, TyreParams(model=TyreModel.PACEJKA))
    x = np.array([0, 0, 0, 15.0, 0.0, 0.0])
    small = (0.0, 1e-4)
    np.testing.assert_allclose(
        pac.derivatives(x, small, 0.5)[4:], lin.derivatives(x, small, 0.5)[4:], rtol=1e-5
    )
    # Large steering: the Pacejka force saturates below μ_tyre F_zF.
    big = (0.0, 0.4)
    fzf = cfg.vehicle.static_loads[0]
    wdot = pac.derivatives(x, big, 0.5)[5]
    assert 0 < wdot * cfg.vehicle.inertia / (cfg.vehicle.a * np.cos(0.4)) <= 0.9 * fzf + 1e-9
    assert lin.derivatives(x, big, 0.5)[5] > wdot


def test_grip_scaling_with_road(cfg: Config) -> None:
    tyre = TyreParams(scale_grip_with_road=True)
    plant = Plant(cfg.vehicle, tyre)
    x = np.array([0, 0, 0, 15.0, 0.0, 0.0])
    dry = plant.derivatives(x, (0.0, 0.3), 0.9)[5]
    ice = plant.derivatives(x, (0.0, 0.3), 0.1)[5]
    assert 0 < ice < 0.2 * dry


def test_friction_force(cfg: Config) -> None:
    plant = Plant(cfg.vehicle, cfg.tyre)
    assert plant.friction_force(0.9) == pytest.approx(0.4 * 683 * 9.81)
