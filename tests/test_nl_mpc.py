"""NL-MPC baseline (SPEC §7): convergence along the paper reference, agreement with the TS-MPC
where the models coincide, and failure handling."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tsmpc.config import Config, SchedulingMode
from tsmpc.control.nl_mpc import NLMPC
from tsmpc.control.ts_mpc import TSMPC, MPCStatus
from tsmpc.models.kinematic import KinematicTS, nonlinear_step
from tsmpc.synthesis.cache import load_or_design_kinematic

N, Tc = 40, 0.1


@pytest.fixture(scope="module")
def parts(cfg: Config):
    d = load_or_design_kinematic(cfg)
    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    return d, model


def test_nl_mpc_converges_and_matches_iter_ts_mpc(cfg: Config, parts, paper_reference_path) -> None:
    from tsmpc.planning.paper_format import load_paper_reference

    d, model = parts
    ref = load_paper_reference(paper_reference_path)
    nl = NLMPC(cfg.mpc, model, d.P, d.S)
    ts = TSMPC(cfg.mpc, model, d.P, d.S, mode=SchedulingMode.ITER)
    e = np.array([0.0, 2.0, 0.1])
    u = np.array([ref.v[0], ref.omega[0]])
    gaps = []
    for k in range(250):
        w = ref.window(k, N + 1)
        r = nl.step(e, u, w)
        assert r.status == MPCStatus.OPTIMAL
        gaps.append(np.abs(r.u - ts.step(e, u, w).u).max())
        u = r.u
        e = nonlinear_step(e, u, w.v[0], w.omega[0], Tc)
        if k == 249:
            assert np.abs(e[:2]).max() < 0.01
    # Near the reference the nonlinear and the (iterated) TS predictions coincide: same first move.
    assert np.median(gaps[100:]) < 1e-4


def test_nl_mpc_predictions_satisfy_the_nonlinear_model(cfg: Config, parts) -> None:
    d, model = parts
    nl = NLMPC(cfg.mpc, model, d.P, d.S)
    ref = SimpleNamespace(v=np.full(N, 8.0), omega=np.full(N, 0.1))
    r = nl.step(np.array([0.5, -0.8, 0.05]), np.array([8.0, 0.1]), ref)
    for i in range(N):
        x1 = nonlinear_step(r.x_pred[i], r.u_pred[i], 8.0, 0.1, Tc)
        assert np.allclose(x1, r.x_pred[i + 1], atol=1e-7)
    assert r.x_pred[-1] @ d.S @ r.x_pred[-1] <= 1 + 1e-6
    assert np.all(np.abs(r.du) <= np.array(cfg.mpc.du_max) + 1e-7)


def test_nl_mpc_soft_and_fallback(cfg: Config, parts) -> None:
    d, model = parts
    """Each status where it belongs: a reachable terminal set is met exactly (OPTIMAL); an
    unreachable one (80 m off) is relaxed (SOFT, x_N' S x_N > 1); a NaN state never reaches the
    solver (FALLBACK: the previous plan shifted by one step, or the held input without one)."""
    ref = SimpleNamespace(v=np.full(N, 10.0), omega=np.zeros(N))
    u_prev = np.array([10.0, 0.0])
    near = NLMPC(cfg.mpc, model, d.P, d.S).step(np.array([2.0, 1.0, 0.05]), u_prev, ref)
    assert near.status == MPCStatus.OPTIMAL
    assert near.x_pred[-1] @ d.S @ near.x_pred[-1] <= 1.0 + 1e-6
    nl = NLMPC(cfg.mpc, model, d.P, d.S)
    far = nl.step(np.array([80.0, -60.0, 0.4]), u_prev, ref)
    assert far.status == MPCStatus.SOFT
    assert far.x_pred[-1] @ d.S @ far.x_pred[-1] > 1.0 + 1e-3
    bad = nl.step(np.array([np.nan, 0.0, 0.0]), u_prev, ref)
    assert bad.status == MPCStatus.FALLBACK
    np.testing.assert_array_equal(bad.u, far.u_pred[1])
    first = NLMPC(cfg.mpc, model, d.P, d.S).step(np.array([np.nan, 0.0, 0.0]), u_prev, ref)
    assert first.status == MPCStatus.FALLBACK
    np.testing.assert_array_equal(first.u, u_prev)
