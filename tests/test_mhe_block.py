"""The MHE-UIO's block in the cascade (tsmpc.control.mhe_block): its inputs and the estimate it hands
on pinned by hand, its logic around the window kernel on a stub kernel (as Python, with or without
numba), and the cascade's compiled call equal to the estimator's own step over random samples with
rejected, failed and dense-QP steps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.config import Config, replace
from tsmpc.control import mhe_block as mb
from tsmpc.control.inner_block import EST_FAILED, EST_OK, EST_REJECTED, EST_WARMUP
from tsmpc.control.mhe_block import (
    EO_F,
    EO_FRAW,
    MHE_DENSE,
    N_EO,
    MHEBlockParams,
    MHEWindow,
    estimate_out,
    mhe_block,
    mhe_inputs,
)
from tsmpc.estimation.mhe_uio import MHEUIO, EstimatorStatus
from tsmpc.models.dynamic import DynamicTS


def test_the_inputs_by_hand() -> None:
    # the sample: v less the speed offset, ω as given; NaN when the gates refused it
    assert mhe_inputs(True, 10.0, 0.2, 0.25, 100.0, 0.01, False, 0.0, False, 0.0, 0.003, 0.0) == (
        9.75, 0.2, 100.0, 0.01)
    y0, y1, u0, u1 = mhe_inputs(False, 10.0, 0.2, 0.25, 100.0, 0.01, False, 0.0, False, 0.0, 0.003, 0.0)
    assert math.isnan(y0) and math.isnan(y1) and (u0, u1) == (100.0, 0.01)
    # the measured force and steering replace the command; the steering plus the offset in force
    assert mhe_inputs(True, 10.0, 0.2, 0.0, 100.0, 0.01, True, 250.0, True, 0.02, 0.003, 0.0)[2:] == (
        250.0, 0.02 + 0.003)
    # the low-speed resistance's part is taken off the force (applied or measured)
    assert mhe_inputs(True, 1.0, 0.0, 0.0, 100.0, 0.01, False, 0.0, False, 0.0, 0.0, 40.0)[2] == 60.0
    assert mhe_inputs(True, 1.0, 0.0, 0.0, 100.0, 0.01, True, 250.0, False, 0.0, 0.0, 40.0)[2] == 210.0


def test_the_estimate_handed_on_by_hand() -> None:
    ms, est = np.array([10.0, 0.01, 0.2, -300.0, 9.0, 9.0, 9.0]), np.zeros(N_EO)
    estimate_out(ms, est, 123.0)
    assert est.tolist() == [10.0, 0.01, 0.2, -300.0, 123.0]


class _Stub:
    """A window kernel that answers a given status and records what it was given."""

    def __init__(self, status: int) -> None:
        self.status, self.args = status, ()

    def __call__(self, *args):
        self.args = args
        ms, mi = args[13], args[14]
        if self.status != MHE_DENSE:
            ms[0:4] = [9.0, 0.02, 0.3, -100.0]
        if self.status == EST_REJECTED:
            mi[1] += 1
        elif self.status == EST_FAILED:
            mi[2] += 1
        return self.status, 77.0, 5, self.status != EST_REJECTED


def _window(n: int = 3) -> MHEWindow:
    return MHEWindow(np.zeros((n + 1, 2)), np.zeros(n + 1), np.zeros((n, 2)), np.zeros((n + 1, 3)),
                     np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n + 1, 3)))


@pytest.mark.parametrize("status", [EST_OK, EST_REJECTED, EST_FAILED, EST_WARMUP, MHE_DENSE])
def test_the_block_around_the_kernel(monkeypatch: pytest.MonkeyPatch, status: int) -> None:
    """The block as Python on a stub kernel: the inputs it gives the kernel, the status passed on
    as the kernel decided it (a failed or rejected sample stays so), the estimate handed on unless
    the dense QP must decide (then F̂_raw only)."""
    stub = _Stub(status)
    monkeypatch.setattr(mb, "mhe_step", stub)
    ms, mi, uk, est = np.zeros(7), np.zeros(3, dtype=np.int64), np.zeros(2), np.full(N_EO, -1.0)
    out = mhe_block(MHEBlockParams(683.0, True), _window(), np.zeros(30), ms, mi, uk, est, True, 10.0, 0.2,
                    0.25, 100.0, 0.01, True, 250.0, True, 0.02, 0.003, 40.0)
    assert stub.args[:5] == (9.75, 0.2, 210.0, 0.02 + 0.003, 683.0)
    assert stub.args[-2:] == (True, True)  # the model in the kernel; deferred as the params say
    assert out.status == status and out.F_raw == 77.0 and out.n == 5 and (out.u0, out.u1) == (210.0, 0.023)
    assert mi.tolist() == [0, int(status == EST_REJECTED), int(status == EST_FAILED)]
    if status == MHE_DENSE:
        assert est.tolist() == [-1.0, -1.0, -1.0, -1.0, 77.0]
    else:
        assert est.tolist() == [9.0, 0.02, 0.3, -100.0, 77.0]


def _mhe(cfg: Config) -> MHEUIO:
    return MHEUIO(cfg.mhe, DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td), cfg.vehicle, cfg.rates.Td,
                  x0=np.array([8.0, 0.0, 0.0]))


def test_the_compiled_block_is_the_estimators_step() -> None:
    """The cascade's compiled call (kernels/blocks.py mhe_call) and MHEUIO.step on the block's
    inputs: the same estimates, statuses and counters to the bit over 400 random steps with
    refused samples, non-finite inputs (rejected), an overflowing F̂_raw (failed) and state
    bounds that make the dense QP decide."""
    kern = kernels.load("blocks")
    if kern is None:
        pytest.skip("compiled kernels unavailable")
    cfg = Config()
    cfg = replace(cfg, mhe=replace(cfg.mhe, x_max=(18.0, 0.03, 0.6)))
    a, b = _mhe(cfg), _mhe(cfg)
    assert a._kern is not None and a._kargs[-1]
    est = np.zeros(N_EO)
    rng = np.random.default_rng(34)
    seen: set[EstimatorStatus] = set()
    dense = 0
    for i in range(400):
        v, om = 8.0 + rng.normal(0, 0.5), 0.3 * math.sin(0.05 * i) + rng.normal(0, 0.01)
        F, d = float(rng.normal(300.0, 200.0)), 0.05 * math.sin(0.05 * i)
        if i % 53 == 7:
            F = math.nan  # a non-finite input: never in the window, the sample rejected
        ok = bool(rng.random() > 0.05)
        if i == 200:  # a finite sample that overflows the one-step UIO force: a failed step
            v, ok = -1e308, True
        args = (ok, v, om, 0.1, F, d, bool(rng.random() < 0.3), F + 5.0,
                bool(rng.random() < 0.3), d - 0.01, 0.004, 0.0 if rng.random() < 0.8 else 30.0)
        y0, y1, u0, u1 = mhe_inputs(*args)
        ea = a.step((y0, y1), (u0, u1))
        st, F_raw, n, ok, v0, v1 = kern.mhe_call(b.vehicle.mass, b._Y, b._W, b._U, b._XS, b._Ab, b._Bb, b._Xb,
                                                  b._mp, b._ms, b._mi, b._uk, est, *args)
        eb = b.estimate(st, F_raw, n, ok, 0.0)
        assert (v0, v1) == (u0, u1) or (math.isnan(u0) and math.isnan(v0)), i
        np.testing.assert_array_equal(ea.x, eb.x, err_msg=str(i))
        assert (ea.F_fr, ea.status) == (eb.F_fr, eb.status), i
        assert ea.F_fr_raw == eb.F_fr_raw or (math.isnan(ea.F_fr_raw) and math.isnan(eb.F_fr_raw)), i
        if st != MHE_DENSE:
            assert est[:3].tolist() == eb.x.tolist() and est[EO_F] == eb.F_fr and est[EO_FRAW] == F_raw
        np.testing.assert_array_equal(a._mi, b._mi, err_msg=str(i))
        np.testing.assert_array_equal(a._ms, b._ms, err_msg=str(i))
        seen.add(eb.status)
        dense += st == MHE_DENSE
        if i == 200:
            assert eb.status == EstimatorStatus.FAILED  # counted as failed, not as a good estimate
    assert seen == {EstimatorStatus.OK, EstimatorStatus.REJECTED, EstimatorStatus.FAILED,
                    EstimatorStatus.WARMUP}
    assert b.n_failed >= 1 and b.n_rejected > 10 and dense > 10
