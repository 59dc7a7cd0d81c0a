"""The cascade's clock block (tsmpc.control._clock, one definition for Cascade and the run engine):
the recovery's catch-up by hand. After a blind stop the reference time waits for the car: each MPC
step it advances by v̂ / v_d of T_c (the offset grows by the rest) until the car is back at the
reference's speed; a reference standing still, or no estimate, ends the catch-up."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc.control._clock import CK_CATCHUP, CK_REANCHOR, N_CK, ClockParams, cascade_time
from tsmpc.control.outer_block import N_OB, OB_TOFF, RefArrays

TC = 0.1


def _clock() -> ClockParams:
    return ClockParams(Td=0.01, Tc=TC, max_jump=1.0, max_age=1.0, recovery=True, blind_after=0.5,
                       n_inner=10, fixed_base=False, bound=False, curvature_max=0.5)


def _refs(v: np.ndarray) -> RefArrays:
    n = v.size
    z = np.zeros(n)
    return RefArrays(np.arange(n) * 1.0, z, z, v, z, z, v.copy(), z)


def _catching_up(offset: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ck = np.zeros(N_CK)
    ck[CK_CATCHUP] = 1.0
    ob = np.zeros(N_OB)
    ob[OB_TOFF] = offset
    return ck, ob, np.zeros(2)


def test_catch_up_advances_the_reference_time_at_the_cars_speed() -> None:
    refs = _refs(np.full(50, 4.0))
    ck, ob, up = _catching_up()
    # at t = 2.0 s the reference sample is 20 (v_d = 4 m/s); the car does 1 m/s: a quarter of T_c
    k, restarted = cascade_time(_clock(), refs, ck, ob, up, 200, 2.0, True, 0.0, 0.0, 1.0, 0.0, 1.0)
    assert ob[OB_TOFF] == pytest.approx(0.75 * TC, rel=1e-15)
    assert k == math.floor((2.0 - 0.75 * TC) / TC + 1e-6) == 19 and not restarted
    assert ck[CK_CATCHUP] == 1.0  # still behind
    # back at the reference's speed: the catch-up ends, the offset stays
    k, _ = cascade_time(_clock(), refs, ck, ob, up, 210, 2.1, True, 0.0, 0.0, 5.0, 0.0, 5.0)
    assert ck[CK_CATCHUP] == 0.0 and ob[OB_TOFF] == pytest.approx(0.75 * TC, rel=1e-15) and k == 20


@pytest.mark.parametrize("why, v_d, v_hat", [("the reference stands still", 0.0, 1.0),
                                             ("no estimate", 4.0, math.nan)])
def test_catch_up_ends_without_a_rate(why: str, v_d: float, v_hat: float) -> None:
    refs = _refs(np.full(50, v_d))
    ck, ob, up = _catching_up(0.3)
    k, restarted = cascade_time(_clock(), refs, ck, ob, up, 200, 2.0, True, 0.0, 0.0, 1.0, 0.0, v_hat)
    assert ck[CK_CATCHUP] == 0.0, why
    assert ob[OB_TOFF] == 0.3 and k == 17 and not restarted


def test_no_catch_up_no_change() -> None:
    refs = _refs(np.full(50, 4.0))
    ck, ob, up = _catching_up(0.3)
    ck[CK_CATCHUP], ck[CK_REANCHOR] = 0.0, 0.0
    k, restarted = cascade_time(_clock(), refs, ck, ob, up, 200, 2.0, True, 0.0, 0.0, 1.0, 0.0, 1.0)
    assert (k, restarted, ob[OB_TOFF], ck[CK_CATCHUP]) == (17, False, 0.3, 0.0)
