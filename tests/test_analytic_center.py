"""The analytic centre of LMIs (tsmpc.synthesis.analytic_center) against known centres and an
independent cvxpy + Clarabel formulation (max Σ log det), and its use for the published run's
feasibility design: the same gains in any scaling, certificates recomputed."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, replace
from tsmpc.errors import ConfigError, SolverError
from tsmpc.synthesis.analytic_center import AffineLMI, analytic_center, log_det_barrier


def _scalar(c0: float, c1: float) -> AffineLMI:
    """c0 + c1 x ≥ 0 as a 1 × 1 LMI in one variable."""
    return AffineLMI(np.array([[c0]]), np.array([[[c1]]]))


def test_centre_of_an_interval_and_of_a_disk() -> None:
    res = analytic_center([_scalar(0.0, 1.0), _scalar(1.0, -1.0)], np.array([0.9]))  # 0 ≤ x ≤ 1
    assert res.x == pytest.approx([0.5], abs=1e-8)
    # x ≥ 0 once and x ≤ 1 twice: φ = −log x − 2 log(1 − x), minimised at x = 1/3
    res = analytic_center([_scalar(0.0, 1.0), _scalar(1.0, -1.0), _scalar(1.0, -1.0)], np.array([0.5]))
    assert res.x == pytest.approx([1.0 / 3.0], abs=1e-8)
    # the disk x1² + x2² ≤ 1 as [[1, x1, x2], [x1, 1, 0], [x2, 0, 1]] ⪰ 0, shifted by (0.3, -0.2)
    F = np.zeros((2, 3, 3))
    F[0, 0, 1] = F[0, 1, 0] = 1.0
    F[1, 0, 2] = F[1, 2, 0] = 1.0
    F0 = np.eye(3) - 0.3 * F[0] + 0.2 * F[1]
    res = analytic_center([AffineLMI(F0, F)], np.array([0.0, 0.0]))
    assert res.x == pytest.approx([0.3, -0.2], abs=1e-8)


def test_centre_matches_cvxpy_max_log_det_on_random_lmis() -> None:
    """Two random 4 × 4 LMIs in 5 variables, bounded (a trace bound block), strictly feasible at 0."""
    cp = pytest.importorskip("cvxpy")
    rng = np.random.default_rng(7)
    n, d = 5, 4
    lmis = []
    for _ in range(2):
        F = rng.normal(size=(n, d, d))
        F = 0.5 * (F + np.swapaxes(F, 1, 2))
        lmis.append(AffineLMI(np.eye(d) * 3.0, F))
    box = np.zeros((n, 2 * n, 2 * n))  # −1 ≤ x_j ≤ 1 as a diagonal block: bounded
    for j in range(n):
        box[j, j, j], box[j, n + j, n + j] = 1.0, -1.0
    lmis.append(AffineLMI(np.eye(2 * n), box))
    res = analytic_center(lmis, np.zeros(n))
    x = cp.Variable(n)
    terms = []
    for lmi in lmis:
        M = lmi.F0 + sum(x[j] * lmi.F[j] for j in range(n))
        terms.append(cp.log_det(0.5 * (M + M.T)))
    cp.Problem(cp.Maximize(sum(terms))).solve(solver=cp.CLARABEL)
    np.testing.assert_allclose(res.x, x.value, atol=1e-4)  # Clarabel: exp-cone tolerance
    assert log_det_barrier(lmis, res.x) <= log_det_barrier(lmis, x.value) + 1e-9


def test_bad_starts_and_unbounded_sets_raise() -> None:
    with pytest.raises(SolverError, match="not strictly feasible"):
        analytic_center([_scalar(0.0, 1.0), _scalar(1.0, -1.0)], np.array([1.5]))
    with pytest.raises(SolverError):  # x ≥ 0 only: the barrier has no minimiser
        analytic_center([_scalar(0.0, 1.0)], np.array([1.0]), max_iter=50)


# --- the published run's feasibility design -----------------------------------------------------

def _problem(cfg: Config, xs: np.ndarray, us: np.ndarray):
    from tsmpc.synthesis.paper_as_run import _scaled_problem, vertex_models

    A, B = vertex_models(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td, cfg.dynamic_lmi.filter_bandwidth)
    return A, B, _scaled_problem(A, B, cfg.dynamic_lmi, xs, us)


def test_the_preset_keeps_the_analytic_centre_and_it_certifies() -> None:
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.synthesis.dynamic import INPUT_SCALE, STATE_SCALE
    from tsmpc.synthesis.paper_as_run import certify_vertices, vertex_lmis

    cfg = Config.preset("paper-as-run")
    assert cfg.dynamic_lmi.feasible_point == "analytic-center"
    d = load_or_design_dynamic(cfg)
    assert d.feasible_point == "analytic-center" and d.center_iterations > 0
    A, B, (As, Bs, Qh, Rh) = _problem(cfg, STATE_SCALE, INPUT_SCALE)
    assert all(c.holds for c in certify_vertices(A, B, cfg.dynamic_lmi, d.K, d.P))
    # the barrier's gradient vanishes there (scaled coordinates: Y = (T P T)⁻¹, W = K_s Y)
    Tx, Tui = np.diag(STATE_SCALE), np.diag(1.0 / INPUT_SCALE)
    Y = np.linalg.inv(Tx @ d.P @ Tx)
    W = (Tui @ d.K @ Tx) @ Y
    iu = np.triu_indices(6)
    x = np.concatenate([Y[iu], W.reshape(-1)])
    from tsmpc.synthesis.analytic_center import _gradient_hessian

    g, H = _gradient_hessian(vertex_lmis(As, Bs, Qh, Rh, d.margin_imposed), x)
    assert float(g @ np.linalg.solve(H, g)) < 1e-9  # Newton decrement²: at the centre


def test_the_centre_is_the_same_in_any_scaling() -> None:
    """Posed in the design's scaling or in nearly physical units (a MATLAB user's), the analytic
    centre gives the same gains: it does not depend on how the problem is written."""
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.synthesis.paper_as_run import _center, _physical

    cfg = Config.preset("paper-as-run")
    d = load_or_design_dynamic(cfg)
    xs, us = np.array([1.0, 0.1, 0.1, 100.0, 1.0, 1.0]), np.array([100.0, 1.0])
    _, _, (As, Bs, Qh, Rh) = _problem(cfg, xs, us)
    Tx, Tui = np.diag(xs), np.diag(1.0 / us)
    # start: the cached centre moved off-centre (a convex blend with Clarabel's answer)
    solver = load_or_design_dynamic(replace(cfg, dynamic_lmi=replace(cfg.dynamic_lmi,
                                                                     feasible_point="solver")))
    P0, K0 = 0.5 * (d.P + solver.P), 0.5 * (d.K + solver.K)
    Y0 = np.linalg.inv(Tx @ P0 @ Tx)
    Yc, Wc, iters = _center(As, Bs, Qh, Rh, d.margin_imposed, 0.5 * (Y0 + Y0.T), (Tui @ K0 @ Tx) @ Y0)
    K, _ = _physical(Yc, Wc, xs, us)
    assert iters > 0
    np.testing.assert_allclose(K, d.K, rtol=1e-5, atol=1e-6 * np.abs(d.K).max())
    assert not np.allclose(solver.K, d.K, rtol=1e-2)  # Clarabel's answer is another point


def test_feasible_point_needs_the_feasibility_formulation() -> None:
    from tsmpc.config import DynamicLMISettings

    with pytest.raises(ConfigError, match="feasible_point: only for the 'feasibility-euler'"):
        replace(DynamicLMISettings(), feasible_point="analytic-center")
    replace(DynamicLMISettings(), formulation="feasibility-euler", feasible_point="analytic-center")
