"""MHE-UIO robustness (issue 14 item 6): the window is built by forward recursion (no inverted
transition products) and any linear-algebra failure inside ``step`` is a FAILED status, never an
exception. Checked with the CommonRoad vehicle 2 (a 1.1 t saloon with stiff tyres): at 2 m/s its
Euler transition matrices contract to |λ| ≈ 0.1, so A_{k−1}⋯A_0 over a 30-sample window is
numerically singular (≈ 1e-30) and the former inversion raised LinAlgError."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

from tsmpc.config import Config, TyreModel, TyreParams, VehicleParams
from tsmpc.estimation.mhe_uio import MHEUIO, EstimatorStatus
from tsmpc.models.dynamic import DynamicTS
from tsmpc.vehicle.plant import Plant


def _vehicle2() -> VehicleParams:
    """CommonRoad vehicle 2 mapped by hand onto tsmpc's parameters: mass, yaw inertia, a, b; the
    single cornering stiffness is the mean of the axles' Pacejka small-slip stiffnesses
    C_S · μ · F_z (C_S = −p_ky1 / p_dy1 [1/rad], μ = p_dy1, static axle loads)."""
    pytest.importorskip("vehiclemodels")  # only this car needs the [commonroad] extra
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    p = parameters_vehicle2()
    g, wb = 9.81, p.a + p.b
    cs = -p.tire.p_ky1 / p.tire.p_dy1
    c_front = cs * p.tire.p_dy1 * p.m * g * p.b / wb
    c_rear = cs * p.tire.p_dy1 * p.m * g * p.a / wb
    return VehicleParams(a=p.a, b=p.b, mass=p.m, inertia=p.I_z,
                         cornering_stiffness=0.5 * (c_front + c_rear))


@pytest.mark.parametrize("jit", [False, True])
def test_mhe_never_raises_with_vehicle2_at_2_mps_across_the_box(cfg: Config, jit: bool) -> None:
    veh = _vehicle2()
    dyn = DynamicTS(cfg.dynamic_box, veh, cfg.rates.Td)
    # The products the former build inverted are singular for this car at 2 m/s.
    A, _ = dyn.matrices(np.array([[0.0, 2.0, 0.0]] * 30))
    prod = np.linalg.multi_dot(list(A))
    assert abs(np.linalg.det(prod)) < 1e-40
    rng = np.random.default_rng(3)
    lo, hi = dyn.premise_box.lower, dyn.premise_box.upper
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not even a RuntimeWarning may escape
        # (a) coherent data: the plant (linear tyres) at 2 m/s, steering held at box values.
        # |δ| ≤ 0.15 rad keeps the plant's slip inside the MHE's |α| ≤ 0.1 bound at this speed.
        for delta in (-0.15, 0.0, 0.15):
            plant = Plant(veh, TyreParams(model=TyreModel.LINEAR), cfg.rates.h)
            x = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0])
            mhe = MHEUIO(cfg.mhe, dyn, veh, cfg.rates.Td, x0=x[3:6], jit=jit)
            u = np.zeros(2)
            statuses = []
            for _ in range(100):
                y = np.array([x[3], x[5]]) + rng.normal(0, [0.005, 0.002])
                e = mhe.step(y, u)
                statuses.append(e.status)
                assert np.all(np.isfinite(e.x)) and np.isfinite(e.F_fr)
                # hold 2 m/s: resistance + a little speed feedback
                u = np.array([veh.mu_nominal * veh.mass * veh.g + 2000.0 * (2.0 - x[3]), delta])
                x = plant.step(x, u, veh.mu_nominal, cfg.rates.plant_per_inner)
            assert statuses.count(EstimatorStatus.OK) >= 65
            assert abs(e.x[0] - x[3]) < 0.05
        # (b) every corner of the scheduling box, with incoherent random inputs and measurements:
        # failures are allowed (bounds infeasible: DAQP then works hard, so the runs are short),
        # exceptions are not.
        for d, v, al in itertools.product(*zip(lo, hi, strict=True)):
            mhe = MHEUIO(cfg.mhe, dyn, veh, cfg.rates.Td, x0=np.array([v, al, 0.0]), jit=jit)
            for k in range(12):
                y = np.array([v, 0.3 * np.sin(0.1 * k)]) + rng.normal(0, 0.01, 2)
                e = mhe.step(y, np.array([rng.normal(0, 3000.0), d]))
                assert e.status in set(EstimatorStatus)
                assert np.all(np.isfinite(e.x)) and np.isfinite(e.F_fr) and np.isfinite(e.F_fr_raw)


def test_linear_algebra_failure_is_a_failed_status(cfg: Config, monkeypatch) -> None:
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, x0=np.array([10.0, 0.0, 0.0]), jit=False)
    for _ in range(5):
        mhe.step(np.array([10.0, 0.0]), np.array([2000.0, 0.0]))

    def broken(*_a, **_k):
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setattr(mhe, "build", broken)
    e = mhe.step(np.array([10.0, 0.0]), np.array([2000.0, 0.0]))
    assert e.status == EstimatorStatus.FAILED and mhe.n_failed == 1
    assert np.all(np.isfinite(e.x))
