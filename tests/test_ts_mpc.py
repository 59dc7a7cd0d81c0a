"""TS-MPC (SPEC §7): condensing against the recursion, QP solutions against cvxpy + Clarabel,
closed-loop convergence of FZN/REF/ITER, failure handling."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tsmpc.config import Config, SchedulingMode, replace
from tsmpc.control.ts_mpc import TSMPC, MPCStatus, condense
from tsmpc.models.kinematic import A_c, B_c, KinematicTS, nonlinear_step, sinc
from tsmpc.synthesis.cache import load_or_design_kinematic

Tc, N = 0.1, 40


@pytest.fixture(scope="module")
def design(cfg: Config):
    return load_or_design_kinematic(cfg)


def _mpc(cfg: Config, design, mode: str = "ref", **changes) -> TSMPC:
    settings = replace(cfg.mpc, **changes) if changes else cfg.mpc
    return TSMPC(settings, KinematicTS(cfg.kinematic_box, cfg.rates.Tc), design.P, design.S,
                 mode=SchedulingMode(mode))


def test_condensed_prediction_and_cost_equal_the_recursion() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        om, vd, eth = rng.uniform(-1.4, 1.4, N), rng.uniform(1, 18, N), rng.uniform(-0.09, 0.09, N)
        x0 = rng.normal(size=3) * [2, 2, 0.1]
        up, r, dU = rng.normal(size=2), rng.normal(size=(N, 2)), rng.normal(size=(N, 2))
        q, R = rng.uniform(0.1, 10, 3), rng.uniform(1e-5, 5, 2)
        M = rng.normal(size=(3, 3))
        P = M @ M.T + np.eye(3)
        qp = condense(x0, up, r, om * Tc, vd * sinc(eth) * Tc, Tc, q, P, R)
        x, u, J, X = x0.copy(), up.copy(), x0 @ (q * x0), []
        for i in range(N):
            u = u + dU[i]
            x = A_c(om[i], vd[i], eth[i], Tc) @ x + B_c(Tc) @ (u - r[i])
            X.append(x)
            J += dU[i] @ (R * dU[i]) + (x @ (q * x) if i < N - 1 else x @ P @ x)
        z = dU.T.reshape(-1)
        Xp = (qp.x_aff + qp.G @ z).reshape(3, N).T
        assert np.allclose(Xp, np.array(X), atol=1e-10 * (1 + np.abs(X).max()))
        assert z @ qp.H @ z + 2 * qp.f @ z + qp.c0 == pytest.approx(J, rel=1e-10)


def _reference_solution(cfg: Config, design, x0, up, vd, wd, soft: bool):
    """The same QCQP written independently: explicit states, A_c(ρ_i) from the model module, the
    REF start-up schedule (ω_d, v_d, ê_θ = [e_θ0, 0, …]), clipped into the box."""
    import cvxpy as cp

    st = cfg.mpc
    box = cfg.kinematic_box
    eth = np.zeros(N)
    eth[0] = x0[2]
    s_lo = float(sinc(box.e_theta[1]))  # box bounds are in rad
    om_c = np.clip(wd, *box.omega)
    vd_c = np.clip(vd, *box.v_d)
    sc = np.clip(sinc(eth), s_lo, 1.0)
    # States as explicit affine maps of the inputs, propagated step by step with the A_c(ρ_i)
    # matrices (no condensing formula); equality-constrained states with cond ≈ 1e9 would leave
    # Clarabel's states inaccurate at 1e-6.
    dU = cp.Variable(2 * N)  # [Δv_0, Δω_0, Δv_1, …]
    Lm = np.kron(np.tri(N), np.eye(2))
    Uc, Um = np.tile(up, N), Lm  # U = Uc + Um ΔU
    Q, _R = np.diag(st.Q), np.diag(st.R)
    F, E = x0.copy(), np.zeros((3, 2 * N))
    rows_c, rows_m = [], []
    for i in range(N):
        A = np.array([[1, om_c[i] * Tc, 0], [-om_c[i] * Tc, 1, vd_c[i] * sc[i] * Tc], [0, 0, 1]])
        r = np.array([vd[i] * np.cos(eth[i]), wd[i]])
        Bi = B_c(Tc)
        F = A @ F + Bi @ (Uc[2 * i:2 * i + 2] - r)
        E = A @ E + Bi @ Um[2 * i:2 * i + 2]
        rows_c.append(F.copy())
        rows_m.append(E.copy())
    Xc, Xm = np.array(rows_c), np.array(rows_m)  # (N, 3), (N, 3, 2N)
    sq = np.sqrt(np.array(st.Q))
    inner = (Xc[:-1] * sq).reshape(-1) + (Xm[:-1] * sq[:, None]).reshape(-1, 2 * N) @ dU
    X = Xc[-1] + Xm[-1] @ dU
    Lp = np.linalg.cholesky(design.P)
    cost = (x0 @ Q @ x0 + cp.sum_squares(inner) + cp.sum_squares(Lp.T @ X)
            + cp.sum_squares(cp.multiply(np.tile(np.sqrt(st.R), N), dU)))
    U = Uc + Um @ dU
    cons = [U >= np.tile(st.u_min, N), U <= np.tile(st.u_max, N), cp.abs(dU) <= np.tile(st.du_max, N)]
    sig = cp.Variable(nonneg=True)
    if soft:
        cons.append(cp.norm(np.linalg.cholesky(design.S).T @ X) <= 1 + sig)
        cost += st.soft_penalty * sig
    else:
        cons.append(cp.quad_form(X, design.S) <= 1)
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11)
    if prob.status == "optimal_inaccurate":  # the tight tolerances stalled: default ones
        prob.solve(solver=cp.CLARABEL)
    return prob


def _instances(n: int, seed: int):
    rng = np.random.default_rng(seed)
    for k in range(n):
        scale = [0.05, 0.5, 3.0, 20.0][k % 4]  # inactive … terminal active … infeasible
        x0 = rng.normal(size=3) * np.array([1.0, 1.0, 0.05]) * scale
        x0[2] = np.clip(x0[2], -0.5, 0.5)
        vd = np.clip(rng.uniform(2, 16) + np.cumsum(rng.normal(0, 0.3, N)), 0.5, 18)
        wd = np.clip(rng.uniform(-0.3, 0.3) + np.cumsum(rng.normal(0, 0.02, N)), -1.4, 1.4)
        up = np.array([np.clip(vd[0] + rng.normal(0, 1), 0, 18),
                       np.clip(wd[0] + rng.normal(0, 0.1), -1.4, 1.4)])
        yield x0, up, vd, wd


def _check_instance(cfg: Config, design, x0, up, vd, wd) -> str:
    mpc = _mpc(cfg, design, "ref")
    res = mpc.step(x0, up, SimpleNamespace(v=vd, omega=wd))
    assert res.status != MPCStatus.FALLBACK
    st = cfg.mpc
    xN = res.x_pred[-1]
    # Constraints of what we return, checked directly.
    assert np.all(res.u_pred >= np.array(st.u_min) - 1e-7)
    assert np.all(res.u_pred <= np.array(st.u_max) + 1e-7)
    assert np.all(np.abs(res.du) <= np.array(st.du_max) + 1e-7)
    prob = _reference_solution(cfg, design, x0, up, vd, wd, soft=False)
    if prob.status == "optimal":
        assert res.status == MPCStatus.OPTIMAL
        assert xN @ design.S @ xN <= 1 + 1e-7
        assert res.cost == pytest.approx(prob.value, rel=1e-6, abs=1e-9)
        return "optimal"
    if prob.status != "infeasible":
        # The reference itself is inaccurate on this borderline instance: our plan must then
        # be a verified feasible point at least as good as the reference's value.
        if res.status == MPCStatus.OPTIMAL:
            assert xN @ design.S @ xN <= 1 + 1e-7
            if prob.value is not None and np.isfinite(prob.value):
                assert res.cost <= prob.value * (1 + 1e-6) + 1e-9
        return "undecided"
    assert res.status == MPCStatus.SOFT
    prob = _reference_solution(cfg, design, x0, up, vd, wd, soft=True)
    ours = res.cost + st.soft_penalty * max(0.0, np.sqrt(xN @ design.S @ xN) - 1)
    assert ours == pytest.approx(prob.value, rel=1e-6)
    return "soft"


def test_qp_matches_cvxpy_on_a_few_instances(cfg: Config, design) -> None:
    kinds = [_check_instance(cfg, design, *inst) for inst in _instances(24, seed=3)]
    assert {"optimal", "soft"} <= set(kinds) and kinds.count("undecided") <= 1


@pytest.mark.slow
def test_qp_matches_cvxpy_on_200_random_instances(cfg: Config, design) -> None:
    """200 instances (500 cost 21 s of CPU of the suite for the same spread of cases: a quarter at
    each scale, inactive to infeasible)."""
    kinds = [_check_instance(cfg, design, *inst) for inst in _instances(200, seed=7)]
    # measured: 187 optimal, 9 soft, 4 undecided
    assert kinds.count("soft") > 4 and kinds.count("optimal") > 150 and kinds.count("undecided") <= 6


def test_terminal_cuts_make_the_ellipsoid_exact(cfg: Config, design) -> None:
    """An instance where the unconstrained optimum leaves the terminal set: the returned plan
    ends on its boundary (active), within the tolerance."""
    mpc = _mpc(cfg, design, "ref")
    rng = np.random.default_rng(11)
    active = 0
    for x0, up, vd, wd in _instances(40, seed=11):
        res = mpc.step(x0, up, SimpleNamespace(v=vd, omega=wd))
        mpc.reset()
        if res.status == MPCStatus.OPTIMAL:
            lvl = res.x_pred[-1] @ design.S @ res.x_pred[-1]
            assert lvl <= 1 + 1e-9
            active += lvl > 1 - 1e-6
    assert active > 0
    del rng


def test_an_inexact_socp_answer_is_rechecked_and_polished_onto_the_ellipsoid(
        cfg: Config, design, monkeypatch) -> None:
    """Every binding instance goes to the SOCP (no cuts), whose answer is pushed 1e-8 outside the
    terminal set — what an interior-point solver at a looser tolerance returns. The step must not
    return it as OPTIMAL: it is re-checked and re-solved inside the ellipsoid at the same cost."""
    from dataclasses import replace as dc_replace

    import tsmpc.control.ts_mpc as ts_mpc

    monkeypatch.setattr(ts_mpc, "MAX_CUTS", 0)
    exact = _run_instances(cfg, design)
    real = ts_mpc.solve_qcqp_clarabel
    pushed = 0

    def inexact(H, f, dlb, dub, L, bl, bu, S, cN, GN, soft_penalty=None, radius=1.0):
        nonlocal pushed
        res = real(H, f, dlb, dub, L, bl, bu, S, cN, GN, soft_penalty=soft_penalty, radius=radius)
        if soft_penalty is None and res.status == ts_mpc.QPStatus.OPTIMAL:
            g = GN.T @ (S @ (cN + GN @ res.z))
            res = dc_replace(res, z=res.z + 0.5e-8 * g / (g @ g))  # level + ≈ 1e-8
            pushed += 1
        return res

    monkeypatch.setattr(ts_mpc, "solve_qcqp_clarabel", inexact)
    polished = _run_instances(cfg, design)
    assert pushed > 0
    for (st0, _, J0), (st1, lvl1, J1) in zip(exact, polished, strict=True):
        assert st1 == st0
        if st1 == MPCStatus.OPTIMAL:
            assert lvl1 <= 1 + 1e-9
            assert J1 == pytest.approx(J0, rel=1e-6, abs=1e-9)


def _run_instances(cfg: Config, design) -> list[tuple[MPCStatus, float, float]]:
    mpc = _mpc(cfg, design, "ref")
    out = []
    for x0, up, vd, wd in _instances(60, seed=11):
        res = mpc.step(x0, up, SimpleNamespace(v=vd, omega=wd))
        mpc.reset()
        out.append((res.status, float(res.x_pred[-1] @ design.S @ res.x_pred[-1]), res.cost))
    return out


@pytest.mark.parametrize("mode", ["fzn", "ref", "iter"])
def test_closed_loop_converges_along_the_paper_reference(cfg: Config, design, mode: str,
                                                         paper_reference_path) -> None:
    from tsmpc.planning.paper_format import load_paper_reference

    ref = load_paper_reference(paper_reference_path)
    mpc = _mpc(cfg, design, mode)
    e = np.array([0.0, 2.0, 0.1])
    u = np.array([ref.v[0], ref.omega[0]])
    errs = []
    for k in range(400):
        w = ref.window(k, N + 1)
        res = mpc.step(e, u, w)
        assert res.status != MPCStatus.FALLBACK
        u = res.u
        e = nonlinear_step(e, u, w.v[0], w.omega[0], Tc)
        errs.append(np.abs(e[:2]).max())
    # From 2 m / 0.1 rad to within 1 cm, and it stays there.
    assert max(errs[150:]) < 0.01


def test_bad_inputs_give_a_flagged_fallback_not_an_exception(cfg: Config, design) -> None:
    mpc = _mpc(cfg, design, "ref")
    ref = SimpleNamespace(v=np.full(N, 10.0), omega=np.zeros(N))
    ok = mpc.step(np.array([0.1, 0.1, 0.0]), np.array([10.0, 0.0]), ref)
    assert ok.status == MPCStatus.OPTIMAL
    bad = mpc.step(np.array([np.nan, 0.0, 0.0]), np.array([10.0, 0.0]), ref)
    assert bad.status == MPCStatus.FALLBACK and not bad.success
    assert np.allclose(bad.u, ok.u_pred[1])  # the shifted previous plan
    short = mpc.step(np.zeros(3), np.array([10.0, 0.0]), SimpleNamespace(v=np.ones(3), omega=np.zeros(3)))
    assert short.status == MPCStatus.FALLBACK


@pytest.mark.parametrize("mode", ["fzn", "ref", "iter"])
def test_compiled_step_decides_like_the_numpy_path_on_garbage(cfg: Config, design, mode: str) -> None:
    """The compiled step does the input checks, the clipping and the previous plan's schedule
    itself (issue 25: fewer Python steps): on good and bad inputs alike its status and plan equal
    the numpy path's (an infinite u_prev is clipped into the box, not refused, as np.clip does)."""
    fast, slow = _mpc(cfg, design, mode), _mpc(cfg, design, mode)
    slow._kern = None
    good = SimpleNamespace(v=np.full(N + 1, 10.0), omega=np.full(N + 1, 0.05))
    nan_ref = SimpleNamespace(v=np.r_[np.full(N - 1, 10.0), np.nan], omega=np.zeros(N))
    cases = [((0.1, 0.2, 0.01), (10.0, 0.0), good), ((0.0, 0.1, 0.0), (np.inf, 0.05), good),
             ((0.0, 0.1, 0.0), (10.0, np.nan), good), ((np.inf, 0.0, 0.0), (10.0, 0.0), good),
             ((0.0, 0.05, 0.0), (10.0, 0.0), nan_ref), ((0.2, -0.1, 0.02), (10.0, 0.05), good),
             ((0.0, 0.0, 0.0), (10.0, 0.0), SimpleNamespace(v=np.ones(3), omega=np.zeros(3))),
             ((0.3, 0.0, -0.01), (9.0, -0.01), good)]
    for e, u, ref in cases:
        a, b = fast.step(np.array(e), np.array(u), ref), slow.step(np.array(e), np.array(u), ref)
        assert a.status == b.status, (e, u)
        np.testing.assert_allclose(a.u_pred, b.u_pred, rtol=1e-7, atol=1e-9, err_msg=str((e, u)))
