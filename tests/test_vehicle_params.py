"""Vehicle parameters: per-axle cornering stiffness in models and plant, mass-scaled force
limits, the CommonRoad parameter sets."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, LQRSettings, TyreModel, TyreParams, VehicleParams, load_config, replace
from tsmpc.errors import ConfigError
from tsmpc.models.dynamic import continuous_matrices
from tsmpc.synthesis.cache import dynamic_key
from tsmpc.vehicle.plant import Plant

SPLIT = VehicleParams(cornering_stiffness_front=41000.0, cornering_stiffness_rear=18000.0)


@pytest.mark.parametrize("seed", range(4))
def test_model_matrices_equal_the_linear_plant_with_split_stiffness(seed: int) -> None:
    # At α = 0 and small δ the TS model's continuous rates equal the plant's up to the small-angle
    # terms it drops: with δ → 0 the gap is O(δ²). Independent reference: the plant's equations.
    rng = np.random.default_rng(seed)
    v, om = rng.uniform(3.0, 18.0), rng.uniform(-0.8, 0.8)
    plant = Plant(SPLIT, TyreParams(model=TyreModel.LINEAR))
    for delta in (0.0, 1e-3):
        u = np.array([rng.uniform(0, 3000), delta])
        A, B = continuous_matrices(v, delta, SPLIT)
        x = np.array([v, 0.0, om])
        model = A @ x + B @ u
        nl = plant.derivatives([0, 0, 0, v, 0.0, om], u, SPLIT.mu_nominal)[3:]
        np.testing.assert_allclose(model, nl, rtol=1e-9, atol=1e-6)
    # and the α column of the α̇ and ω̇ rows against a central difference of the plant (the v row
    # drops the products α·F_y, as in the paper)
    A, _ = continuous_matrices(v, 0.0, SPLIT)
    h = 1e-6
    fd = (plant.derivatives([0, 0, 0, v, h, om], (0, 0), 0.5)
          - plant.derivatives([0, 0, 0, v, -h, om], (0, 0), 0.5))[3:] / (2 * h)
    np.testing.assert_allclose(A[1:, 1], fd[1:], rtol=1e-6, atol=1e-6)


def test_paper_values_keep_the_design_key_and_one_stiffness_means_both_axles() -> None:
    cfg = Config()
    assert (cfg.vehicle.C_f, cfg.vehicle.C_r) == (25000.0, 25000.0)
    same = replace(cfg.vehicle, cornering_stiffness_front=25000.0, cornering_stiffness_rear=25000.0)
    A1, B1 = continuous_matrices(10.0, 0.1, cfg.vehicle)
    A2, B2 = continuous_matrices(10.0, 0.1, same)
    np.testing.assert_array_equal(A1, A2)
    np.testing.assert_array_equal(B1, B2)
    # the cache key of the paper's design did not change with the new optional fields
    assert dynamic_key(cfg) == dynamic_key(replace(cfg, vehicle=VehicleParams()))
    assert dynamic_key(cfg) != dynamic_key(replace(cfg, vehicle=SPLIT))
    scaled = SPLIT.with_stiffness_scaled(0.5)
    assert (scaled.C_f, scaled.C_r) == (20500.0, 9000.0)


def test_force_limits_scale_with_mass(tmp_path) -> None:
    s = LQRSettings(force_max_per_kg=5.0, force_min_per_kg=-8.0)
    assert s.force_limits(VehicleParams(mass=1000.0)) == (-8000.0, 5000.0)
    assert s.force_limits(VehicleParams(mass=2000.0)) == (-16000.0, 10000.0)
    # default: per kg, the paper's limits at its 683 kg; absolute limits do not follow the mass
    assert LQRSettings().force_limits(VehicleParams()) == (-2000.0, 10000.0)
    assert LQRSettings().force_limits(VehicleParams(mass=2000.0)) == pytest.approx((-2000.0 * 2000 / 683,
                                                                                   10000.0 * 2000 / 683))
    absolute = LQRSettings(force_min=-2000.0, force_max=10000.0)
    assert absolute.force_limits(VehicleParams(mass=2000.0)) == (-2000.0, 10000.0)
    with pytest.raises(ConfigError, match="F_min = 50 N >= F_max = 10 N"):
        LQRSettings(force_min=50.0, force_max_per_kg=0.01).force_limits(VehicleParams(mass=1000.0))
    cfg = replace(Config(), lqr=s, vehicle=SPLIT)
    path = tmp_path / "c.toml"
    path.write_text(cfg.to_toml())
    assert load_config(path) == cfg


def test_commonroad_vehicle_2_equivalent_stiffness() -> None:
    vm = pytest.importorskip("vehiclemodels.parameters_vehicle2")
    p = vm.parameters_vehicle2()
    v = VehicleParams.from_commonroad(p)
    L = p.a + p.b
    # CommonRoad's ST lateral force at the static load: μ C_S F_z, μ = p_dy1, C_S = −p_ky1/p_dy1
    mu, cs = p.tire.p_dy1, -p.tire.p_ky1 / p.tire.p_dy1
    assert v.C_f == pytest.approx(mu * cs * p.m * 9.81 * p.b / L, rel=1e-12)
    assert v.C_r == pytest.approx(mu * cs * p.m * 9.81 * p.a / L, rel=1e-12)
    assert (v.mass, v.inertia, v.a, v.b, v.drag_factor) == (p.m, p.I_z, p.a, p.b, 0.0)
    assert (v.C_f + v.C_r) / 2 / v.mass == pytest.approx(107.5, rel=0.01)  # the C/M ≈ 107
