"""The yaw-rate sensor's bias as a state of the measurement fusion (``fusion.gyro_bias``, issue 35):
the block alone on a synthetic turn (Python and compiled), and the closed loop on the paper's
reference — the acceptance of issue 35's first line and engine = Python cascade on a biased gyro.

θ̇ = ω holds exactly (kinematics, no model), so a chord of D seconds between two measured headings
measures the bias as b = (∫ω_measured dt − Δθ_measured) / D with the noise
√(2 σ_θ² + D T_d σ_ω²) / D; the fit is the exponentially forgotten, weighted mean of the chords."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from _blocks import Blocks
from _paths import need_data
from tsmpc import kernels
from tsmpc.conditions import apply_conditions
from tsmpc.config import Config, replace
from tsmpc.estimation import fusion as fu
from tsmpc.estimation.fusion import GYRO_CHORD_S, GYRO_MAX_GAP_S, GYRO_MEMORY_S, GYRO_PRIOR_SIGMA
from tsmpc.sim import engine as eng
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import simulate

_BLOCKS = ("gyro_params", "gyro_start", "gyro_sample", "gyro_bias")
_Blocks = Blocks


@pytest.fixture(params=["python", "compiled"])
def b(request) -> _Blocks:
    if request.param == "compiled" and kernels.load("mpc") is None:
        pytest.skip("compiled kernels unavailable")
    return Blocks(fu, _BLOCKS, request.param == "compiled")


TD = 0.01


def _turn(seconds: float, bias, sig_th: float, sig_w: float, seed: int = 7):
    """A car weaving through turns (ω = 0.4 sin(0.3 t) + 0.1 rad/s, the heading its exact integral,
    wrapped): (t, measured θ, measured ω = ω + bias(t) + noise)."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds / TD) + 1) * TD
    w = 0.4 * np.sin(0.3 * t) + 0.1
    th = (0.4 / 0.3) * (1.0 - np.cos(0.3 * t)) + 0.1 * t + 2.5  # crosses ±π
    th_m = (th + sig_th * rng.standard_normal(t.size) + math.pi) % (2.0 * math.pi) - math.pi
    w_m = w + bias(t) + sig_w * rng.standard_normal(t.size)
    return t, th_m, w_m


def _chord_sigma(sig_th: float, sig_w: float, D: float = GYRO_CHORD_S) -> float:
    """The bias noise of one chord of D seconds."""
    return math.sqrt(2.0 * sig_th**2 + D * TD * sig_w**2) / D


def _bound(sig_th: float, sig_w: float) -> float:
    """4 σ of the fit in steady state: exponential forgetting over chords of GYRO_CHORD_S averages
    N_eff = (1 + g) / (1 − g) chords (g = exp(−D / memory)); consecutive chords share their end
    headings, whose errors cancel in the sum, so independent chords are the pessimistic case."""
    g = math.exp(-GYRO_CHORD_S / GYRO_MEMORY_S)
    return 4.0 * _chord_sigma(sig_th, sig_w) / math.sqrt((1.0 + g) / (1.0 - g))


def _feed(b: _Blocks, p, s, th, w, heading=None, omega=None):
    """Samples into the fit; (the estimate after each sample, the state)."""
    out = np.empty(len(th))
    for k in range(len(th)):
        hh = True if heading is None else bool(heading[k])
        ho = True if omega is None else bool(omega[k])
        s = b.gyro_sample(p, s, hh, float(th[k]), ho, float(w[k]))
        out[k] = b.gyro_bias(s)
    return out, s


@pytest.mark.parametrize(("sig_th", "sig_w"), [(1e-4, 1e-4), (1e-3, 1e-3)])
def test_the_fit_converges_to_a_constant_bias_within_its_noise(b: _Blocks, sig_th: float,
                                                                sig_w: float) -> None:
    """0.01 rad/s on a weaving turn, at the default σ's and at 10× them. At every sample after the
    first chord the estimate is within 4 σ of the fit's own noise 1/√Σw (a pessimistic σ: the
    forgotten weights and the shared chord ends only lower the true variance) plus the prior's pull
    b w_prior / Σw. The fit is fast: at the default σ's that bound is below half the bias by 0.5 s
    (a fresh fit's chords grow from one sample) and below 10 % by 2 s. After 60 s it holds within
    4 σ of the steady fit."""
    t, th, w = _turn(60.0, lambda t: 0.01 + 0 * t, sig_th, sig_w)
    p = b.gyro_params(TD, sig_th, sig_w)
    s = b.gyro_start(p)
    assert b.gyro_bias(s) == 0.0 and s.sw == p.prior_w
    bound = np.full(len(t), np.inf)
    est = np.empty(len(t))
    for k in range(len(t)):
        s = b.gyro_sample(p, s, True, float(th[k]), True, float(w[k]))
        est[k] = b.gyro_bias(s)
        if s.n_chords:
            bound[k] = 4.0 / math.sqrt(s.sw) + 0.01 * p.prior_w / s.sw
    assert math.isinf(bound[0]) and est[0] == 0.0  # one heading: no chord yet
    assert np.all(np.abs(est - 0.01) <= bound), np.max(np.abs(est - 0.01) / bound)
    if sig_th == 1e-4:  # a fresh fit's chords start at one sample: half the bias by 0.5 s
        assert bound[50] < 0.5 * 0.01 and bound[200] < 0.1 * 0.01, (bound[50], bound[200])
    assert s.n_chords >= round(60.0 / GYRO_CHORD_S)
    tail = est[-round(10.0 / TD):]
    assert np.max(np.abs(tail - 0.01)) < _bound(sig_th, sig_w), np.max(np.abs(tail - 0.01))


def test_the_fit_tracks_a_drifting_bias(b: _Blocks) -> None:
    """A bias drifting at 1e-4 rad/s per s (0.34 °/s per minute): the exponentially forgotten mean
    lags a ramp by about its memory, so the error stays near d · GYRO_MEMORY_S, never beyond
    1.5× it, and is well below the drift's own 6e-3 rad/s over the minute."""
    d = 1e-4
    t, th, w = _turn(90.0, lambda t: 0.005 + d * t, 1e-4, 1e-4)
    p = b.gyro_params(TD, 1e-4, 1e-4)
    est, _ = _feed(b, p, b.gyro_start(p), th, w)
    err = est - (0.005 + d * t)
    late = err[t >= 3.0 * GYRO_MEMORY_S - 1e-9]
    assert np.all(np.abs(late) < 1.5 * d * GYRO_MEMORY_S), np.max(np.abs(late))
    assert np.all(late < 0.0)  # it lags (ramp up: the estimate is behind)


def test_without_headings_the_estimate_holds(b: _Blocks) -> None:
    """Fit 10 s, then 20 s without a heading (5 s of poses without θ, 15 s of NaN headings): the
    estimate does not move, and no chord counts. The bias of a fresh fit
    without any heading stays at the prior 0."""
    t, th, w = _turn(30.0, lambda t: 0.02 + 0 * t, 1e-4, 1e-4)
    p = b.gyro_params(TD, 1e-4, 1e-4)
    n10 = round(10.0 / TD)
    est, s = _feed(b, p, b.gyro_start(p), th[:n10], w[:n10])
    b10, c10 = est[-1], s.n_chords
    assert abs(b10 - 0.02) < 1e-3
    th_nan = th.copy()
    th_nan[n10 + 500:] = math.nan
    k = np.arange(len(t))
    heading = (k < n10) | (k >= n10 + 500)  # 5 s of poses without θ, then 15 s of NaN headings
    est2, s2 = _feed(b, p, s, th_nan[n10:], w[n10:], heading=heading[n10:])
    assert np.all(est2 == b10) and s2.n_chords == c10
    est0, s0 = _feed(b, p, b.gyro_start(p), np.full(500, math.nan), w[:500])
    assert np.all(est0 == 0.0) and s0.n_chords == 0 and s0.sw == 1.0 / GYRO_PRIOR_SIGMA**2


def test_a_missing_yaw_rate_is_held_briefly_and_a_long_gap_drops_the_chord(b: _Blocks) -> None:
    """Every other yaw rate missing (a 50 Hz gyro at T_d = 10 ms): held, the bias is still found;
    a gap beyond GYRO_MAX_GAP_S drops the open chord (no chord ends across it)."""
    t, th, w = _turn(20.0, lambda t: -0.01 + 0 * t, 1e-4, 1e-4)
    p = b.gyro_params(TD, 1e-4, 1e-4)
    half = np.arange(len(t)) % 2 == 0
    est, _ = _feed(b, p, b.gyro_start(p), th, np.where(half, w, math.nan), omega=half)
    assert abs(est[-1] + 0.01) < 2e-4  # the hold's error: ω̇ T_d / 2 at most, averaged over turns
    # after 10 s, 0.7 s without a yaw rate: held for GYRO_MAX_GAP_S, then the open chord is dropped
    # (no chord ends across the gap, the estimate holds), and a chord starts with the next ω
    n10 = round(10.0 / TD)
    _, s = _feed(b, p, b.gyro_start(p), th[:n10], w[:n10])
    g0, g1 = n10, n10 + 70
    opened, ends = [], []
    for k in range(g0, g1 + 1):
        before = s.n_chords
        s = b.gyro_sample(p, s, True, float(th[k]), k >= g1, float(w[k]) if k >= g1 else math.nan)
        opened.append(s.open)
        ends.append(s.n_chords - before)
    n_held = round(GYRO_MAX_GAP_S / TD)  # samples held; the next one drops the chord
    assert all(opened[:n_held]) and not any(opened[n_held:-1]) and sum(ends[n_held:]) == 0
    assert s.open and s.n == 0 and s.th0 == th[g1]


# ------------------------------------------------------------------------------ closed loop
def _case(bias: float, *, gyro: bool = True) -> tuple[Config, Any]:
    cfg = Config()
    cfg = replace(cfg, fusion=replace(cfg.fusion, gyro_bias=gyro), scenario=replace(
        cfg.scenario, sensors=replace(cfg.scenario.sensors, omega_bias=bias)))
    case = apply_conditions(cfg, load_scenario(cfg, need_data("paper")))
    return case.config, case.scenario


def _metrics(bias: float, *, gyro: bool = True) -> dict[str, float]:
    cfg, sc = _case(bias, gyro=gyro)
    m = compute_metrics(simulate(cfg, "REF", sc))
    assert m["termination"] == "completed"
    return {**m["rmse"], "max_e_y": m["max_abs_lateral_m"]}


@pytest.fixture(scope="module")
def runs() -> dict[str, dict[str, float]]:
    """REF, seed 1, the paper's reference: calibrated (bias 0), the gyro 0.01 rad/s off, and the
    calibrated gyro with the fit off (the nominal run before the fit)."""
    return {"calibrated": _metrics(0.0), "biased": _metrics(0.01), "off": _metrics(0.0, gyro=False)}


def test_a_biased_gyro_tracks_like_a_calibrated_one(runs) -> None:
    """Issue 35: with a 0.01 rad/s (0.57 °/s) yaw-rate bias, RMSE y and max |e_y| within 1.5× the
    calibrated run's (without the fit: 11× and 4.9×)."""
    cal, bia = runs["calibrated"], runs["biased"]
    for col in ("y", "max_e_y"):
        assert bia[col] <= 1.5 * cal[col], (col, bia[col], cal[col])


def test_the_fit_costs_the_calibrated_gyro_nothing(runs) -> None:
    """Issue 35: the nominal run (bias 0) with the fit no column more than 2 % worse than without it."""
    on, off = runs["calibrated"], runs["off"]
    for col in ("x", "y", "theta", "v", "omega", "max_e_y"):
        assert on[col] <= 1.02 * off[col], (col, on[col], off[col])


def test_the_engine_equals_the_python_cascade_on_a_biased_gyro() -> None:
    """A drifting, biased gyro (the fit busy all along): the compiled engine and the Python loop give
    the same run to 1e-8 (every logged array, events, termination)."""
    cfg, sc = _case(0.02)
    cfg = replace(cfg, scenario=replace(cfg.scenario, sensors=replace(
        cfg.scenario.sensors, omega_drift=2e-4, dropout_probability=0.02)))
    case = apply_conditions(cfg, load_scenario(cfg, need_data("paper")))
    cfg, sc = case.config, case.scenario
    assert eng.applicability(cfg, "REF", sc) is None
    eng.LAST_RUN.clear()
    le = simulate(cfg, "REF", sc, engine=True, max_steps=300)
    assert eng.LAST_RUN
    lp = simulate(cfg, "REF", sc, engine=False, max_steps=300)
    assert le.events == lp.events and le.termination == lp.termination
    for name, a in le.arrays().items():
        if a.dtype.kind == "f" and not name.endswith("time_s"):
            np.testing.assert_allclose(a, lp.arrays()[name], rtol=0, atol=1e-8, equal_nan=True, err_msg=name)
    # and the fit acted: the MHE's ω̂ follows the true yaw rate, not the biased sensor
    w_err = lp.estimate[100:, 2] - lp.state[100:, 5]
    assert abs(float(np.mean(w_err))) < 2e-3
