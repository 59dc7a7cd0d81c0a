"""The batch's lane-vectorised MHE window solve is the only second form of the window solve
(issue 34): on random windows, each lane of :func:`tsmpc.kernels.batch.mhe_window_lanes` gives
the scalar kernel's answer (:func:`tsmpc.kernels.mhe.euler_matrices` then
:func:`~tsmpc.kernels.mhe.banded_solve`) to the last bit — the same operations in the same order."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.kernels import batch as kb
from tsmpc.kernels import engine as ke
from tsmpc.kernels import mhe as km


def _lane_inputs(rng: np.random.Generator, n: int) -> dict:
    """One lane's window: a vehicle near the paper's, weights, measurements, inputs and the
    states the model is evaluated at (speeds inside the box, some measurements missing)."""
    scale = rng.uniform(0.7, 1.3, 6)
    return {
        "M": 683.0 * scale[0], "I": 560.94 * scale[1], "Cf": 25000.0 * scale[2], "Cr": 25000.0 * scale[3],
        "a": 0.758 * scale[4], "b": 1.036 * scale[5], "mug": rng.uniform(500.0, 6000.0),
        "kd": rng.uniform(0.1, 0.6), "Td": 0.01,
        "q": np.exp(rng.uniform(-1.0, 3.0, 3)), "r": np.exp(rng.uniform(-4.0, 0.0, 2)),
        "p": np.exp(rng.uniform(-1.0, 2.0, 3)), "pF": np.exp(rng.uniform(-12.0, -6.0)),
        "lo": np.array([-0.4, 0.5]), "hi": np.array([0.4, 18.0]),
        "Y": np.column_stack([rng.uniform(1.0, 17.0, n + 1), rng.uniform(-0.8, 0.8, n + 1)]),
        "W": (rng.uniform(size=n + 1) > 0.1).astype(float),
        # steering angles partly outside the box (clipped) and repeated (the angle cache's reuse)
        "U": np.column_stack([rng.uniform(-2000.0, 10000.0, n),
                              np.repeat(rng.uniform(-0.5, 0.5, (n + 1) // 2), 2)[:n]]),
        "XS": np.column_stack([rng.uniform(0.2, 19.0, n + 1), rng.uniform(-0.05, 0.05, n + 1),
                               rng.uniform(-0.8, 0.8, n + 1)]),
        "arrival": rng.uniform(-1.0, 10.0, 3), "F_prior": rng.uniform(-500.0, 2000.0),
        "full": bool(rng.uniform() > 0.5),
    }


def _scalar(d: dict, n: int) -> tuple[np.ndarray, float]:
    A, B = np.empty((n, 3, 3)), np.empty((n, 3, 2))
    km.euler_matrices(d["U"], d["XS"], n, d["lo"], d["hi"], d["M"], d["I"], d["Cf"], d["Cr"], d["a"], d["b"],
                      d["mug"], d["kd"], d["Td"], A, B)
    X = np.empty((n + 1, 3))
    arrival = d["XS"][0] if d["full"] else d["arrival"]
    F = km.banded_solve(d["Y"], d["W"], d["U"], A, B, n, arrival.copy(), d["F_prior"], d["q"], d["r"], d["p"],
                        d["pF"], X)
    return X, F


def _gather(ws: np.ndarray, slot: int, d: dict, n: int) -> None:
    mp, sf, si = np.zeros(km.N_MP), np.zeros(ke.N_SF), np.zeros(ke.N_SI, dtype=np.int64)
    mp[km.MP_TD] = d["Td"]
    for k, name in ((km.MP_M, "M"), (km.MP_I, "I"), (km.MP_CF, "Cf"), (km.MP_CR, "Cr"), (km.MP_A, "a"),
                    (km.MP_B, "b"), (km.MP_MUG, "mug"), (km.MP_KD, "kd")):
        mp[k] = d[name]
    mp[km.MP_Q:km.MP_Q + 3], mp[km.MP_R:km.MP_R + 2], mp[km.MP_P:km.MP_P + 3] = d["q"], d["r"], d["p"]
    mp[km.MP_PF] = d["pF"]
    mp[km.MP_LO:km.MP_LO + 2], mp[km.MP_HI:km.MP_HI + 2] = d["lo"], d["hi"]
    sf[ke.SF_ARR:ke.SF_ARR + 3], sf[ke.SF_MF] = d["arrival"], d["F_prior"]
    si[ke.SI_MHEFULL] = int(d["full"])
    key, sn, cs = np.full(n + 1, np.nan), np.zeros(n + 1), np.zeros(n + 1)
    kb._mhe_gather(ws, slot, n, d["Y"], d["W"], d["U"], d["XS"].copy(), mp, sf, si, key, sn, cs)


@pytest.mark.parametrize("n", [2, 7, 30])
def test_every_lane_of_the_vector_window_solve_is_the_scalar_solve_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(34 + n)
    lanes = [_lane_inputs(rng, n) for _ in range(kb.LANES)]
    ws = kb.mhe_workspace(n)
    for slot, d in enumerate(lanes):
        _gather(ws, slot, d, n)
    kb.mhe_window_lanes(ws, n)
    L = kb.LANES
    for slot, d in enumerate(lanes):
        X, F = _scalar(d, n)
        assert np.isfinite(F) and ws[kb.MH_BAD * L + slot] == 0.0
        assert ws[kb.MH_F * L + slot] == F, slot
        for k in range(n + 1):
            o = (k + 1) * kb.MR * L + slot
            got = [ws[o + (kb.MR_X + i) * L] for i in range(3)]
            assert got == list(X[k]), (slot, k, got, X[k])
