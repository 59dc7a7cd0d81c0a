"""Compiled kernels (tsmpc.kernels) against their numpy oracles, on recorded and random data.

Tolerances: the kernels solve the same problems by other factorisations (Riccati recursion,
block-tridiagonal elimination) or evaluate the same formulas in another order, so they agree to
rounding amplified by the problems' conditioning: 1e-8 on inputs/states (the issue's bound), and
far tighter where the arithmetic is identical (plant, LQR: 1e-10)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.config import Config, SchedulingMode, replace
from tsmpc.control.ts_mpc import TSMPC, MPCStatus, condense
from tsmpc.models.kinematic import KinematicTS, nonlinear_step
from tsmpc.synthesis.cache import load_or_design_kinematic

pytestmark = pytest.mark.skipif(not kernels.enabled(), reason="TSMPC_NO_JIT is set")

N = 40


@pytest.fixture(scope="module")
def kdesign(cfg: Config):
    return load_or_design_kinematic(cfg)


def _pair(cfg: Config, design, mode: str, **changes) -> tuple[TSMPC, TSMPC]:
    st = replace(cfg.mpc, **changes) if changes else cfg.mpc
    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    return (TSMPC(st, model, design.P, design.S, mode=SchedulingMode(mode), jit=True),
            TSMPC(st, model, design.P, design.S, mode=SchedulingMode(mode), jit=False))


def _same(ra, rb, tol: float = 1e-8) -> None:
    assert ra.status == rb.status
    assert ra.n_clipped == rb.n_clipped
    assert ra.iterations == rb.iterations
    np.testing.assert_allclose(ra.u_pred, rb.u_pred, rtol=0, atol=tol)
    np.testing.assert_allclose(ra.du, rb.du, rtol=0, atol=tol)
    np.testing.assert_allclose(ra.x_pred, rb.x_pred, rtol=0, atol=tol)
    assert ra.cost == pytest.approx(rb.cost, rel=1e-9, abs=1e-9)


def test_riccati_kernel_is_the_condensed_unconstrained_minimiser() -> None:
    mk = kernels.load("mpc")
    assert mk is not None
    rng = np.random.default_rng(1)
    Tc = 0.1
    for _ in range(200):
        c = rng.uniform(-0.14, 0.14, N)
        s = rng.uniform(0.1, 1.8, N)
        x0 = rng.normal(size=3) * [2, 2, 0.1]
        up, r = rng.normal(size=2) + np.array([8.0, 0.0]), rng.normal(size=(N, 2)) + np.array([8.0, 0.0])
        q, R = rng.uniform(0.05, 15, 3), rng.uniform(1e-5, 5, 2)
        M = rng.normal(size=(3, 3))
        P = M @ M.T + np.eye(3)
        qp = condense(x0, up, r, c, s, Tc, q, P, R)
        z = np.linalg.solve(qp.H, -qp.f)
        U, DU, X = np.empty((N, 2)), np.empty((N, 2)), np.empty((N + 1, 3))
        cost = mk.riccati(x0, up, c, s, r, Tc, q, P, R, U, DU, X)
        # Random weights down to R_v = 1e-5 give cond(H) ≈ 1e7: agreement relative to the size
        # of the answer, and the Riccati answer is at least as good a minimiser (KKT residual).
        zr = DU.T.reshape(-1)
        scale = max(1.0, np.abs(z).max())
        np.testing.assert_allclose(zr, z, rtol=0, atol=1e-8 * scale)
        np.testing.assert_allclose(X[1:], (qp.x_aff + qp.G @ z).reshape(3, N).T, rtol=0,
                                   atol=1e-8 * max(1.0, np.abs(X).max()))
        res_chol, res_ric = np.abs(qp.H @ z + qp.f).max(), np.abs(qp.H @ zr + qp.f).max()
        assert res_ric <= 3.0 * res_chol + 1e-12 * np.abs(qp.f).max()
        assert cost == pytest.approx(z @ qp.H @ z + 2 * qp.f @ z + qp.c0, rel=1e-9)


@pytest.mark.parametrize("mode", ["fzn", "ref", "iter"])
def test_mpc_fast_path_equals_the_condensed_path_on_the_paper_reference(
    cfg: Config, kdesign, paper_reference_path, mode: str
) -> None:
    from tsmpc.planning.paper_format import load_paper_reference

    ref = load_paper_reference(paper_reference_path)
    a, b = _pair(cfg, kdesign, mode)
    e, u = np.array([0.0, 2.0, 0.1]), np.array([ref.v[0], ref.omega[0]])
    statuses = set()
    for k in range(400):
        w = ref.window(k, N + 1)
        ra, rb = a.step(e, u, w), b.step(e, u, w)
        _same(ra, rb)
        statuses.add((rb.status, rb.iterations > 0))
        u = rb.u
        e = nonlinear_step(e, u, w.v[0], w.omega[0], cfg.rates.Tc)
    assert (MPCStatus.OPTIMAL, False) in statuses  # the fast path was taken


@pytest.mark.parametrize("mode", ["fzn", "ref", "iter"])
def test_mpc_fast_path_equals_the_condensed_path_on_random_data(cfg: Config, kdesign, mode: str) -> None:
    """Random errors, previous inputs and references, including ones where a rate, input or the
    terminal constraint is active (the kernel must hand those to the QP path: same answer)."""
    rng = np.random.default_rng(7)
    a, b = _pair(cfg, kdesign, mode)
    n_qp = n_fast = 0
    for _ in range(150):
        if rng.random() < 0.3:
            a.reset()
            b.reset()
        e = rng.normal(size=3) * [1.5, 1.5, 0.08]
        u = np.array([rng.uniform(0, 18), rng.uniform(-1.4, 1.4)])
        v = np.clip(u[0] + np.cumsum(rng.normal(0, 0.3, N + 1)), 0.5, 17.5)
        w = np.clip(u[1] + np.cumsum(rng.normal(0, 0.05, N + 1)), -1.3, 1.3)
        ref = SimpleNamespace(v=v, omega=w)
        ra, rb = a.step(e, u, ref), b.step(e, u, ref)
        _same(ra, rb)
        if rb.iterations:
            n_qp += 1
        else:
            n_fast += 1
    assert n_qp > 0 and n_fast > 0  # both paths exercised


def test_mpc_kernel_switch_off(cfg: Config, kdesign, monkeypatch) -> None:
    monkeypatch.setenv("TSMPC_NO_JIT", "1")
    a = TSMPC(cfg.mpc, KinematicTS(cfg.kinematic_box, cfg.rates.Tc), kdesign.P, kdesign.S)
    assert a._kern is None


# -- MHE-UIO -----------------------------------------------------------------------------------
#: F̂ tolerance [N]. F enters the window only through T_d/M ≈ 1.5e-5 (m/s)/N per sample, and the
#: Schur complement that determines it is the small difference h_FF − hᵀT⁻¹h (≈ 1e-10 against
#: terms of ≈ 1e-9), so agreement in F̂ is ≈ 1e4 × looser than in x̂ in absolute terms: 1e-4 N is
#: 1e-7 of the ±1000 N range of the friction force (observed: ≈ 2e-6 N).
F_TOL = 1e-4


def _mhe_pair(cfg: Config, x0):
    from tsmpc.estimation.mhe_uio import MHEUIO
    from tsmpc.models.dynamic import DynamicTS

    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    return (MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, x0, jit=True),
            MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, x0, jit=False))


def test_mhe_kernel_equals_the_dense_qp_in_the_closed_inner_loop(cfg: Config) -> None:
    """Recorded data: the inner loop closed on the Pacejka plant with speed and yaw-rate
    references, a friction change and two rejected (NaN) measurements."""
    from tsmpc.control.ts_lqr import TSLQR
    from tsmpc.models.dynamic import DynamicTS
    from tsmpc.scenarios import SensorNoise
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.vehicle.plant import Plant

    Td = cfg.rates.Td
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    lqr = TSLQR(load_or_design_dynamic(cfg).K, dyn, cfg.vehicle, cfg.lqr, Td)
    plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    noise = SensorNoise(cfg.noise, 0)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    a, b = _mhe_pair(cfg, x[3:6])
    u = np.zeros(2)
    seen = set()
    for k in range(1200):
        y = np.array([x[3], x[5]]) + noise.sample()[3:5]
        if k in (77, 640):
            y[0] = np.nan
        ea, eb = a.step(y, u), b.step(y, u)
        assert ea.status == eb.status
        seen.add(eb.status)
        np.testing.assert_allclose(ea.x, eb.x, rtol=0, atol=1e-8)
        assert abs(ea.F_fr - eb.F_fr) <= F_TOL
        assert ea.F_fr_raw == pytest.approx(eb.F_fr_raw, rel=1e-9, abs=1e-6)
        cmd = lqr.step(eb, 10.0 + 3.0 * np.sin(0.003 * k), 0.15 * np.sin(0.03 * (k // 10)))
        u = np.array([cmd.F_xR, cmd.delta])
        x = plant.step(x, u, 0.9 if k < 600 else 0.5, cfg.rates.plant_per_inner)
    assert {"ok", "warmup", "rejected"} <= {str(s) for s in seen}


def test_mhe_kernel_equals_the_dense_qp_on_random_windows(cfg: Config) -> None:
    """Random windows (measurements, inputs, scheduling, rejected samples, arrival, F prior) solved
    by the banded kernel and by the dense build + Cholesky."""
    from tsmpc.estimation.mhe_uio import F_PRIOR_WEIGHT, MHEUIO
    from tsmpc.models.dynamic import DynamicTS

    mk = kernels.load("mhe")
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, jit=False)
    rng = np.random.default_rng(11)
    for trial in range(200):
        n = int(rng.integers(2, cfg.mhe.N + 1))
        v = rng.uniform(2.0, 20.0)
        xs = np.column_stack([v + rng.normal(0, 0.3, n + 1), rng.uniform(-0.1, 0.1, n + 1),
                              rng.uniform(-1, 1, n + 1)])
        us = np.column_stack([rng.normal(500, 2000, n), rng.uniform(-0.4, 0.4, n)])
        ys = xs[:, [0, 2]] + rng.normal(0, 0.05, (n + 1, 2))
        w = (rng.random(n + 1) > 0.1).astype(float)
        arrival, F_prior = xs[0] + rng.normal(0, 0.1, 3), rng.normal(0, 500)
        A, B = dyn.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
        qp = mhe.build(ys, us, w, xs, arrival, F_prior, matrices=(A, B))
        z = np.linalg.solve(qp.H, -qp.f)
        X_ref = (qp.M @ z + qp.c).reshape(-1, 3)
        X = np.empty((n + 1, 3))
        F = mk.banded_solve(ys, w, us, A, B, n, arrival, F_prior, mhe._q, mhe._r, mhe._p,
                            F_PRIOR_WEIGHT, X)
        np.testing.assert_allclose(X, X_ref, rtol=0, atol=1e-8, err_msg=f"trial {trial}")
        assert abs(F - z[3]) <= F_TOL
        # and the kernel's own model evaluation equals DynamicTS.matrices
        Ak, Bk = np.empty((n, 3, 3)), np.empty((n, 3, 2))
        box = dyn.premise_box
        p = cfg.vehicle
        mk.euler_matrices(us, xs, n, np.asarray(box.lower), np.asarray(box.upper), p.mass, p.inertia,
                          p.cornering_stiffness, p.cornering_stiffness, p.a, p.b, p.mu_nominal * p.g,
                          p.drag_factor, cfg.rates.Td, Ak, Bk)
        np.testing.assert_allclose(Ak, A, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(Bk, B, rtol=1e-14, atol=1e-15)


# -- plant block -------------------------------------------------------------------------------
@pytest.mark.parametrize(("tyre", "combined"), [("pacejka", False), ("linear", False),
                                                ("pacejka", True)])
@pytest.mark.parametrize("scale_grip", [False, True])
def test_plant_block_equals_the_float_rk4(cfg: Config, tyre: str, scale_grip: bool,
                                          combined: bool) -> None:
    from tsmpc.config import TyreParams
    from tsmpc.vehicle.plant import Plant

    tp = TyreParams(model=tyre, scale_grip_with_road=scale_grip, combined_slip=combined)
    a = Plant(cfg.vehicle, tp, cfg.rates.h, jit=True)
    b = Plant(cfg.vehicle, tp, cfg.rates.h, jit=False)
    assert a._kern is not None and b._kern is None
    rng = np.random.default_rng(5)
    for _ in range(300):
        # random states including the low-speed regularisation (v < v_floor) and reversing
        x = np.array([*rng.normal(0, 50, 2), rng.normal(0, 3), rng.uniform(-1, 20),
                      rng.normal(0, 0.1), rng.normal(0, 0.5)])
        u = (rng.normal(0, 4000), rng.uniform(-0.45, 0.45))
        mu, n = rng.uniform(0.0, 1.0), int(rng.integers(1, 20))
        np.testing.assert_allclose(a.step(x, u, mu, n), b.step(x, u, mu, n), rtol=1e-12, atol=1e-10)


def test_plant_block_non_finite_raises_as_before(cfg: Config) -> None:
    from tsmpc.errors import NonFiniteError
    from tsmpc.vehicle.plant import Plant

    p = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h, jit=True)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    with pytest.raises(NonFiniteError, match="non-finite input"):
        p.step(x, (np.nan, 0.0), 0.9, 10)
    with pytest.raises(NonFiniteError, match="non-finite state"):
        p.step(np.array([0.0, 0.0, 0.0, np.inf, 0.0, 0.0]), (0.0, 0.0), 0.9, 10)


def test_kernels_stand_down_when_the_model_differs(cfg: Config) -> None:
    """A model edited on the numpy side only must not be silently replaced by the kernel's."""
    from tsmpc.estimation.mhe_uio import MHEUIO
    from tsmpc.models.dynamic import DynamicTS
    from tsmpc.vehicle.plant import Plant

    class Scaled(DynamicTS):
        def matrices(self, z):
            A, B = super().matrices(z)
            return A, 1.01 * B

    dyn = Scaled(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, jit=True)
    assert mhe._kern is not None and mhe._kargs[-1] is False  # kernel solves, numpy evaluates
    ref = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, jit=False)
    for k in range(60):
        y, u = np.array([10.0 + 0.01 * k, 0.1]), np.array([800.0, 0.02])
        np.testing.assert_allclose(mhe.step(y, u).x, ref.step(y, u).x, rtol=0, atol=1e-8)

    class OtherPlant(Plant):  # (the model is one definition; a subclass may still change the Python side)
        def _step_floats(self, x, u, mu_road, n_steps):
            return 1.001 * super()._step_floats(x, u, mu_road, n_steps)

    assert OtherPlant(cfg.vehicle, cfg.tyre, cfg.rates.h, jit=True)._kern is None


# -- TS-LQR ------------------------------------------------------------------------------------
@pytest.mark.parametrize("changes", [{}, {"speed_feedback": False, "friction_estimate": "uio"},
                                     {"friction_compensation": False}])
def test_lqr_kernel_equals_the_numpy_step(cfg: Config, changes: dict) -> None:
    """Closed against the Pacejka plant (recorded) with random estimates mixed in (random data):
    starts, saturations, the frozen integrator, non-finite F̂ and estimates."""
    from tsmpc.control.ts_lqr import TSLQR
    from tsmpc.models.dynamic import DynamicTS
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.vehicle.plant import Plant

    st = replace(cfg.lqr, **changes) if changes else cfg.lqr
    Td = cfg.rates.Td
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    K = load_or_design_dynamic(cfg).K
    a = TSLQR(K, dyn, cfg.vehicle, st, Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth, jit=True)
    b = TSLQR(K, dyn, cfg.vehicle, st, Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth, jit=False)
    assert a._kern is not None and b._kern is None
    plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    rng = np.random.default_rng(2)
    x = np.array([0.0, 0.0, 0.0, 8.0, 0.0, 0.0])
    n_sat = 0
    for k in range(2500):
        if k % 700 == 0:
            a.reset()
            b.reset()
        if rng.random() < 0.1:  # random estimate anywhere in (and beyond) the box
            est = SimpleNamespace(x=np.array([rng.uniform(0, 22), rng.uniform(-0.15, 0.15),
                                              rng.uniform(-1.5, 1.5)]),
                                  F_fr=rng.choice([rng.normal(0, 800), np.nan]), F_fr_raw=rng.normal(0, 900))
        else:
            est = SimpleNamespace(x=x[3:6].copy(), F_fr=-300.0, F_fr_raw=-250.0)
        if k == 1234:
            est.x[1] = np.nan
        v_ref = 8.0 + 6.0 * np.sin(0.002 * k) + (15.0 if 1500 < k < 1530 else 0.0)
        w_ref = 0.3 * np.sin(0.004 * k)
        ca, cb = a.step(est, v_ref, w_ref), b.step(est, v_ref, w_ref)
        assert ca.saturated == cb.saturated
        assert ca.F_xR == pytest.approx(cb.F_xR, rel=1e-10, abs=1e-10)
        assert ca.delta == pytest.approx(cb.delta, rel=1e-10, abs=1e-12)
        assert ca.F_comp == cb.F_comp
        np.testing.assert_allclose(a._s, b._s, rtol=1e-10, atol=1e-12)
        n_sat += cb.saturated
        x = plant.step(x, (cb.F_xR, cb.delta), 0.9, cfg.rates.plant_per_inner)
    assert n_sat > 0


def test_mhe_kernel_with_zoh_matrices_evaluated_by_numpy(cfg: Config) -> None:
    """ZOH discretisation: numpy evaluates the window's matrices, the kernel solves."""
    from tsmpc.estimation.mhe_uio import MHEUIO
    from tsmpc.models.dynamic import Discretization, DynamicTS

    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td, method=Discretization.ZOH)
    a = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, np.array([8.0, 0.0, 0.0]), jit=True)
    b = MHEUIO(cfg.mhe, dyn, cfg.vehicle, cfg.rates.Td, np.array([8.0, 0.0, 0.0]), jit=False)
    assert a._kern is not None and a._kargs[-1] is False
    rng = np.random.default_rng(4)
    for k in range(120):
        y = np.array([8.0 + 0.02 * k, 0.2 * np.sin(0.05 * k)]) + rng.normal(0, 0.005, 2)
        u = np.array([900.0 + 50 * np.sin(0.1 * k), 0.04 * np.sin(0.05 * k)])
        ea, eb = a.step(y, u), b.step(y, u)
        assert ea.status == eb.status
        np.testing.assert_allclose(ea.x, eb.x, rtol=0, atol=1e-8)
        assert abs(ea.F_fr - eb.F_fr) <= F_TOL


def test_kernels_follow_per_axle_cornering_stiffness(cfg: Config) -> None:
    """C_f ≠ C_r (issue 14's vehicle parameters): every kernel stays on and equals numpy."""
    from tsmpc.control.ts_lqr import TSLQR
    from tsmpc.estimation.mhe_uio import MHEUIO
    from tsmpc.models.dynamic import DynamicTS
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.vehicle.plant import Plant

    veh = replace(cfg.vehicle, cornering_stiffness_front=31000.0, cornering_stiffness_rear=21000.0)
    Td = cfg.rates.Td
    dyn = DynamicTS(cfg.dynamic_box, veh, Td)
    K = load_or_design_dynamic(cfg).K
    pa, pb = Plant(veh, cfg.tyre, cfg.rates.h, jit=True), Plant(veh, cfg.tyre, cfg.rates.h, jit=False)
    ma, mb = (MHEUIO(cfg.mhe, dyn, veh, Td, np.array([9.0, 0.0, 0.0]), jit=j) for j in (True, False))
    la, lb = (TSLQR(K, dyn, veh, cfg.lqr, Td, jit=j) for j in (True, False))
    assert pa._kern is not None and ma._kern is not None and ma._kargs[-1] and la._kern is not None
    x = np.array([0.0, 0.0, 0.0, 9.0, 0.0, 0.0])
    u = np.zeros(2)
    for k in range(300):
        y = x[[3, 5]].copy()
        ea, eb = ma.step(y, u), mb.step(y, u)
        np.testing.assert_allclose(ea.x, eb.x, rtol=0, atol=1e-8)
        ca, cb = la.step(eb, 9.0, 0.2 * np.sin(0.02 * k)), lb.step(eb, 9.0, 0.2 * np.sin(0.02 * k))
        assert ca.F_xR == pytest.approx(cb.F_xR, rel=1e-10, abs=1e-10)
        assert ca.delta == pytest.approx(cb.delta, rel=1e-10, abs=1e-12)
        u = np.array([cb.F_xR, cb.delta])
        xa, x = pa.step(x, u, 0.9, 10), pb.step(x, u, 0.9, 10)
        np.testing.assert_allclose(xa, x, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("method", ["FZN", "REF", "ITER"])
def test_no_kernel_compiles_inside_a_timed_step(cfg: Config, method: str) -> None:
    """After ``kernels.load`` (which warms every signature), a closed-loop run adds no new
    specialisation to the step kernels: numba types read-only arrays apart, and a signature
    compiled lazily costs ≈ 1 s inside the first timed MPC/MHE step of a fresh install."""
    from numba.core.registry import CPUDispatcher

    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.simulator import simulate

    mods = {m: kernels.load(m) for m in ("mpc", "mhe", "lqr", "plant")}
    if mods["mpc"] is None:
        pytest.skip("kernels switched off")
    steps = {("mpc", "fast_step"), ("mpc", "_schedule"), ("mhe", "window_step"), ("lqr", "lqr_step"),
             ("lqr", "reference_gain"), ("plant", "rk4_block")}

    def signatures() -> dict[tuple[str, str], int]:
        return {(m, n): len(f.signatures) for m, mod in mods.items() for n, f in vars(mod).items()
                if isinstance(f, CPUDispatcher) and (m, n) in steps}

    before = signatures()
    assert len(before) == len(steps), "a step kernel was renamed: update this test"
    simulate(cfg, method, load_scenario(cfg, None), max_steps=5)
    assert signatures() == before
