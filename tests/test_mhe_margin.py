"""The MHE-UIO's yaw-model margin (tsmpc.estimation.mhe_margin, issue 35): its update by hand, and on
an estimator fed by a car whose yaw inertia is not the model's — the margin grows there and stays
off with the model's own car, the same on the compiled window step and on the numpy path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.config import Config, replace
from tsmpc.estimation.mhe_margin import (
    MP_MARGIN,
    MS_MARGIN,
    N_MARGIN_MP,
    margin_params,
    margin_residual,
    margin_update,
)
from tsmpc.estimation.mhe_uio import MHEUIO
from tsmpc.models.dynamic import DynamicTS


def _mp(ref: float, f_max: float = 15.0, rise: float = 0.1, decay: float = 0.01, q: float = 0.5,
        linear: float = 0.0) -> np.ndarray:
    mp = np.zeros(MP_MARGIN + N_MARGIN_MP)
    mp[2] = q
    mp[21:28] = [683.0, 560.94, 25000.0, 25000.0, 0.758, 1.036, 0.65 * 9.81]  # M, I, C_f, C_r, a, b, μ_o g
    mp[MP_MARGIN:] = [ref, f_max, rise, decay, q, linear]
    return mp


def test_the_update_by_hand() -> None:
    n, e, ref = 4, 3e-4, 1e-4
    XS, A, B, U = np.zeros((n + 1, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n, 2))
    XS[1:, 1] = [e, -e, e, -e]  # the slip rows' residuals (A = B = 0: nothing predicted)
    XS[:, 0], XS[:, 2] = 7.0, 0.3  # (other rows are not read)
    mp, ms = _mp(ref), np.zeros(8)
    margin_update(mp, ms, XS, A, B, U, n)
    assert ms[MS_MARGIN] == pytest.approx(0.1 * 9.0)  # rising: f += 0.1 (ratio 9 − 0)
    assert mp[2] == 0.5  # f < 1: the configured weight
    for _ in range(30):
        margin_update(mp, ms, XS, A, B, U, n)
    f = ms[MS_MARGIN]
    assert f == pytest.approx(9.0 * (1 - 0.9 ** 31)) and mp[2] == pytest.approx(0.5 / f)
    XS[1:, 1] = 0.0  # a window that fits: the margin decays at the decay gain
    margin_update(mp, ms, XS, A, B, U, n)
    assert ms[MS_MARGIN] == pytest.approx(0.99 * f)
    # the prediction of the slip row: A x + B (u − F̂ e_0), F̂ in ms[3]
    A[:, 1] = [0.01, 0.9, 0.02]
    B[:, 1] = [1e-5, 0.05]
    U[:] = [900.0, 0.02]
    ms2 = np.zeros(8)
    ms2[3] = 400.0
    for k in range(n):
        XS[k + 1, 1] = A[k, 1] @ XS[k] + B[k, 1, 0] * (U[k, 0] - 400.0) + B[k, 1, 1] * U[k, 1]
    mp2 = _mp(ref)
    margin_update(mp2, ms2, XS, A, B, U, n)
    assert ms2[MS_MARGIN] == pytest.approx(0.0, abs=1e-12)
    # the bound on the factor, and off
    mp3, ms3 = _mp(ref, f_max=2.0), np.array([0, 0, 0, 0, 0, 0, 0, 50.0])
    margin_update(mp3, ms3, XS, A, B, U, n)
    assert mp3[2] == 0.5 / 2.0
    mp4, ms4 = _mp(0.0), np.full(8, 3.0)
    margin_update(mp4, ms4, XS * 10.0, A, B, U, n)
    assert mp4[2] == 0.5 and ms4[MS_MARGIN] == 3.0


def test_only_windows_within_the_linear_tyre_count() -> None:
    """A window whose front axle slip δ − α − a ω / v passes the share of the saturation slip
    μ_o g M b / (L C_f) (0.0962 rad here) leaves the margin as it was; within it, it counts."""
    n = 4
    XS, A, B, U = np.zeros((n + 1, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n, 2))
    XS[:, 0] = 8.0
    XS[1:, 1] = [3e-4, -3e-4, 3e-4, -3e-4]
    sat_f = 0.65 * 9.81 * 683.0 * 1.036 / (1.794 * 25000.0)
    for delta, counts in ((0.49 * sat_f, True), (0.51 * sat_f, False)):
        U[:, 1] = delta
        mp, ms = _mp(1e-4, linear=0.5), np.zeros(8)
        margin_update(mp, ms, XS, A, B, U, n)
        assert (ms[MS_MARGIN] > 0.0) == counts, delta
        mp0, ms0 = _mp(1e-4, linear=0.0), np.zeros(8)  # 0: every window
        margin_update(mp0, ms0, XS, A, B, U, n)
        assert ms0[MS_MARGIN] > 0.0
    # the rear axle's slip b ω / v − α against μ_o g M a / (L C_r), the front one held at 0
    sat_r = 0.65 * 9.81 * 683.0 * 0.758 / (1.794 * 25000.0)
    for share, counts in ((0.49, True), (0.51, False)):
        w = share * sat_r * 8.0 / 1.036
        XS[:, 2], U[:, 1] = w, 0.758 * w / 8.0
        mp, ms = _mp(1e-4, linear=0.5), np.zeros(8)
        margin_update(mp, ms, XS, A, B, U, n)
        assert (ms[MS_MARGIN] > 0.0) == counts, share


def test_the_parameters_of_the_config() -> None:
    assert margin_params(0.01, 15.0, 1.0, 20.0, 2.0, 0.01, 0.5) == pytest.approx(
        [1e-4, 15.0, 0.01, 5e-4, 0.5, 0.5])
    assert Config().mhe.margin_slip_rate == 0.01
    assert Config.preset("paper").mhe.margin_slip_rate == 0.0  # the paper's MHE: fixed Q
    assert Config.preset("paper-as-run").mhe.margin_slip_rate == 0.0


def _run(inertia_scale: float, jit: bool, seconds: float = 12.0) -> MHEUIO:
    """An estimator with the config's model on a car whose yaw inertia is ``inertia_scale`` × the
    model's (the same TS model otherwise), steered in a 0.4 Hz slalom at 8 m/s."""
    cfg = Config()
    Td, veh = cfg.rates.Td, cfg.vehicle
    model = DynamicTS(cfg.dynamic_box, veh, Td)
    car = DynamicTS(cfg.dynamic_box, replace(veh, inertia=veh.inertia * inertia_scale), Td)
    mhe = MHEUIO(cfg.mhe, model, veh, Td, x0=np.array([8.0, 0.0, 0.0]), jit=jit)
    rng = np.random.default_rng(35)
    x, F_fr = np.array([8.0, 0.0, 0.0]), 300.0
    for k in range(int(seconds / Td)):
        delta = 0.04 * math.sin(2 * math.pi * 0.4 * k * Td)
        u = np.array([F_fr, delta])
        A, B = car.matrices(np.array([delta, x[0], x[1]]))
        x = A @ x + B @ u - B[:, 0] * F_fr
        mhe.step((x[0] + rng.normal(0, 0.005), x[2] + rng.normal(0, 1e-4)), (u[0], u[1]))
    return mhe


@pytest.mark.parametrize("scale", [0.7, 1.3])
def test_a_wrong_yaw_inertia_grows_the_margin_and_the_models_car_does_not(scale: float) -> None:
    wrong, right = _run(scale, jit=False), _run(1.0, jit=False)
    # the slip residual's mean square ≈ 3 × its reference's (the model's own car: ≈ 0.55 ×)
    assert wrong._ms[MS_MARGIN] > 2.0, wrong._ms[MS_MARGIN]
    assert wrong._mp[2] < 0.5 / 2.0
    assert right._ms[MS_MARGIN] < 1.0, right._ms[MS_MARGIN]  # the model's own car: the paper's Q_ω
    assert right._mp[2] == 0.5
    wrong.reset()  # a reset starts from the configured weight
    assert wrong._ms[MS_MARGIN] == 0.0 and wrong._mp[2] == 0.5


def test_the_compiled_window_step_has_the_numpy_paths_margin() -> None:
    if kernels.load("mhe") is None:
        pytest.skip("compiled kernels unavailable")
    a, b = _run(0.7, jit=True, seconds=6.0), _run(0.7, jit=False, seconds=6.0)
    assert a._kern is not None and b._kern is None
    assert a._ms[MS_MARGIN] == pytest.approx(b._ms[MS_MARGIN], rel=1e-6)
    assert a._mp[2] == pytest.approx(b._mp[2], rel=1e-6)
    np.testing.assert_allclose(a._x, b._x, rtol=1e-7, atol=1e-9)


def test_its_slots_are_the_estimators() -> None:
    """The margin's slot numbers (the module imports no numba, so it names them itself) are the
    kernel's records'."""
    km = kernels.load("mhe")
    if km is None:
        pytest.skip("compiled kernels unavailable")
    from tsmpc.estimation import mhe_margin as mm

    assert (mm._MP_M, mm._MP_CF, mm._MP_CR, mm._MP_A, mm._MP_B, mm._MP_MUG) == (
        km.MP_M, km.MP_CF, km.MP_CR, km.MP_A, km.MP_B, km.MP_MUG)
    assert (mm._MP_QW, mm._MS_F) == (km.MP_Q + 2, km.MS_F)
    assert (mm.MP_MARGIN, mm.MS_MARGIN) == (km.N_MP - mm.N_MARGIN_MP, km.N_MS - 1)


def test_the_batch_lanes_window_arithmetic_is_the_scalar_one() -> None:
    """tsmpc.kernels.batch.margin_lanes (the batch's second form of :func:`margin_residual`, lane
    innermost) equals the scalar function bit for bit on random windows, the linear-tyre flag too
    (lanes with large slips, and a share of 0: every window)."""
    from tsmpc.kernels import batch as kb

    rng = np.random.default_rng(53)
    L = kb.LANES
    for n in (2, 7, 30):
        s = np.zeros(kb.mhe_workspace(n).size)
        hdr = {kb.MH_M: rng.uniform(500, 900, L), kb.MH_CF: rng.uniform(1.5e4, 3.5e4, L),
               kb.MH_CR: rng.uniform(1.5e4, 3.5e4, L), kb.MH_AA: rng.uniform(0.6, 1.0, L),
               kb.MH_BB: rng.uniform(0.8, 1.2, L), kb.MH_MUG: rng.uniform(3.0, 9.0, L),
               kb.MH_F: rng.normal(300.0, 100.0, L), kb.MH_LIN: np.where(rng.random(L) < 0.2, 0.0, 0.5)}
        for f, v in hdr.items():
            s[f * L:(f + 1) * L] = v
        XS = np.stack([rng.uniform(0.5, 20.0, (L, n + 1)), rng.normal(0, 0.02, (L, n + 1)),
                       rng.normal(0, 0.3, (L, n + 1))], axis=-1)
        XS[::5, n // 2, 1] = 0.2  # (a large slip: outside the linear tyres)
        A, B = rng.normal(0, 1, (L, n, 3, 3)), rng.normal(0, 1e-3, (L, n, 3, 2))
        U = np.stack([rng.normal(500, 200, (L, n)), rng.normal(0, 0.05, (L, n))], axis=-1)
        for k in range(n + 1):
            o = (k + 1) * kb.MR * L
            for i in range(3):
                s[o + (kb.MR_X + i) * L:o + (kb.MR_X + i + 1) * L] = XS[:, k, i]
            if k < n:
                for j in range(3):
                    s[o + (kb.MR_A + 3 + j) * L:o + (kb.MR_A + 4 + j) * L] = A[:, k, 1, j]
                for j in range(2):
                    s[o + (kb.MR_B + 2 + j) * L:o + (kb.MR_B + 3 + j) * L] = B[:, k, 1, j]
                    s[o + (kb.MR_U + j) * L:o + (kb.MR_U + j + 1) * L] = U[:, k, j]
        kb.margin_lanes(s, n)
        flags = []
        for lane in range(L):
            mp = np.zeros(MP_MARGIN + N_MARGIN_MP)
            mp[21], mp[23], mp[24] = hdr[kb.MH_M][lane], hdr[kb.MH_CF][lane], hdr[kb.MH_CR][lane]
            mp[25], mp[26], mp[27] = hdr[kb.MH_AA][lane], hdr[kb.MH_BB][lane], hdr[kb.MH_MUG][lane]
            mp[MP_MARGIN + 5] = hdr[kb.MH_LIN][lane]
            msq, linear = margin_residual(mp, hdr[kb.MH_F][lane], XS[lane], A[lane], B[lane], U[lane], n)
            assert (s[kb.MH_MOK * L + lane] != 0.0) == linear, (n, lane)
            if linear:
                assert s[kb.MH_MSQ * L + lane] == msq, (n, lane)
            flags.append(linear)
        assert 0 < sum(flags) < L  # both kinds of window were compared
