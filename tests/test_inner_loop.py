"""Inner loop (SPEC §8, §9): TS-LQR + TS-MHE-UIO against the Pacejka plant, the MHE window QP
against an independent cvxpy + Clarabel formulation, bounds and bad measurements."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, replace
from tsmpc.control.ts_lqr import TSLQR, equilibrium
from tsmpc.estimation.mhe_uio import MHEUIO, EstimatorStatus
from tsmpc.models.dynamic import DynamicTS, continuous_matrices
from tsmpc.scenarios import SensorNoise
from tsmpc.synthesis.cache import load_or_design_dynamic
from tsmpc.vehicle.plant import Plant

Td = 0.01


@pytest.fixture(scope="module")
def dd(cfg: Config):
    return load_or_design_dynamic(cfg)


def _run(cfg: Config, dd, *, compensation: bool, mu_of_t, v_of_t, w_of_t, T: float, seed: int = 0):
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    lqr = TSLQR(dd.K, dyn, cfg.vehicle, replace(cfg.lqr, friction_compensation=compensation), Td)
    plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    noise = SensorNoise(cfg.noise, seed)
    x = np.array([0.0, 0.0, 0.0, v_of_t(0.0), 0.0, 0.0])
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, Td, x[3:6])
    u = np.zeros(2)
    rows = []
    for k in range(round(T / Td)):
        t = k * Td
        mu = mu_of_t(t)
        y = np.array([x[3], x[5]]) + noise.sample()[3:5]
        e = mhe.step(y, u)
        cmd = lqr.step(e, v_of_t(t), w_of_t(t))
        u = np.array([cmd.F_xR, cmd.delta])
        f_min, f_max = cfg.lqr.force_limits(cfg.vehicle)
        assert f_min - 1e-9 <= u[0] <= f_max + 1e-9
        assert abs(u[1]) <= cfg.lqr.delta_max + 1e-12
        rows.append([t, x[3], v_of_t(t), x[5], w_of_t(t), x[4], e.x[1], e.F_fr,
                     (mu - cfg.vehicle.mu_nominal) * cfg.vehicle.mass * cfg.vehicle.g])
        x = plant.step(x, u, mu, cfg.rates.plant_per_inner)
    return np.array(rows)


def test_equilibrium_is_a_fixed_point_of_the_nominal_model(cfg: Config) -> None:
    for v, w in [(5.0, 0.0), (10.0, 0.2), (15.0, -0.15)]:
        a, F, d = equilibrium(v, w, cfg.vehicle)
        A, B = continuous_matrices(v, d, cfg.vehicle)
        assert np.allclose(A @ [v, a, w] + B @ [F, d], 0.0, atol=1e-6)


def test_tracking_with_and_without_friction_compensation(cfg: Config, dd) -> None:
    """μ(road) = 0.9 vs μ_o = 0.5: a 2680 N disturbance. Steps and a ramp of the references."""
    kw = dict(mu_of_t=lambda t: 0.9, v_of_t=lambda t: 10.0 + min(max(t - 3, 0), 2.0),
              w_of_t=lambda t: 0.1 if t > 6 else 0.0, T=12.0)
    on = _run(cfg, dd, compensation=True, **kw)
    off = _run(cfg, dd, compensation=False, **kw)
    tail = slice(-200, None)  # the last 2 s, at constant references
    ev_on = np.abs(on[tail, 2] - on[tail, 1]).mean() / 12.0
    ew_on = np.abs(on[tail, 4] - on[tail, 3]).mean() / 0.1
    ev_off = np.abs(off[tail, 2] - off[tail, 1]).mean() / 12.0
    assert ev_on < 0.01 and ew_on < 0.01
    assert ev_off > 5 * ev_on  # without compensation the speed error is visibly larger


def test_slip_and_friction_estimates_on_the_paper_friction_levels(cfg: Config, dd) -> None:
    levels = [(0.0, 0.9), (4.0, 0.68), (8.0, 0.6), (12.0, 0.9)]

    def mu(t: float) -> float:
        return [m for t0, m in levels if t >= t0][-1]

    log = _run(cfg, dd, compensation=True, mu_of_t=mu, v_of_t=lambda t: 10.0,
               w_of_t=lambda t: 0.12 * np.sin(0.5 * t), T=16.0)
    t = log[:, 0]
    settled = np.zeros(t.size, dtype=bool)
    for t0, _ in levels:
        settled |= (t >= t0 + 1.0) & (t < t0 + 4.0)
    alpha_rmse = np.sqrt(np.mean((log[settled, 5] - log[settled, 6]) ** 2))
    assert alpha_rmse <= 0.003
    for t0, m in levels:
        seg = (t >= t0 + 1.0) & (t < t0 + 4.0)
        dist = abs(m - cfg.vehicle.mu_nominal) * cfg.vehicle.mass * cfg.vehicle.g
        f_rmse = np.sqrt(np.mean((log[seg, 7] - log[seg, 8]) ** 2))
        assert f_rmse <= 0.1 * dist, (m, f_rmse, dist)


def test_nan_measurements_are_rejected_and_counted(cfg: Config) -> None:
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, Td, np.array([10.0, 0.0, 0.0]))
    u = np.array([3400.0, 0.0])
    for _ in range(40):
        e = mhe.step(np.array([10.0, 0.0]), u)
    good = e.x.copy()
    bad = mhe.step(np.array([np.nan, 0.0]), u)
    assert bad.status == EstimatorStatus.REJECTED and mhe.n_rejected == 1
    assert np.all(np.isfinite(bad.x)) and abs(bad.x[0] - good[0]) < 0.05
    after = mhe.step(np.array([10.0, 0.0]), u)
    assert after.status == EstimatorStatus.OK


def test_mhe_window_matches_cvxpy(cfg: Config) -> None:
    """The window QP against an independent formulation: explicit states, dynamics as equality
    constraints, same scheduling, weights and bounds."""
    import cvxpy as cp

    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    mhe = MHEUIO(cfg.mhe, dyn, cfg.vehicle, Td)
    rng = np.random.default_rng(5)
    st = cfg.mhe
    for trial in range(5):
        n = st.N
        us = np.column_stack([rng.uniform(2000, 7000, n), rng.uniform(-0.1, 0.1, n)])
        xs = np.column_stack([rng.uniform(5, 15, n + 1), rng.uniform(-0.02, 0.02, n + 1),
                              rng.uniform(-0.3, 0.3, n + 1)])
        ys = xs[:, [0, 2]] + rng.normal(0, 0.01, (n + 1, 2))
        w = np.ones(n + 1)
        w[rng.integers(0, n + 1)] = 0.0  # one rejected sample
        arrival, F_prior = xs[0] + rng.normal(0, 0.05, 3), rng.uniform(-500, 2000)
        qp = mhe.build(ys, us, w, xs, arrival, F_prior)
        z = mhe._solve(qp)

        A, B = dyn.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
        X = cp.Variable((n + 1, 3))
        W = cp.Variable((n, 3))
        F = cp.Variable()
        q, r, p = 1 / np.array(st.Q), 1 / np.array(st.R), 1 / np.array(st.P)
        cons = [X[k + 1] == A[k] @ X[k] + B[k] @ us[k] - B[k][:, 0] * F + W[k] for k in range(n)]
        cons += [X >= np.tile(st.x_min, (n + 1, 1)), X <= np.tile(st.x_max, (n + 1, 1))]
        cost = (cp.sum(cp.multiply(p, cp.square(X[0] - arrival))) + 1e-10 * cp.square(F - F_prior)
                + cp.sum(cp.multiply(np.tile(q, (n, 1)), cp.square(W)))
                + cp.sum(cp.multiply(w[:, None] * r[None, :], cp.square(ys - X[:, [0, 2]]))))
        prob = cp.Problem(cp.Minimize(cost), cons)
        prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
        # Our QP omits the constant ‖·‖² terms: compare the minimisers, and the full objective
        # evaluated (with numpy) at our minimiser against cvxpy's optimal value.
        Xo = (qp.M @ z + qp.c).reshape(-1, 3)
        assert np.allclose(Xo, X.value, rtol=1e-6, atol=1e-6), trial
        assert z[3] == pytest.approx(F.value, rel=1e-6, abs=1e-3)
        def full(zz: np.ndarray, qp=qp, A=A, B=B, us=us, n=n, arrival=arrival,
                 F_prior=F_prior, w=w, ys=ys, p=p, q=q, r=r) -> float:
            """The textbook objective at the QP variables zz."""
            Xz = (qp.M @ zz + qp.c).reshape(-1, 3)
            Fz = zz[3]
            Wz = np.array([Xz[k + 1] - A[k] @ Xz[k] - B[k] @ us[k] + B[k][:, 0] * Fz for k in range(n)])
            return float(np.sum(p * (Xz[0] - arrival) ** 2) + 1e-10 * (Fz - F_prior) ** 2
                         + np.sum(q * Wz**2)
                         + np.sum(w[:, None] * r[None, :] * (ys - Xz[:, [0, 2]]) ** 2))

        ours = full(z)
        assert ours == pytest.approx(prob.value, rel=1e-6), trial
        # Our H, f are that objective up to a constant: the difference is the same elsewhere.
        quad = lambda zz, qp=qp: float(0.5 * zz @ qp.H @ zz + qp.f @ zz)  # noqa: E731
        z2 = z + rng.normal(0, 0.01, z.size)
        assert full(z2) - quad(z2) == pytest.approx(ours - quad(z), rel=1e-6, abs=1e-6), trial


def _discrete_reference_gain(cfg: Config, z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """N̄ = [C (I − A_d − B_d K₅)⁻¹ B_d]⁻¹ from the Euler plant + filter model of DynamicTS."""
    Ad, Bd = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td).matrices(z)
    lam = cfg.dynamic_lmi.filter_bandwidth
    A5 = np.zeros((5, 5))
    A5[:3, :3], A5[:3, 3:] = Ad, Bd  # u = filter state
    A5[3:, 3:] = (1.0 - lam * Td) * np.eye(2)
    B5 = np.zeros((5, 2))
    B5[3:, :] = lam * Td * np.eye(2)
    C = np.zeros((2, 5))
    C[0, 0] = C[1, 2] = 1.0
    return np.linalg.inv(C @ np.linalg.solve(np.eye(5) - A5 - B5 @ K[:, :5], B5))


def test_lqr_law_matches_vectorised_blend(cfg: Config, dd) -> None:
    """The float fast path of TSLQR.step equals the textbook law u = N̄ r + Σμ_i(ϑ)K_i x with the
    memberships of SchedulingBox (numpy) and N̄ from the discrete (Euler) model, inside and
    outside the premise box; the speed-error feedback adds M (v_ref − v̂)/τ."""
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    rng = np.random.default_rng(3)
    lo, hi = dyn.premise_box.lower, dyn.premise_box.upper
    for _ in range(50):
        z = lo + (hi - lo) * rng.uniform(-0.2, 1.2, 3)
        ref = np.asarray(dyn.premise_box.memberships(z))
        fast = TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td)._memberships(*z)
        np.testing.assert_allclose(fast, ref, atol=1e-14)
    for fb in (False, True):
        st = replace(cfg.lqr, friction_compensation=False, speed_feedback=fb)
        lqr = TSLQR(dd.K, dyn, cfg.vehicle, st, Td)

        class E:
            x = np.array([9.7, 0.01, 0.12])
            F_fr = 0.0
            F_fr_raw = 0.0

        v_ref, w_ref = 10.0, 0.1
        cmd = lqr.step(E, v_ref, w_ref)  # first step: bumpless start
        f0 = lqr._f.copy()
        cmd = lqr.step(E, v_ref, w_ref)
        z = np.array([f0[1], E.x[0], E.x[1]])
        K = np.tensordot(dyn.premise_box.memberships(z), dd.K, axes=(0, 0))
        N = _discrete_reference_gain(cfg, z, K)
        x = np.array([*E.x, *f0, Td * (w_ref - E.x[2])])
        u_f = N @ [v_ref, w_ref] + K @ x
        a = lqr._a
        np.testing.assert_allclose(lqr._f, a * f0 + (1 - a) * u_f, rtol=1e-9)
        F_add = cfg.vehicle.mass * (v_ref - E.x[0]) / st.speed_time_constant if fb else 0.0
        assert cmd.F_xR == pytest.approx(f0[0] + F_add, rel=1e-12)
        assert cmd.delta == pytest.approx(f0[1], rel=1e-12)


def test_static_reference_gain_zero_steady_state_error(cfg: Config, dd) -> None:
    """SPEC §8: with u = N̄ r + K x, constant (v, ω) references are tracked with zero steady-state
    error on the nominal model and the integrator rests at 0. Independent check: iterate the
    discrete Euler loop (DynamicTS matrices, filter, integrator) frozen at the scheduling point to
    its fixed point, and compare its steady state with :func:`equilibrium` (nonlinear solve)."""
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    lam = cfg.dynamic_lmi.filter_bandwidth
    lqr = TSLQR(dd.K, dyn, cfg.vehicle, cfg.lqr, Td)
    for v_ref, w_ref in ((3.0, 0.0), (8.0, 0.25), (12.0, -0.1), (17.0, 0.05)):
        a_eq, F_eq, d_eq = equilibrium(v_ref, w_ref, cfg.vehicle, iters=30)
        z = np.array([d_eq, v_ref, a_eq])
        K = np.tensordot(dyn.premise_box.memberships(z), dd.K, axes=(0, 0))
        N = lqr.reference_gain(d_eq, v_ref, K)
        np.testing.assert_allclose(N, _discrete_reference_gain(cfg, z, K), rtol=1e-8)
        Ad, Bd = dyn.matrices(z)
        x = np.zeros(6)  # [v, α, ω, F_f, δ_f, ζ], from rest
        for _ in range(20000):  # 200 s: the slowest closed-loop mode is a few seconds
            u = N @ [v_ref, w_ref] + K @ x
            x = np.concatenate([Ad @ x[:3] + Bd @ x[3:5], x[3:5] + lam * Td * (u - x[3:5]),
                                [x[5] + Td * (w_ref - x[2])]])
        assert x[0] == pytest.approx(v_ref, abs=1e-8)
        assert x[2] == pytest.approx(w_ref, abs=1e-9)
        assert x[5] == pytest.approx(0.0, abs=1e-6)  # the integrator is not needed at steady state
        np.testing.assert_allclose(x[1:5], [a_eq, w_ref, F_eq, d_eq], rtol=1e-6, atol=1e-9)
