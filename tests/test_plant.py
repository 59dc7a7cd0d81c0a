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


# -- combined slip: the friction ellipse of the driven tyre (tyre.combined_slip, issue 21) -------
def _rear_lateral_force(plant: Plant, x: np.ndarray, u: tuple[float, float], mu: float) -> float:
    """F_yR from ω̇ = (a F_yF cos δ − b F_yR)/I (SPEC §3) with F_yF computed by hand."""
    p, tyre = plant.vehicle, plant.tyre
    v, al, om = x[3], x[4], x[5]
    mu_t = mu * tyre.mu_tyre / tyre.mu_dry if tyre.scale_grip_with_road else tyre.mu_tyre
    D = mu_t * p.static_loads[0]
    B = p.C_f / (tyre.shape_c * D)
    s = B * (np.arctan2(v * np.sin(al) + p.a * om, v * np.cos(al)) - u[1])
    fyf = -D * np.sin(tyre.shape_c * np.arctan(s - tyre.curvature_e * (s - np.arctan(s))))
    wdot = plant.derivatives(x, u, mu)[5]
    return float((p.a * fyf * np.cos(u[1]) - p.inertia * wdot) / p.b)


def _pure_rear(p, tyre: TyreParams, x: np.ndarray, mu: float) -> float:
    """The pure-slip Pacejka rear force at state x, by hand (SPEC §3)."""
    v, al, om = x[3], x[4], x[5]
    mu_t = mu * tyre.mu_tyre / tyre.mu_dry if tyre.scale_grip_with_road else tyre.mu_tyre
    D = mu_t * p.static_loads[1]
    B = p.C_r / (tyre.shape_c * D)
    s = B * np.arctan2(v * np.sin(al) - p.b * om, v * np.cos(al))
    return float(-D * np.sin(tyre.shape_c * np.arctan(s - tyre.curvature_e * (s - np.arctan(s)))))


def test_combined_slip_traction_saturates_at_mu_fz(cfg: Config) -> None:
    p = cfg.vehicle
    tyre = TyreParams(combined_slip=True, scale_grip_with_road=True)
    plant = Plant(p, tyre)
    mu = 0.3
    D = 0.3 * p.static_loads[1]  # μ_t = μ(road) μ_tyre / μ_dry = 0.3
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])  # straight, no slip: v̇ = (F_t − drag)/M
    f_res = mu * p.mass * p.g * np.tanh(10.0 / 0.05)
    drag = p.drag_factor * 100.0
    for F, expect in [(f_res + 500.0, 500.0), (f_res + 5 * D, D), (f_res - 5 * D, -D)]:
        vdot = plant.derivatives(x, (F, 0.0), mu)[3]
        assert vdot == pytest.approx((expect - drag) / p.mass, rel=1e-12)
    # Without the ellipse the same 5 D of traction accelerates the car five times harder.
    free = Plant(p, TyreParams(scale_grip_with_road=True)).derivatives(x, (f_res + 5 * D, 0.0), mu)[3]
    assert free == pytest.approx((5 * D - drag) / p.mass, rel=1e-12)


def test_combined_slip_lateral_force_shrinks_on_the_ellipse(cfg: Config) -> None:
    p = cfg.vehicle
    tyre = TyreParams(combined_slip=True)
    plant = Plant(p, tyre)
    mu = 0.9
    D = tyre.mu_tyre * p.static_loads[1]
    x = np.array([0.0, 0.0, 0.0, 12.0, -0.03, 0.25])  # cornering: the rear tyre slips
    f_res = mu * p.mass * p.g * np.tanh(12.0 / 0.05)
    pure = _pure_rear(p, tyre, x, mu)
    assert abs(pure) > 0.3 * D
    for share in (0.0, 0.6, 0.99, 2.0):
        ft = min(share, 1.0) * D
        fyr = _rear_lateral_force(plant, x, (f_res + share * D, 0.0), mu)
        assert fyr == pytest.approx(pure * np.sqrt(1.0 - (ft / D) ** 2), rel=1e-9, abs=1e-6)
        assert ft**2 + fyr**2 <= D**2 * (1 + 1e-12)  # inside the friction circle


def test_combined_slip_caps_the_lateral_acceleration_at_mu_g(cfg: Config) -> None:
    """Every tyre force stays inside μ F_z, so the acceleration normal to the velocity,
    v (ω + α̇) = (−F_t sin α + F_yF cos(δ − α) + F_yR cos α)/M, never exceeds μ g (issue 21: the
    paper's plant on a μ = 0.3 road keeps lateral force from the drive force's normal component)."""
    p = cfg.vehicle
    rng = np.random.default_rng(3)
    worst = {}
    for combined in (False, True):
        plant = Plant(p, TyreParams(combined_slip=combined, scale_grip_with_road=True))
        a_n = []
        for _ in range(2000):
            x = np.array([0.0, 0.0, 0.0, rng.uniform(5, 25), rng.uniform(-0.2, 0.2), rng.uniform(-1, 1)])
            u = (rng.uniform(-2000, 10000), rng.uniform(-0.45, 0.45))
            d = plant.derivatives(x, u, 0.3)
            a_n.append(abs(x[3] * (x[5] + d[4])))
        worst[combined] = max(a_n)
    assert worst[True] <= 0.3 * p.g * (1 + 1e-9)
    assert worst[False] > 0.3 * p.g + 0.5  # the paper's plant: ≈ 1 m/s² beyond the grip


def test_combined_slip_needs_pacejka() -> None:
    from tsmpc.config import validate
    from tsmpc.errors import ConfigError

    with pytest.raises(ConfigError, match="combined_slip"):
        validate(TyreParams, {"model": "linear", "combined_slip": True}, source="tyre")
