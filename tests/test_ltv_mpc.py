"""LTV-MPC (issue 26 baseline): the linearisation against the nonlinear model's Jacobian, the QP's
answer against an independent cvxpy + Clarabel formulation on random instances (compiled fast path
and numpy path), and what separates it from the TS-MPC's REF mode."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tsmpc.config import Config, Method
from tsmpc.control.ltv_mpc import LTVMPC, linearisation
from tsmpc.control.ts_mpc import TSMPC, MPCStatus
from tsmpc.models.kinematic import A_c, B_c, KinematicTS, nonlinear_step
from tsmpc.synthesis.cache import load_or_design_kinematic

Tc, N = 0.1, 40


@pytest.fixture(scope="module")
def design(cfg: Config):
    return load_or_design_kinematic(cfg)


def _ltv(cfg: Config, design, jit: bool | None = None) -> LTVMPC:
    return LTVMPC(cfg.mpc, KinematicTS(cfg.kinematic_box, Tc), design.P, design.S, jit=jit)


def test_linearisation_is_the_jacobian_along_the_reference() -> None:
    """A_i = ∂x⁺/∂x and B = ∂x⁺/∂u of the nonlinear Euler error model at (x = 0, u = r), by
    central differences (step 1e-6: truncation O(h²) ≈ 1e-12, rounding ≈ 1e-10)."""
    rng = np.random.default_rng(1)
    v_d, w_d = rng.uniform(1, 20, 5), rng.uniform(-1, 1, 5)
    c, s, r = linearisation(v_d, w_d, Tc)
    h = 1e-6
    for i in range(5):
        def f(x, u, i=i):
            return nonlinear_step(x, u, v_d[i], w_d[i], Tc)
        J = np.column_stack([(f(h * e, r[i]) - f(-h * e, r[i])) / (2 * h) for e in np.eye(3)])
        Ju = np.column_stack([(f(np.zeros(3), r[i] + h * e) - f(np.zeros(3), r[i] - h * e)) / (2 * h)
                              for e in np.eye(2)])
        A = np.array([[1, c[i], 0], [-c[i], 1, s[i]], [0, 0, 1]])
        np.testing.assert_allclose(J, A, atol=1e-8)
        np.testing.assert_allclose(Ju, B_c(Tc), atol=1e-8)
        np.testing.assert_allclose(f(np.zeros(3), r[i]), 0.0, atol=1e-15)  # r is the equilibrium


def _cvxpy_ltv(cfg: Config, design, x0, up, vd, wd, soft: bool):
    """The LTV-MPC written independently: z = [Δu_0; Δu_1; …], inputs U_j = u_prev + Σ_{l≤j} Δu_l,
    states as affine maps x_j = F_j + E_j z propagated one step at a time with
    A_c(ω_d, v_d, e_θ = 0) from the model module and B_c (no condensing formula)."""
    import cvxpy as cp

    st = cfg.mpc
    z = cp.Variable(2 * N)
    Sel = np.kron(np.tri(N), np.eye(2))  # U = tile(u_prev) + Sel z
    F, E = x0.astype(float).copy(), np.zeros((3, 2 * N))
    sqQ, sqR = np.sqrt(np.array(st.Q)), np.sqrt(np.array(st.R))
    stage_F, stage_E = [], []
    for j in range(N):
        A = A_c(wd[j], vd[j], 0.0, Tc)
        F = A @ F + B_c(Tc) @ (up - np.array([vd[j], wd[j]]))
        E = A @ E + B_c(Tc) @ Sel[2 * j:2 * j + 2]
        stage_F.append(F.copy())
        stage_E.append(E.copy())
    Fs = np.concatenate([sqQ * f for f in stage_F[:-1]])
    Es = np.vstack([sqQ[:, None] * e for e in stage_E[:-1]])
    xN = stage_F[-1] + stage_E[-1] @ z
    cost = (x0 @ np.diag(st.Q) @ x0 + cp.sum_squares(Fs + Es @ z)
            + cp.sum_squares(np.linalg.cholesky(design.P).T @ xN)
            + cp.sum_squares(cp.multiply(np.tile(sqR, N), z)))
    U = np.tile(up, N) + Sel @ z
    cons = [cp.abs(z) <= np.tile(st.du_max, N), U >= np.tile(st.u_min, N), U <= np.tile(st.u_max, N)]
    if soft:
        sig = cp.Variable(nonneg=True)
        cons.append(cp.norm(np.linalg.cholesky(design.S).T @ xN) <= 1 + sig)
        cost += st.soft_penalty * sig
    else:
        cons.append(cp.quad_form(xN, design.S) <= 1)
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11)
    if prob.status == "optimal_inaccurate":  # the tight tolerances stalled: default ones
        prob.solve(solver=cp.CLARABEL)
    return prob


def _instances(n: int, seed: int):
    """Random problems from inactive constraints to an infeasible terminal set; ω_d up to ±2 rad/s
    and v_d up to 25 m/s, beyond the TS box (the LTV model has none)."""
    rng = np.random.default_rng(seed)
    for k in range(n):
        scale = [0.05, 0.5, 3.0, 20.0][k % 4]
        x0 = rng.normal(size=3) * np.array([1.0, 1.0, 0.05]) * scale
        x0[2] = np.clip(x0[2], -0.5, 0.5)
        vd = np.clip(rng.uniform(2, 16) + np.cumsum(rng.normal(0, 0.3, N)), 0.5, 25)
        wd = np.clip(rng.uniform(-0.3, 0.3) + np.cumsum(rng.normal(0, 0.03, N)), -2, 2)
        up = np.array([np.clip(vd[0] + rng.normal(0, 1), 0, 18),
                       np.clip(wd[0] + rng.normal(0, 0.1), -1.4, 1.4)])
        yield x0, up, vd, wd


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
@pytest.mark.parametrize("jit", [True, False])
def test_qp_answer_matches_cvxpy_clarabel(cfg: Config, design, jit: bool) -> None:
    """Optimal instances: same cost (rel 1e-6) and a feasible plan; infeasible terminal set: the
    soft answer's exactly penalised cost equals the soft reference's."""
    st = cfg.mpc
    kinds = []
    for x0, up, vd, wd in _instances(16, seed=8):
        mpc = _ltv(cfg, design, jit)
        res = mpc.step(x0, up, SimpleNamespace(v=vd, omega=wd))
        assert res.status != MPCStatus.FALLBACK
        assert np.all(res.u_pred >= np.array(st.u_min) - 1e-7)
        assert np.all(res.u_pred <= np.array(st.u_max) + 1e-7)
        assert np.all(np.abs(res.du) <= np.array(st.du_max) + 1e-7)
        xN = res.x_pred[-1]
        prob = _cvxpy_ltv(cfg, design, x0, up, vd, wd, soft=False)
        if prob.status == "optimal":
            assert res.status == MPCStatus.OPTIMAL
            assert xN @ design.S @ xN <= 1 + 1e-7
            assert res.cost == pytest.approx(prob.value, rel=1e-6, abs=1e-9)
            kinds.append("optimal")
        elif prob.status == "infeasible":
            assert res.status == MPCStatus.SOFT
            ref = _cvxpy_ltv(cfg, design, x0, up, vd, wd, soft=True)
            ours = res.cost + st.soft_penalty * max(0.0, float(np.sqrt(xN @ design.S @ xN)) - 1)
            assert ours == pytest.approx(ref.value, rel=1e-6)
            kinds.append("soft")
        else:
            kinds.append(prob.status)
        # Predictions follow the linearised model exactly.
        x = x0.copy()
        for j in range(N):
            x = A_c(wd[j], vd[j], 0.0, Tc) @ x + B_c(Tc) @ (res.u_pred[j] - [vd[j], wd[j]])
            np.testing.assert_allclose(res.x_pred[j + 1], x, atol=1e-8 * (1 + np.abs(x).max()))
    assert kinds.count("optimal") >= 8 and kinds.count("soft") >= 2, kinds


def test_ltv_is_ref_at_start_up_inside_the_box_and_differs_outside(cfg: Config, design) -> None:
    """At start-up with e_θ = 0 the REF schedule is (ω_d, v_d, sinc 0) and r = [v_d, ω_d]: the
    linearisation along the reference. Outside the box REF clips ρ, the LTV model does not."""
    model = KinematicTS(cfg.kinematic_box, Tc)
    ref_mpc = TSMPC(cfg.mpc, model, design.P, design.S, mode=Method.REF)
    x0, up = np.array([0.3, -0.4, 0.0]), np.array([10.0, 0.1])
    inside = SimpleNamespace(v=np.full(N, 10.0), omega=np.full(N, 0.1))
    a = _ltv(cfg, design).step(x0, up, inside)
    b = ref_mpc.step(x0, up, inside)
    np.testing.assert_allclose(a.u_pred, b.u_pred, atol=1e-10)
    ref_mpc.reset()
    outside = SimpleNamespace(v=np.full(N, 25.0), omega=np.full(N, 0.1))
    a = _ltv(cfg, design).step(x0, np.array([18.0, 0.1]), outside)
    b = ref_mpc.step(x0, np.array([18.0, 0.1]), outside)
    assert b.n_clipped > 0 and a.n_clipped == 0
    assert np.max(np.abs(a.x_pred - b.x_pred)) > 1e-3


def test_bad_inputs_give_the_fallback(cfg: Config, design) -> None:
    mpc = _ltv(cfg, design)
    ref = SimpleNamespace(v=np.full(N, 10.0), omega=np.zeros(N))
    ok = mpc.step(np.array([0.1, 0.1, 0.0]), np.array([10.0, 0.0]), ref)
    bad = mpc.step(np.array([0.1, np.nan, 0.0]), np.array([10.0, 0.0]), ref)
    assert ok.status == MPCStatus.OPTIMAL and bad.status == MPCStatus.FALLBACK
    assert np.allclose(bad.u, ok.u_pred[1])
    assert mpc.mode is Method.LTV and not Method.LTV.is_ts_mpc
