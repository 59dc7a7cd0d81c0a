"""The TS-LQR step's block (ts_lqr.inner_step, issue 34): the glue around the compiled law — the hold
on a non-finite estimate, the compensated friction estimate, the low-speed residual — written once
and called by TSLQR.step (as Python) and by the run engine and the batch (compiled).

By hand, as Python and compiled (the engine's way): every branch of the glue, with the law's
answer passed through. Python = compiled to the bit on random inputs through the real law. And in
both loops (the engine and the Python loop, one first outer step each): the force the low-speed
residual adds is μ_o M g (1 − v̂ / v_min), so a mutation of that arithmetic fails here in both."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.config import Config, apply_overrides
from tsmpc.control import ts_lqr
from tsmpc.control.ts_lqr import (
    LQR_HELD,
    LQR_NUMPY,
    LQR_OK,
    InnerParams,
    LQRLaw,
    compensated_friction,
    inner_step,
    low_speed_force,
)

P = InnerParams(compensation=True, raw_estimate=False, low_speed=True, v_min=2.0, resistance=1000.0)


def _compiled(fn):
    """``fn`` compiled by numba as the engine compiles it (a plain njit of the same source)."""
    if kernels.load("lqr") is None:
        pytest.skip("compiled kernels unavailable")
    from numba import njit

    return njit(cache=False)(fn)


@pytest.fixture(params=["python", "compiled"])
def way(request):
    """The block functions as the cascade calls them (Python) or as the engine does (compiled)."""
    if request.param == "python":
        return lambda fn: fn
    return _compiled


def _law(nan_gains: bool = False) -> LQRLaw:
    """A law of the box δ ∈ ±0.4, v ∈ [2, 20], α ∈ ±0.1 (the kernel's warm-up values); NaN gains
    make its reference gain singular (the kernel's pivot test)."""
    Kv = np.zeros((8, 2, 6))
    Kv[:, 0, 0] = -100.0
    Kv[:, 1, 2] = -0.1
    if nan_gains:
        Kv[:] = math.nan
    bits = np.array([[(i >> j) & 1 for j in range(3)] for i in range(8)], dtype=np.bool_)
    prm = np.array([683.0, 560.0, 25000.0, 25000.0, 0.758, 1.036, 4.9, 0.4])
    return LQRLaw(Kv, np.array([-0.4, 2.0, -0.1]), np.array([0.4, 20.0, 0.1]), bits, prm, 10.0,
                  math.exp(-10.0 * 0.01), 0.01, -2000.0, 10000.0, -0.4, 0.4, True, 0.3)


def test_compensation_chooses_the_configured_estimate(way) -> None:
    f = way(compensated_friction)
    assert f(P, 120.0, 90.0) == 120.0  # the window fit
    assert f(P._replace(raw_estimate=True), 120.0, 90.0) == 90.0  # the one-step UIO formula
    assert f(P._replace(compensation=False), 120.0, 90.0) == 0.0
    assert f(P, math.nan, 90.0) == 0.0  # a non-finite estimate is not compensated
    assert f(P._replace(raw_estimate=True), 120.0, math.inf) == 0.0


def test_low_speed_residual_by_hand(way) -> None:
    f = way(low_speed_force)
    assert f(P, 0.5) == 1000.0 * (1.0 - 0.5 / 2.0) == 750.0
    assert f(P, 1.5) == 250.0
    assert f(P, -1.0) == 1000.0  # backwards: the whole resistance (the speed clipped at 0)
    assert f(P, 2.0) == 0.0 and f(P, 7.0) == 0.0  # inside the box the model has it
    assert f(P, math.nan) == 0.0
    assert f(P._replace(low_speed=False), 0.5) == 0.0


@pytest.mark.parametrize("bad", [0, 1, 2])
def test_a_non_finite_estimate_holds_the_last_input(way, bad: int) -> None:
    f = way(inner_step)
    s = np.array([1.0, 2.0, 3.0, 1.0, 1234.5, -0.03])
    x = [5.0, 0.01, 0.1]
    x[bad] = math.nan
    out = f(P, _law(), s, x[0], x[1], x[2], 120.0, 90.0, 5.0, 0.1)
    assert tuple(out) == (1234.5, -0.03, True, 0.0, 0.0, LQR_HELD)
    np.testing.assert_array_equal(s, [1.0, 2.0, 3.0, 1.0, 1234.5, -0.03])  # nothing moved


def test_without_a_law_the_numpy_step_gets_the_terms() -> None:
    """TSLQR without the compiled law (TSMPC_NO_JIT, or jit=False) hands the step to its numpy law
    with the compensation and the residual the block computed."""
    s = np.zeros(6)
    out = inner_step(P, None, s, 0.5, 0.0, 0.0, 120.0, 90.0, 1.0, 0.0)
    assert (out.status, out.F_comp, out.F_low_speed) == (LQR_NUMPY, 120.0, 750.0)
    assert not s.any()


@pytest.mark.parametrize("ok", [True, False])
def test_the_law_gets_both_force_terms_and_its_answer_passes(monkeypatch, ok: bool) -> None:
    """The block as Python, with a stand-in law: it receives F̂ + the residual outside the filter
    and the references; its answer is the block's, or (N̄ singular) the numpy step decides."""
    seen = []

    def law(s, v, al, om, F_add, v_ref, w_ref, *rest):
        seen.append((v, al, om, F_add, v_ref, w_ref, len(rest)))
        return 11.0, 0.02, True, ok

    monkeypatch.setattr(ts_lqr, "lqr_step", law)
    out = inner_step(P._replace(raw_estimate=True), _law(), np.zeros(6), 1.0, 0.01, 0.1, 120.0, 90.0,
                     3.0, 0.2)
    assert seen == [(1.0, 0.01, 0.1, 90.0 + 500.0, 3.0, 0.2, 14)]
    want = (11.0, 0.02, True, 90.0, 500.0, LQR_OK) if ok else (0.0, 0.0, False, 90.0, 500.0, LQR_NUMPY)
    assert tuple(out) == want


def test_a_singular_reference_gain_goes_to_the_numpy_step(way) -> None:
    f = way(inner_step)
    if kernels.load("lqr") is None:
        pytest.skip("compiled kernels unavailable")
    s = np.zeros(6)
    out = f(P, _law(nan_gains=True), s, 5.0, 0.0, 0.0, 120.0, 90.0, 5.0, 0.0)
    assert out.status == LQR_NUMPY and (out.F_comp, out.F_low_speed) == (120.0, 0.0)
    assert not s.any()  # the numpy step starts from the same state


def test_compiled_equals_python_through_the_real_law() -> None:
    """Random estimates, references and switches: the compiled block and the block as Python (the
    law's dispatcher) give the same commands and the same controller state, to the bit."""
    nb = _compiled(inner_step)
    rng = np.random.default_rng(34)
    law = _law()
    s_py, s_nb = np.zeros(6), np.zeros(6)
    for i in range(600):
        p = P._replace(compensation=bool(rng.random() < 0.8), raw_estimate=bool(rng.random() < 0.5),
                       low_speed=bool(rng.random() < 0.8))
        v = float(rng.uniform(-0.5, 8.0)) if i % 97 else math.nan
        args = (v, float(rng.normal(0, 0.05)), float(rng.normal(0, 0.3)), float(rng.normal(200, 300)),
                float(rng.normal(200, 600)), float(rng.uniform(0, 8)), float(rng.normal(0, 0.3)))
        a = inner_step(p, law, s_py, *args)
        b = nb(p, law, s_nb, *args)
        assert tuple(a) == tuple(b), (i, args)
        assert s_py.tobytes() == s_nb.tobytes(), i


@pytest.mark.parametrize("engine", [True, False])
def test_both_force_terms_reach_the_command_in_both_loops(paper_reference_path: Path, engine: bool) -> None:
    """The paper's reference starts at 0.12 m/s, below the box's floor (2 m/s). At the first inner
    step (same estimate, same filter with the switch on and off) the force differs by exactly the
    residual μ_o M g (1 − v̂ / v_min); at the second (the same history: F̂ = 0 at the first) the
    one-step UIO formula's run differs from the window fit's by exactly F̂_raw − F̂. In the run
    engine and in the Python loop alike."""
    from tsmpc.sim import engine as eng
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.simulator import simulate

    if engine and kernels.load("lqr") is None:
        pytest.skip("compiled kernels unavailable (no run engine)")
    logs = {}
    for low, est in ((True, "window"), (False, "window"), (True, "uio")):
        cfg = apply_overrides(Config(), [f"lqr.low_speed_resistance={str(low).lower()}",
                                         f"lqr.friction_estimate={est}"])
        sc = load_scenario(cfg, paper_reference_path)
        eng.LAST_RUN.clear()
        logs[low, est] = simulate(cfg, "REF", sc, engine=engine, max_steps=1)
        assert bool(eng.LAST_RUN) == engine, eng.applicability(cfg, "REF", sc)
    on, off, uio = logs[True, "window"], logs[False, "window"], logs[True, "uio"]
    veh, v_min = cfg.vehicle, float(cfg.dynamic_box.v[0])
    f_max = cfg.lqr.force_limits(veh)[1]
    # the residual, at the first step
    v_hat = float(on.estimate[0, 0])
    assert v_hat == float(off.estimate[0, 0]) and v_hat < 1.0
    want = veh.mu_nominal * veh.g * veh.mass * (1.0 - max(v_hat, 0.0) / v_min)
    assert on.command[0, 0] < f_max  # not saturated: the whole residual is in the force
    assert on.command[0, 0] - off.command[0, 0] == pytest.approx(want, rel=1e-9)
    assert on.command[0, 1] == off.command[0, 1]
    # the compensated estimate, at the second step
    np.testing.assert_array_equal(uio.estimate[:2], on.estimate[:2])
    gap = float(uio.F_fr_raw[1] - on.F_fr_hat[1])
    assert abs(gap) > 500.0, gap  # the two estimates differ there: the choice shows
    assert max(uio.command[1, 0], on.command[1, 0]) < f_max
    assert uio.command[1, 0] - on.command[1, 0] == pytest.approx(gap, rel=1e-9)
