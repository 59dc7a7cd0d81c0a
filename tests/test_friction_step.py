"""``lqr.friction_step`` (estimation/friction_step.py): a CUSUM test on the one-step UIO friction
estimate's innovation against the MHE window fit; after a detected step the one-step estimate is
compensated for one window, then the window fit again.

The detector is checked on synthetic signals where the truth is known — its false-alarm rate on
Gaussian noise (the CUSUM's in-control run length with drift 1 σ and threshold 5 σ is ≈ 5.7·10⁴
samples, Siegmund's approximation, so 2·10⁴ samples give ≈ 0.35 alarms on average), its delay on a
shift of 2.5 σ (1.5 σ of evidence per sample against a threshold of 5 σ: the fourth sample), the
hand-back after one window, and that rejected samples neither detect nor reach the output. The
whole cascade is checked where it bit (docs/mismatch.md, mu_step): the road loses its grip at the
first corner's apex (μ 0.9 → 0.3, tyres with a friction ellipse); the window fit alone follows
over its 0.3 s window while the rear tyre cannot transmit the force that held the speed, and the
car spins (measured: diverged 4.5 s after the step); with the detector it completes (measured:
largest |e_y| 0.16 m)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tsmpc.config import Config, apply_overrides
from tsmpc.estimation.friction_step import MIN_SAMPLES, FrictionStep
from tsmpc.sim import experiment

SIGMA = 400.0  # N: the one-step estimate's noise order (σ_v = 5 mm/s × M / T_d ≈ 340 N)


def _quiet(fs: FrictionStep, rng: np.random.Generator, n: int, F: float = 2700.0) -> list[float]:
    return [fs.step(F, F + SIGMA * rng.standard_normal(), True) for _ in range(n)]


def test_noise_alone_almost_never_declares_a_step() -> None:
    fs = FrictionStep(window=30, threshold=5.0)
    out = _quiet(fs, np.random.default_rng(0), 20_000)
    assert fs.n_steps <= 2, fs.n_steps  # expected ≈ 0.35 (see the module docstring)
    assert sum(o != 2700.0 for o in out) <= 30 * fs.n_steps  # quiet: the window fit passes through


@pytest.mark.parametrize("sign", [-1.0, 1.0])  # grip lost or regained
def test_a_step_is_detected_within_a_few_samples_and_handed_back_after_one_window(sign: float) -> None:
    rng = np.random.default_rng(1)
    fs = FrictionStep(window=30, threshold=5.0)
    _quiet(fs, rng, 500)
    n0 = fs.n_steps
    after = 2700.0 + sign * 2.5 * SIGMA
    raw = [after + SIGMA * 0.2 * rng.standard_normal() for _ in range(80)]
    # the window fit: still the old force until the window holds only samples after the step
    window = [2700.0 if k < 30 else after for k in range(80)]
    out = [fs.step(w, r, True) for w, r in zip(window, raw, strict=True)]
    assert fs.n_steps == n0 + 1
    first = next(i for i, (o, r) in enumerate(zip(out, raw, strict=True)) if o == r)
    assert first <= 4, first  # 1.5 σ of evidence per sample against h = 5 σ: the fourth sample
    # the one-step estimate for one window (the window then holds only samples after the step) …
    assert all(o == r for o, r in zip(out[first:first + 30], raw[first:first + 30], strict=True))
    assert out[first + 30:] == window[first + 30:]  # … then the window fit again


def test_rejected_samples_neither_detect_nor_reach_the_output() -> None:
    fs = FrictionStep(window=30, threshold=5.0)
    rng = np.random.default_rng(2)
    _quiet(fs, rng, MIN_SAMPLES + 10)
    for bad in (np.nan, np.inf, -1e6):  # not ok: whatever the one-step estimate says
        assert fs.step(2700.0, bad, False) == 2700.0
    assert fs.n_steps == 0
    assert fs.step(2700.0, np.nan, True) == 2700.0  # a non-finite estimate counts as rejected
    while not fs.active:  # a real step …
        fs.step(2700.0, 0.0, True)
    assert fs.step(2700.0, np.nan, False) == 2700.0  # … and a rejected sample inside it
    assert fs.step(2700.0, 5.0, True) == 5.0


def test_no_step_before_the_innovation_variance_is_known() -> None:
    fs = FrictionStep(window=30, threshold=5.0)
    out = [fs.step(2700.0, -5000.0, True) for _ in range(MIN_SAMPLES)]
    assert fs.n_steps == 0 and all(o == 2700.0 for o in out)


@pytest.mark.parametrize("bad", [dict(window=0), dict(threshold=0.0), dict(threshold=float("nan"))])
def test_bad_parameters_are_refused(bad: dict) -> None:
    with pytest.raises(ValueError, match="FrictionStep"):
        FrictionStep(**{"window": 30, "threshold": 5.0, **bad})


MU_STEP = ["scenario.base_mu=0.9", "scenario.replan_for_force_budget=true",
           "scenario.plant.combined_slip=true", "scenario.plant.grip_scales_with_road=true",
           "scenario.friction=[{at_corner = 1, mu = 0.3, duration_s = 5.0}]", "seed=1"]


@pytest.mark.parametrize("on", [True, False])
def test_a_sudden_loss_of_grip_mid_corner_is_survived(paper_reference_path: Path, on: bool) -> None:
    """examples/mismatch.toml's mu_step on the paper's reference, the first 50 s (the step at
    ≈ 42.2 s): without the detector the car spins; with it |e_y| stays well inside the bound."""
    cfg = apply_overrides(Config(), [*MU_STEP, f"lqr.friction_step={str(on).lower()}"])
    exp = experiment.prepare(cfg, ["ref"], reference=paper_reference_path, duration=50.0)
    res = experiment.run(exp, None, plots=False)
    log = res.logs["REF"]
    ey = np.abs(log.errors[:, 1])
    if on:
        assert log.termination == "completed", log.termination
        assert ey.max() <= 0.3, ey.max()  # measured 0.16 m over the whole run
        assert log.events["friction_steps"] >= 1
    else:
        assert log.termination.startswith("diverged"), (log.termination, ey.max())
