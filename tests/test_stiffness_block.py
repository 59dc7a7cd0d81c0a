"""The stiffness hand-over as one block (control/stiffness_block.py, issue 34): by hand, and through
the cascade (its arrays and the Python models around them). The engine compiles the same function:
tests/test_engine.py compares its runs with the Python loop's (the stiffness fit is on by
default)."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.config import Config, Method
from tsmpc.control.cascade import Cascade
from tsmpc.control.fusion_block import course_store, slip_load
from tsmpc.control.stiffness_block import (
    MP_A,
    MP_B,
    MP_CF,
    MP_CR,
    MP_I,
    N_SA,
    PRM_A,
    PRM_B,
    PRM_CF,
    PRM_CR,
    PRM_I,
    SA_CF,
    SA_CR,
    SA_HAS,
    stiffness_block,
)
from tsmpc.estimation.fusion import SLIP_PRIOR, CourseFusion, StiffFit, stiffness
from tsmpc.planning.circuit import builtin_circuit


def _course(cfg: Config, kf: float, kr: float) -> CourseFusion:
    """A course fusion whose stiffness fit says (kf C_f, kr C_r) and whose slip fit has learnt a
    κ (and a β)."""
    veh = cfg.vehicle
    c = CourseFusion(cfg.rates.Tc, 0.05, veh, Td=cfg.rates.Td, n_inner=cfg.rates.inner_per_outer)
    slip = c.state.slip._replace(kappa=0.003, beta=0.01, P00=1e-7, P01=2e-8, P10=2e-8, P11=3e-6)
    c.state = c.state._replace(slip=slip, stiff=StiffFit(1.0, 1.0, kf * veh.C_f, kr * veh.C_r, 0.0, False))
    return c


def test_the_hand_over_by_hand() -> None:
    cfg = Config()
    veh = cfg.vehicle
    c = _course(cfg, 0.9, 1.2)
    sa, mp, prm = np.zeros(N_SA), np.arange(30.0), np.arange(8.0)
    mp0, prm0 = mp.copy(), prm.copy()
    # none given yet: given, into both blocks' slots and the record; κ kept (no model replaced)
    give, s = stiffness_block(c.params, c.state, sa, mp, prm)
    cf, cr = stiffness(c.params, c.state.stiff)
    assert (cf, cr) == pytest.approx((0.9 * veh.C_f, 1.2 * veh.C_r), rel=1e-12)
    assert give and s.slip == c.state.slip
    assert (mp[MP_CF], mp[MP_CR], prm[PRM_CF], prm[PRM_CR]) == (cf, cr, cf, cr)
    # the joint lateral fit is not ready: the model's I_z and CoG go with them
    model = (veh.inertia, veh.a, veh.b)
    assert (mp[MP_I], mp[MP_A], mp[MP_B]) == model and (prm[PRM_I], prm[PRM_A], prm[PRM_B]) == model
    assert list(sa) == [1.0, cf, cr, *model] and (sa[SA_HAS], sa[SA_CF], sa[SA_CR]) == (1.0, cf, cr)
    rest = np.ones(30, dtype=bool)
    rest[[MP_I, MP_CF, MP_CR, MP_A, MP_B]] = False
    np.testing.assert_array_equal(mp[rest], mp0[rest])
    np.testing.assert_array_equal(prm[[0, 6, 7]], prm0[[0, 6, 7]])
    # the same fit again (within 1 %): nothing given, nothing written
    c.state = c.state._replace(stiff=StiffFit(1.0, 1.0, 0.905 * veh.C_f, 1.205 * veh.C_r, 0.0, False))
    before = (sa.copy(), mp.copy(), prm.copy())
    give, s = stiffness_block(c.params, c.state, sa, mp, prm)
    assert not give and s is c.state
    for a, b in zip(before, (sa, mp, prm), strict=True):
        np.testing.assert_array_equal(a, b)
    # only C_r moved by over 1 %: both given again (the TS-LQR's C_r too), and κ restarts (it
    # explained the previous model's error) while β and its variance stay
    c.state = c.state._replace(stiff=StiffFit(1.0, 1.0, 0.9 * veh.C_f, 1.3 * veh.C_r, 0.0, False))
    give, s = stiffness_block(c.params, c.state, sa, mp, prm)
    cf, cr = stiffness(c.params, c.state.stiff)
    assert give and cr == pytest.approx(1.3 * veh.C_r, rel=1e-12)
    assert (mp[MP_CF], mp[MP_CR], prm[PRM_CF], prm[PRM_CR]) == (cf, cr, cf, cr)
    assert list(sa) == [1.0, cf, cr, *model]
    f = s.slip
    assert (f.kappa, f.P00, f.P01, f.P10) == (0.0, SLIP_PRIOR[0] ** 2, 0.0, 0.0)
    assert (f.beta, f.P11) == (0.01, 3e-6)
    assert s.stiff == c.state.stiff and s.ring == c.state.ring


def test_the_cascade_hands_over_through_the_block_and_reset_takes_them_back() -> None:
    cfg = Config()
    veh = cfg.vehicle
    cas = Cascade(cfg, Method.REF, builtin_circuit(), x0=np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]))
    fu = cas._fusion
    course_store(_course(cfg, 0.8, 1.1).state, cas._fb, cas._ivs)  # (the fusion block's vectors)
    cas._outer_block(0.0, 0.0, 0.0, 10.0, 0.0, True)  # an MPC step's phase before the solve: the stiffness
    # block in it
    cf, cr = 0.8 * veh.C_f, 1.1 * veh.C_r
    assert cas._sa == pytest.approx([1.0, cf, cr, veh.inertia, veh.a, veh.b], rel=1e-12)
    C = (cas._sa[SA_CF], cas._sa[SA_CR])
    mhe, lqr = cas.mhe, cas.lqr
    assert (mhe.vehicle.C_f, mhe.vehicle.C_r) == C and (lqr.vehicle.C_f, lqr.vehicle.C_r) == C
    assert (mhe.model.params.C_f, mhe.model.params.C_r) == C  # the numpy window model
    assert (fu.steer_p.C_f, fu.steer_p.C_r) == C  # the steering-offset fit's balance
    if mhe._kern is not None:  # the compiled blocks' parameters: the block wrote them
        assert tuple(mhe._mp[[MP_CF, MP_CR]]) == C and mhe._kargs[10:12] == C
    if lqr._law is not None:
        assert tuple(lqr._law.prm[[PRM_CF, PRM_CR]]) == C
    assert slip_load(cas._fb).kappa == 0.003  # the first hand-over: κ kept
    cas.reset(np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]))  # back to the config's everywhere
    C0 = (veh.C_f, veh.C_r)
    assert not any(cas._sa)
    assert (mhe.vehicle.C_f, mhe.vehicle.C_r) == C0 and (lqr.vehicle.C_f, lqr.vehicle.C_r) == C0
    assert (fu.steer_p.C_f, fu.steer_p.C_r) == C0
    if mhe._kern is not None:
        assert tuple(mhe._mp[[MP_CF, MP_CR]]) == C0
    if lqr._law is not None:
        assert tuple(lqr._law.prm[[PRM_CF, PRM_CR]]) == C0



def test_the_slots_are_the_mhe_kernels() -> None:
    """The block's I_z, C_f, C_r, a, b slots are those of the MHE kernel's parameters (written in the block,
    not imported: the kernels would bring numba in with the estimator, which imports the block)."""
    pytest.importorskip("numba")
    from tsmpc.kernels import mhe as km

    assert (km.MP_I, km.MP_CF, km.MP_CR, km.MP_A, km.MP_B) == (MP_I, MP_CF, MP_CR, MP_A, MP_B)
