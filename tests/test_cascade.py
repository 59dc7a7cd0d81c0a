"""The runtime cascade (MPC every T_c, MHE-UIO + TS-LQR every T_d) and the plant interface."""

from __future__ import annotations

from dataclasses import replace as dc_replace

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import Config
from tsmpc.control.cascade import Cascade, Measurement, Method
from tsmpc.control.ts_mpc import MPCStatus
from tsmpc.estimation.mhe_uio import EstimatorStatus
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.plant import Plant
from tsmpc.sim.simulator import simulate
from tsmpc.vehicle.plant import VehiclePlant


@pytest.fixture(scope="module")
def ref():
    return builtin_circuit(dt=0.1)


def _start(ref) -> NDArray[np.float64]:
    return np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, ref.omega[0]])


def _meas(x: NDArray[np.float64], **kw) -> Measurement:
    return Measurement((x[0], x[1], x[2]), x[3], x[5], **kw)


def test_mpc_runs_every_tc_over_td_calls_and_the_loop_tracks(cfg: Config, ref) -> None:
    cas = Cascade(cfg, Method.REF, ref, x0=_start(ref))
    plant = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    x = _start(ref)
    plant.reset(x)
    ran = []
    for m in range(300):
        cmd = cas.step(m * cfg.rates.Td, _meas(x))
        ran.append(cmd.plan is not None)
        x = plant.step(cmd.u, cfg.rates.Td, 0.9)
    assert ran == [m % 10 == 0 for m in range(300)]
    assert cas.last_plan is not None and cas.last_plan.x_pred.shape == (cfg.mpc.N + 1, 3)
    assert cas.last_estimate is not None and cas.last_estimate.status == EstimatorStatus.OK
    # 3 s on the circuit from its start: within centimetres of the reference (a broken loop is
    # metres off), and the estimate of v within 0.1 m/s of the truth.
    k = 30
    from tsmpc.models.kinematic import pose_to_errors

    e = pose_to_errors(x[0], x[1], x[2], ref.x[k], ref.y[k], ref.theta[k])
    assert abs(e[1]) < 0.1
    assert abs(cas.last_estimate.x[0] - x[3]) < 0.1
    assert cas.events["step_errors"] == 0


def test_nan_and_stale_samples_are_rejected_and_counted(cfg: Config, ref) -> None:
    cas = Cascade(cfg, Method.REF, ref, x0=_start(ref))
    x = _start(ref)
    nan = Measurement((np.nan, x[1], x[2]), np.nan, x[5])
    cmd = cas.step(0.0, nan)  # an MPC call: the pose falls back to x0's, the MHE rejects
    assert np.isfinite(cmd.F_xR) and np.isfinite(cmd.delta)
    assert cmd.plan is not None and cmd.plan.status != MPCStatus.FALLBACK
    assert cmd.estimate.status == EstimatorStatus.REJECTED
    cas.step(0.01, _meas(x, stamp=0.01 - 0.5))  # half a second old: stale
    ev = cas.events
    assert ev["pose_rejected"] == 1 and ev["mhe_rejected"] == 2 and ev["stale_rejected"] == 1
    assert cas.step(0.02, _meas(x, stamp=0.02)).estimate.status != EstimatorStatus.REJECTED


def test_step_never_raises_blocks_fall_back_and_count(cfg: Config, ref) -> None:
    cas = Cascade(cfg, Method.REF, ref, x0=_start(ref))
    x = _start(ref)
    first = cas.step(0.0, _meas(x))

    def boom(*_a, **_k):
        raise np.linalg.LinAlgError("Singular matrix")

    cas.mhe.step = boom  # type: ignore[method-assign]
    cmd = cas.step(0.01, _meas(x))  # the LQR still runs on the last estimate
    assert cmd.estimate.status == EstimatorStatus.FAILED and not cmd.held
    np.testing.assert_array_equal(cmd.estimate.x, first.estimate.x)
    assert cas.events["step_errors"] == 1 and cas.events["mhe_failed"] == 1
    assert "LinAlgError" in (cas.last_error or "")
    cas.mpc.step = boom  # type: ignore[method-assign]
    for m in range(2, 11):  # reaches the next MPC call (m = 10): shifted previous plan
        cmd = cas.step(m * 0.01, _meas(x))
    assert cmd.plan is not None and cmd.plan.status == MPCStatus.FALLBACK
    assert np.isfinite(cmd.F_xR) and np.isfinite(cmd.delta)
    cas.lqr.step = boom  # type: ignore[method-assign]
    held = cas.step(0.11, _meas(x))  # nothing left to fall back on: hold the last command
    assert held.held and (held.F_xR, held.delta) == (cmd.F_xR, cmd.delta)
    assert cas.events["step_errors"] == 13  # 11 MHE calls, 1 MPC call, 1 LQR call



def test_a_replaced_lqr_step_is_what_the_cascade_runs(cfg: Config, ref, monkeypatch) -> None:
    """The default path runs the inner block in place of TSLQR.step; a step replaced on the class
    (an instrumentation, a test's recorder) is called instead, with the block's compensated
    estimate, and decides the command."""
    from tsmpc.control.ts_lqr import TSLQR

    x = _start(ref)
    plain = Cascade(cfg, Method.REF, ref, x0=x).step(0.0, _meas(x))
    seen = []
    orig = TSLQR.step

    def recorded(self, est, v_ref, w_ref):
        seen.append(float(est.F_fr))
        return orig(self, est, v_ref, w_ref)

    monkeypatch.setattr(TSLQR, "step", recorded)
    cmd = Cascade(cfg, Method.REF, ref, x0=x).step(0.0, _meas(x))
    assert len(seen) == 1 and (cmd.F_xR, cmd.delta) == (plain.F_xR, plain.delta)


def test_measured_applied_input_reaches_the_mhe(cfg: Config, ref) -> None:
    """The MHE's window holds the measured applied input, not the command, when given (the force
    net of the law's lqr.low_speed_resistance part, which its model lacks)."""
    x = _start(ref)
    a = Cascade(cfg, Method.REF, ref, x0=x)
    b = Cascade(cfg, Method.REF, ref, x0=x)
    a.step(0.0, _meas(x))
    first = b.step(0.0, _meas(x))
    low = b._low_applied
    assert low == pytest.approx(b.lqr.low_speed_residual(float(first.estimate.x[0])))
    a.step(0.01, _meas(x))
    b.step(0.01, _meas(x, steering=0.05, force=123.0))
    assert not np.allclose(a.mhe._U[0], [123.0 - low, 0.05])
    np.testing.assert_allclose(b.mhe._U[0], [123.0 - low, 0.05])


def test_first_measurement_starts_the_cascade_without_x0(cfg: Config, ref) -> None:
    cas = Cascade(cfg, "ref", ref)
    cmd = cas.step(0.0, _meas(_start(ref)))
    assert cmd.plan is not None and np.isfinite(cmd.F_xR)


class _KinematicCar:
    """A user's plant in a few lines: a kinematic bicycle with first-order speed (no slip)."""

    def __init__(self, mass: float = 683.0, wheelbase: float = 1.794) -> None:
        self.m, self.L, self.x, self.u = mass, wheelbase, np.zeros(6), np.zeros(2)

    def reset(self, x0: ArrayLike) -> None:
        self.x = np.array(x0, dtype=float)

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        self.u = np.asarray(u, dtype=float)
        X, Y, th, v, _, _ = self.x
        for _ in range(10):
            h = dt / 10
            a = self.u[0] / self.m
            om = v * np.tan(self.u[1]) / self.L
            X, Y, th, v = X + h * v * np.cos(th), Y + h * v * np.sin(th), th + h * om, v + h * a
        self.x = np.array([X, Y, th, v, 0.0, v * np.tan(self.u[1]) / self.L])
        return self.x.copy()

    @property
    def applied_input(self) -> NDArray[np.float64]:
        return self.u.copy()

    @property
    def friction_force(self) -> float | None:
        return None


def test_a_user_plant_runs_through_simulate(cfg: Config) -> None:
    car = _KinematicCar()
    assert isinstance(car, Plant)
    sc = load_scenario(cfg)
    log = simulate(cfg, Method.REF, sc, plant=car, max_steps=80)
    assert log.termination == "completed" and log.n_outer == 80
    assert np.all(np.isnan(log.F_fr_true))
    # No resistance on this car (the models expect μ_o M g): the UIO absorbs the difference and
    # the loop tracks the first 8 s within a few decimetres.
    assert np.max(np.abs(log.errors[:, 1])) < 0.3


def test_default_plant_is_tsmpc_vehicle_plant_and_identical_when_passed(cfg: Config) -> None:
    sc = load_scenario(cfg)
    a = simulate(cfg, Method.REF, sc, max_steps=20)
    b = simulate(cfg, Method.REF, sc, max_steps=20,
                 plant=VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h))
    np.testing.assert_array_equal(a.state, b.state)
    np.testing.assert_array_equal(a.F_fr_true, b.F_fr_true)
    c = simulate(cfg, Method.REF, dc_replace(sc, initial_error=(0.2, 0.0)), max_steps=20)
    assert not np.array_equal(a.state, c.state)


@pytest.mark.parametrize("course_slip", [True, False])
def test_dead_reckoning_drives_the_slip_fits_velocity_heading(cfg: Config, ref, course_slip: bool) -> None:
    """Between poses the pose record moves one T_d along θ + α̂ + κ̂ v̂ ω̂ + β̂ (the slip fit's
    correction at the car's own lateral acceleration, with ``fusion.course_slip``), else along
    θ + α̂: a fitted model error of 20 mrad at 1.5 m/s² is 4 mm per second of a missing pose at 10
    m/s, beyond the 1e-9 m this test resolves."""
    from tsmpc.config import replace
    from tsmpc.control.fusion_block import FB_BETA, FB_KAPPA
    from tsmpc.control.gates import PO_TH, PO_X, PO_Y

    c = replace(cfg, fusion=replace(cfg.fusion, course_slip=course_slip))
    cas = Cascade(c, Method.REF, ref, x0=_start(ref))
    plant = VehiclePlant(c.vehicle, c.tyre, c.rates.h)
    x = _start(ref)
    plant.reset(x)
    Td = c.rates.Td
    n = 3400  # into the circuit's first corner (a_y,d > 1 m/s² from 33.2 s)
    for m in range(n):
        x = plant.step(cas.step(m * Td, _meas(x)).u, Td, 0.9)
    cas._fb[FB_KAPPA], cas._fb[FB_BETA] = 0.01, 0.005
    before = cas._pose.copy()
    cmd = cas.step(n * Td, Measurement((np.nan, np.nan, np.nan), x[3], x[5]))  # the pose missing
    v_hat, a_hat, w_hat = cmd.estimate.x
    assert abs(v_hat * w_hat) > 0.5  # cornering: the correction is not its β̂ alone
    heading = before[PO_TH] + a_hat + ((0.01 * v_hat * w_hat + 0.005) if course_slip else 0.0)
    assert cas._pose[PO_X] == pytest.approx(before[PO_X] + v_hat * np.cos(heading) * Td, abs=1e-9)
    assert cas._pose[PO_Y] == pytest.approx(before[PO_Y] + v_hat * np.sin(heading) * Td, abs=1e-9)
    assert cas._pose[PO_TH] == pytest.approx(before[PO_TH] + w_hat * Td, abs=1e-12)
