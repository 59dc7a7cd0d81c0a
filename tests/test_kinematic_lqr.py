"""Kinematic LQR (issue 26 baseline): at a vertex of the scheduling box the law is u = r + K_i x
exactly; between vertices it blends the gains with the TS memberships; it saturates to Π only; the
design's gains stabilise the TS error model in closed loop (the LMI's guarantee)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tsmpc.config import Config, KinematicBox, replace
from tsmpc.control.kinematic_lqr import KinematicLQR
from tsmpc.control.ts_mpc import MPCStatus
from tsmpc.models.kinematic import A_c, B_c, KinematicTS
from tsmpc.synthesis.cache import load_or_design_kinematic

BOX = KinematicBox(omega=(-1.0, 1.0), v_d=(2.0, 16.0), e_theta=(-math.radians(5), math.radians(5)))


def _law(cfg: Config, K: np.ndarray, box: KinematicBox = BOX) -> KinematicLQR:
    mpc = replace(cfg.mpc, u_min=(0.0, -1.4), u_max=(30.0, 1.4))
    return KinematicLQR(mpc, KinematicTS(box, cfg.rates.Tc), K)


def _ref(v: float, w: float) -> SimpleNamespace:
    return SimpleNamespace(v=np.full(41, v), omega=np.full(41, w))


def test_at_every_vertex_the_law_is_that_vertex_gain(cfg: Config) -> None:
    """Vertex i = 4 b_ω + 2 b_v + b_s (b = 1: upper bound; the sinc premise's upper bound is
    sinc 0 = 1, its lower bound sinc 5°): premises (ω = u_prev[1], v_d, e_θ) there give μ = e_i."""
    rng = np.random.default_rng(4)
    K = rng.normal(size=(8, 2, 3))
    law = _law(cfg, K)
    for bw in (0, 1):
        for bv in (0, 1):
            for bs in (0, 1):
                i = 4 * bw + 2 * bv + bs
                om, vd = BOX.omega[bw], BOX.v_d[bv]
                eth = 0.0 if bs else BOX.e_theta[1]
                x = np.array([0.3, -0.2, eth])
                res = law.step(x, np.array([vd, om]), _ref(vd, 0.1))
                r = np.array([vd * math.cos(eth), 0.1])
                np.testing.assert_allclose(res.u - r, K[i] @ x, rtol=0, atol=1e-12)
                assert res.status == MPCStatus.OPTIMAL and res.n_clipped == 0


def test_between_vertices_the_gains_are_blended(cfg: Config) -> None:
    """ω halfway between its bounds, v_d and sinc e_θ at their upper bounds: μ = ½ at vertices
    3 (ω low) and 7 (ω high), so u − r = ½ (K_3 + K_7) x."""
    rng = np.random.default_rng(5)
    K = rng.normal(size=(8, 2, 3))
    x = np.array([0.1, 0.4, 0.0])
    res = _law(cfg, K).step(x, np.array([16.0, 0.0]), _ref(16.0, 0.0))
    np.testing.assert_allclose(res.u - [16.0, 0.0], 0.5 * (K[3] + K[7]) @ x, atol=1e-12)


def test_saturation_and_clipped_premises_are_reported(cfg: Config) -> None:
    K = np.zeros((8, 2, 3))
    K[:, 1, 1] = 10.0  # ω gain on e_y
    law = _law(cfg, K)
    res = law.step(np.array([0.0, 1.0, 0.0]), np.array([20.0, 0.0]), _ref(20.0, 0.0))  # v_d > box
    assert res.u[1] == pytest.approx(1.4)  # the input box Π, nothing else
    assert res.n_clipped == 1
    bad = law.step(np.array([np.nan, 0.0, 0.0]), np.array([10.0, 0.0]), _ref(10.0, 0.0))
    assert bad.status == MPCStatus.FALLBACK


def test_design_gains_stabilise_the_ts_error_model(cfg: Config) -> None:
    """Closed loop x⁺ = A_c(ρ) x + B_c (u − r) with the law and the paper design's gains, from
    2 m / 0.05 rad on a curving reference: the errors decay (the LMI certificate's promise)."""
    kd = load_or_design_kinematic(cfg)
    law = KinematicLQR(cfg.mpc, KinematicTS(cfg.kinematic_box, cfg.rates.Tc), kd.K)
    Tc = cfg.rates.Tc
    x, u = np.array([1.0, 2.0, 0.05]), np.array([10.0, 0.1])
    norms = []
    for k in range(300):
        vd, wd = 10.0 + 2.0 * math.sin(0.02 * k), 0.1 * math.cos(0.03 * k)
        u = law.step(x, u, _ref(vd, wd)).u
        x = A_c(u[1], vd, x[2], Tc) @ x + B_c(Tc) @ (u - [vd * math.cos(x[2]), wd])
        norms.append(float(np.linalg.norm(x)))
    assert max(norms[150:]) < 1e-3 * norms[0]
