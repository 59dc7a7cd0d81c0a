"""The blocks' one definitions (tsmpc.kernels.jit): each runs as Python from the cascade and compiled
inside the engine. Here: both ways agree to the bit on random inputs, and the arithmetic of each
gate, fit and blend is pinned by hand-computed values (a mutation of it fails a test)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.control import gates
from tsmpc.control.slip_aware import BASELINE, GATE_RAD, slip_gate_update
from tsmpc.estimation.friction_step import (
    DRIFT,
    MIN_SAMPLES,
    FrictionStepParams,
    FrictionStepState,
    friction_step_update,
)
from tsmpc.kernels.jit import cpython_hypot, exact_hypot
from tsmpc.scenarios import _in_burst, _ramp, apply_events, event_weight, paper_mu, patch_mu


def _hypot_call(a: float, b: float) -> float:
    """exact_hypot as a compiled caller sees it (its overload; njit of exact_hypot itself would
    compile its Python body, libm's hypot)."""
    return exact_hypot(a, b)


G = gates.GateParams(v_lo=-1.0, v_hi=40.0, w_limit=4.0, pose_noise=0.05, heading_noise=0.01, Td=0.01)


def _compiled(fn):
    """``fn`` compiled by numba as the engine compiles it (a plain njit of the same source)."""
    if kernels.load("mpc") is None:
        pytest.skip("compiled kernels unavailable")
    from numba import njit

    return njit(cache=False)(fn)


@pytest.mark.parametrize("fn, draw", [
    (gates.plausible_speeds, lambda r: (G, r.normal(0, 30), r.normal(0, 4))),
    (gates.pose_consistent, lambda r: (G, *r.normal(0, 2, 3), *r.normal(0, 2, 3), r.uniform(-0.1, 2))),
    (gates.dead_reckon, lambda r: (G, *r.normal(0, 100, 3), r.normal(10, 10), *r.normal(0, 0.2, 2))),
    (gates.jump_run, lambda r: (G, 2.0, r.uniform(0, 3), *r.normal(0, 2, 3), 1.0, *r.normal(0, 2, 3),
                                r.uniform(1, 4))),
    (gates.blind_stop, lambda r: (r.normal(2, 3), r.normal(0, 0.2), 683.0, 3.0, -2000.0, 10000.0)),
    (_hypot_call, lambda r: tuple(r.normal(0, 1e3, 2) * r.choice([1e-6, 1.0, 1e3], 2))),
    (event_weight, lambda r: (r.uniform(-5, 25), 2.0, r.choice([0.0, 1.5]), 12.0)),
    (paper_mu, lambda r: (r.uniform(0, 130), 0.9, 0.002, 0.68, 0.1, 0.6)),
    (_in_burst, lambda r: (r.uniform(0, 30), 3.0, 7.0, 0.05)),
    (_ramp, lambda r: (r.uniform(0, 5), 1.0, 2.0, 3.0, 4.0, 0.9, 0.3)),
])
def test_compiled_equals_python_to_the_bit(fn, draw) -> None:
    """Random inputs through both ways of one definition: identical results (the engine's
    bit-identity with the Python loop rests on it)."""
    nb = _compiled(fn)
    rng = np.random.default_rng(7)
    for _ in range(400):
        args = draw(rng)
        args = tuple(float(a) if isinstance(a, np.floating) else a for a in args)
        assert nb(*args) == fn(*args), (fn.__name__, args)


def test_friction_step_compiled_equals_python() -> None:
    nb = _compiled(friction_step_update)
    p = FrictionStepParams(30, 5.0)
    rng = np.random.default_rng(3)
    s_py = s_nb = FrictionStepState()
    for i in range(3000):
        Fw, Fr = 100.0 + rng.normal(0, 5), 100.0 + rng.normal(0, 300) + (900.0 if i > 1500 else 0.0)
        ok = bool(rng.random() > 0.02)
        a = friction_step_update(p, s_py, Fw, Fr, ok)
        b = nb(p, s_nb, Fw, Fr, ok)
        assert a[0] == b[0] and a[2] == b[2] and tuple(a[1]) == tuple(b[1])
        s_py, s_nb = a[1], FrictionStepState(*b[1])


def test_slip_gate_and_patches_compiled_equal_python() -> None:
    nb_gate, nb_patch, nb_events = (_compiled(f) for f in (slip_gate_update, patch_mu, apply_events))
    rng = np.random.default_rng(5)
    pa, pb = np.zeros((BASELINE + 1, 3)), np.zeros((BASELINE + 1, 3))
    na = nb = 0
    x = y = th = 0.0
    for _ in range(300):
        x, y, th = x + rng.uniform(0, 2), y + rng.normal(0, 0.3), th + rng.normal(0, 0.02)
        a_hat = float(rng.normal(0, 0.03))
        ra, na = slip_gate_update(0.01, pa, na, x, y, th, a_hat)
        rb, nb = nb_gate(0.01, pb, nb, x, y, th, a_hat)
        assert ra == rb and na == nb and np.array_equal(pa, pb)
    patches = np.array([[10.0, 30.0, 0.4, 5.0], [50.0, 60.0, 0.2, 0.0]])
    events = np.array([[1.0, 2.0, 1.0, 8.0, 0.5], [0.0, 20.0, 4.0, math.inf, 0.3]])
    for s in rng.uniform(-5, 200, 300):
        assert nb_patch(s, 0.9, 100.0, patches) == patch_mu(s, 0.9, 100.0, patches)
        m = float(rng.uniform(0.2, 1.0))
        t = float(rng.uniform(0, 10))
        assert nb_events(m, t, s, events) == apply_events(m, t, s, events)


def test_gate_arithmetic_by_hand() -> None:
    assert gates.plausible_speeds(G, 39.9, -3.9) and not gates.plausible_speeds(G, 40.1, 0.0)
    assert not gates.plausible_speeds(G, -1.1, 0.0) and not gates.plausible_speeds(G, 0.0, 4.1)
    assert gates.plausible_speeds(G, math.nan, 100.0)  # NaN: the MHE's to reject
    # distance allowance 1 m + 2 m/s dt + 0.05 m; heading 0.3 + 0.5 rad/s dt + 0.01 rad
    assert gates.pose_consistent(G, 1.04, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert not gates.pose_consistent(G, 1.06, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert gates.pose_consistent(G, 3.04, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert not gates.pose_consistent(G, 3.06, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert gates.pose_consistent(G, 0.0, 0.0, 0.80, 0.0, 0.0, 0.0, 0.98)  # 0.3 + 0.49 + 0.01
    assert not gates.pose_consistent(G, 0.0, 0.0, 0.81, 0.0, 0.0, 0.0, 0.98)
    assert gates.pose_consistent(G, 0.0, 0.0, 2 * math.pi - 0.2, 0.0, 0.0, 0.0, 0.0)  # wrapped
    assert not gates.pose_consistent(G, 1.06, 0.0, 0.0, 0.0, 0.0, 0.0, -5.0)  # dt < 0 counts as 0
    X, Y, th = gates.dead_reckon(G, 1.0, 2.0, 0.5, 10.0, 0.1, 0.2)
    assert (X, Y, th) == pytest.approx((1.0 + 0.1 * math.cos(0.6), 2.0 + 0.1 * math.sin(0.6), 0.502),
                                       abs=1e-15)
    assert gates.dead_reckon(G, 1.0, 2.0, 0.5, -3.0, 0.1, 0.2)[:2] == (1.0, 2.0)  # v clipped to 0
    v_hi = gates.dead_reckon(G, 1.0, 2.0, 0.5, 80.0, 0.0, 0.0)[0]  # the speed clipped to v_hi
    assert v_hi == pytest.approx(1.0 + 0.4 * math.cos(0.5))
    assert gates.dead_reckon(G, 1.0, 2.0, 0.5, math.nan, 0.0, 0.0) == (1.0, 2.0, 0.5)
    assert cpython_hypot(3e-200, 4e-200) == math.hypot(3e-200, 4e-200)


def test_friction_step_arithmetic_by_hand() -> None:
    p = FrictionStepParams(window=3, threshold=5.0)
    s = FrictionStepState()
    for i in range(MIN_SAMPLES):  # the variance learns: mean of d² over the first samples
        F, s, dec = friction_step_update(p, s, 0.0, 10.0 if i % 2 else -10.0, True)
        assert F == 0.0 and not dec
    assert s.var == pytest.approx(100.0) and s.n_var == MIN_SAMPLES
    # a 3.5σ innovation: z = 3.5, g⁺ = 3.5 − k = 2.5 (beyond 3σ: the variance does not learn it)
    F, s, dec = friction_step_update(p, s, 0.0, 35.0, True)
    assert s.g_plus == pytest.approx(3.5 - DRIFT) and s.var == pytest.approx(100.0) and not dec
    F, s, dec = friction_step_update(p, s, 0.0, 35.0, True)  # g⁺ = 5: not beyond h yet
    assert s.g_plus == pytest.approx(5.0) and not dec and F == 0.0
    F, s, dec = friction_step_update(p, s, 0.0, 35.0, True)  # g⁺ = 7.5 > 5: a step, F_raw used
    assert dec and F == 35.0 and s.since == 1
    for k in (2, 3):  # compensated for the window (3 samples), then the window fit again
        F, s, dec = friction_step_update(p, s, 0.0, 40.0, True)
        assert F == 40.0 and s.since == k
    F, s, dec = friction_step_update(p, s, 0.0, 40.0, True)
    assert F == 0.0 and s.since == 0 and s.g_plus == 0.0
    assert friction_step_update(p, s, 0.0, math.nan, True)[0] == 0.0


def test_slip_gate_arithmetic_by_hand() -> None:
    poses = np.zeros((BASELINE + 1, 3))
    a, n = slip_gate_update(0.0, poses, 0, 0.0, 0.0, 0.0, 0.05)
    assert (a, n) == (0.05, 1)  # one pose: no chord yet
    a, n = slip_gate_update(0.0, poses, n, 10.0, 0.0, 0.0, 0.05)
    assert n == 2 and a == pytest.approx(GATE_RAD)  # the course says 0: α̂ bounded to the band
    a, n = slip_gate_update(0.0, poses, n, 20.0, 1.0, 0.0, -0.05)
    assert a == pytest.approx(math.atan2(1.0, 20.0) - GATE_RAD)  # course atan2(1, 20), band below
    for k in range(10):  # the ring keeps BASELINE + 1 poses, oldest first
        a, n = slip_gate_update(0.0, poses, n, 30.0 + k, 1.0, 0.0, 0.0)
    assert n == BASELINE + 1 and poses[0, 0] == 39.0 - BASELINE
    band = GATE_RAD + 4.0 * math.sqrt(2.0) * 0.1 / 10.0  # the position noise widens the band
    p2 = np.zeros((BASELINE + 1, 3))
    slip_gate_update(0.1, p2, 0, 0.0, 0.0, 0.0, 0.0)
    assert slip_gate_update(0.1, p2, 1, 10.0, 0.0, 0.0, 1.0)[0] == pytest.approx(band)


def test_friction_programs_by_hand() -> None:
    assert paper_mu(0.0, 0.9, 0.002, 0.68, 0.1, 0.6) == 0.9
    assert paper_mu(15.5, 0.9, 0.0, 0.68, 0.1, 0.6) == pytest.approx(0.79)  # half-way down the ramp
    assert paper_mu(70.05, 0.9, 0.0, 0.68, 0.1, 0.6) == 0.1
    assert paper_mu(119.5, 0.9, 0.0, 0.68, 0.1, 0.6) == pytest.approx(0.75)
    patches = np.array([[10.0, 30.0, 0.4, 5.0]])
    assert patch_mu(12.5, 0.9, 0.0, patches) == pytest.approx(0.65)  # half the entry ramp
    assert patch_mu(20.0, 0.9, 0.0, patches) == pytest.approx(0.4)
    assert patch_mu(27.5, 0.9, 0.0, patches) == pytest.approx(0.65)  # half the exit ramp (inside)
    assert patch_mu(112.5, 0.9, 100.0, patches) == pytest.approx(0.65)  # the next lap
    assert event_weight(3.0, 2.0, 2.0, 10.0) == 0.5 and event_weight(11.0, 2.0, 2.0, 10.0) == 0.5
    assert event_weight(1.9, 2.0, 0.0, 10.0) == 0.0 and event_weight(2.0, 2.0, 0.0, 10.0) == 1.0
    ev = np.array([[1.0, 0.0, 0.0, math.inf, 0.5], [1.0, 5.0, 2.0, math.inf, 0.1]])
    assert apply_events(0.9, 6.0, 0.0, ev) == pytest.approx(0.3)  # from the running 0.5, not 0.9
    assert _in_burst(3.02, 3.0, 7.0, 0.05) and not _in_burst(3.06, 3.0, 7.0, 0.05)
    assert _in_burst(10.02, 3.0, 7.0, 0.05) and not _in_burst(2.9, 3.0, 7.0, 0.05)


def test_every_module_with_a_block_is_in_the_engine_cache_key() -> None:
    """The engine's machine code holds the ``@jitable`` blocks it calls, and numba keys a cache
    entry by its own file only: every module defining one must be in BLOCK_MODULES (hashed into
    the engine's cache stamp), else an edit of it would leave a stale engine."""
    from pathlib import Path

    from tsmpc.kernels.jit import BLOCK_MODULES

    src = Path(__file__).resolve().parents[1] / "src"
    with_blocks = {".".join(p.relative_to(src).with_suffix("").parts)
                   for p in (src / "tsmpc").rglob("*.py") if "\n@jitable\n" in p.read_text(encoding="utf-8")}
    assert with_blocks and with_blocks <= set(BLOCK_MODULES), with_blocks - set(BLOCK_MODULES)


# The branches the rest of the block tests leave unexercised as Python (tests/test_block_coverage.py
# measures them): each pinned by hand.
def test_blind_stop_by_hand() -> None:
    """Brake at ``decel`` within [f_min, f_max] on a moving estimate (683 kg · 3 m/s² = 2049 N,
    clipped to 2000; at 2 m/s² 1366 N), on the last steering; no force at v̂ ≤ 0.05 m/s."""
    assert gates.blind_stop(2.0, 0.1, 683.0, 3.0, -2000.0, 10000.0) == (-2000.0, 0.1)
    assert gates.blind_stop(0.06, -0.2, 683.0, 2.0, -2000.0, 10000.0) == (-1366.0, -0.2)
    assert gates.blind_stop(0.05, 0.1, 683.0, 2.0, -2000.0, 10000.0) == (0.0, 0.1)
    assert gates.blind_stop(-1.0, 0.1, 683.0, -2.0, -2000.0, 10000.0) == (0.0, 0.1)


def test_gates_take_their_bounds_inclusive() -> None:
    """Each gate's bound is the largest accepted value (mutation checks: a `<` for a `<=` survived
    the tests above, which stop 0.01 short of each bound)."""
    assert gates.plausible_speeds(G, 40.0, 4.0) and gates.plausible_speeds(G, -1.0, -4.0)
    assert gates.pose_consistent(G, 1.05, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 1 m + 0 + 0.05 m exactly
    # heading: the wrapped difference of 0.31 rad is 0.31000000000000005 in floats; a dt of 6e-17 s
    # makes the allowance 0.3 + 0.5 dt + 0.01 exactly that (found by search, asserted here)
    dth = (0.31 + math.pi) % (2.0 * math.pi) - math.pi
    assert gates.HEADING_JUMP_RAD + gates.HEADING_DRIFT_RAD_PER_S * 6e-17 + 0.01 == dth
    assert gates.pose_consistent(G, 0.0, 0.0, 0.31, 0.0, 0.0, 0.0, 6e-17)


def test_a_jump_run_is_judged_over_the_time_since_its_last_pose() -> None:
    """jump_run compares a pose with the run's last one over t − lt (not t + lt, a mutation that
    survived): 5 m in 0.1 s at t = 100 s is a new run, 5 m in 2 s continues it."""
    assert gates.jump_run(G, 1.0, 99.0, 0.0, 0.0, 0.0, 99.9, 5.0, 0.0, 0.0, 100.0) == (False, 100.0)
    assert gates.jump_run(G, 1.0, 98.0, 0.0, 0.0, 0.0, 98.0, 5.0, 0.0, 0.0, 100.0) == (True, 98.0)


def test_ramps_and_the_ripple_by_hand() -> None:
    """_ramp's two ramps over spans other than 1 s (the paper's ramps are 1 s long, where a product
    for the quotient survived), and the sign of the paper profile's ripple."""
    assert _ramp(1.0, 0.0, 2.0, 5.0, 9.0, 1.0, 3.0) == 2.0  # half-way up a 2 s ramp
    assert _ramp(7.0, 0.0, 2.0, 5.0, 9.0, 1.0, 3.0) == 2.0  # half-way down a 4 s ramp
    assert _ramp(3.0, 0.0, 2.0, 5.0, 9.0, 1.0, 3.0) == 3.0
    t = math.pi  # sin(t / 2) = 1, outside every event of the profile
    assert paper_mu(t, 0.9, 0.05, 0.5, 0.1, 0.6) == pytest.approx(0.95, abs=1e-15)


def test_nearest_sample_by_hand() -> None:
    """The nearest sample within [k_lo, k_hi] (both ends included), the first of equals."""
    x = np.array([0.0, 1.0, 2.0, 3.0, 2.0, 1.0])
    y = np.zeros(6)
    assert gates.nearest_sample(x, y, 0, 5, 2.1, 0.0) == 2  # k = 2 and k = 4 tie: the first
    assert gates.nearest_sample(x, y, 3, 5, 2.1, 0.0) == 4
    assert gates.nearest_sample(x, y, 3, 5, 1.0, 0.0) == 5  # the last sample of the range
    assert gates.nearest_sample(x, y, 2, 2, 0.0, 9.0) == 2
    # both coordinates count, as squares that add, away from the origin (mutations survived with y ≡ 0)
    assert gates.nearest_sample(np.array([0.0, 1.0]), np.array([3.0, 0.0]), 0, 1, 0.0, 0.0) == 1
    assert gates.nearest_sample(np.array([0.0, 0.0]), np.array([4.0, -4.0]), 0, 1, 0.0, 5.0) == 0


def test_rate_limit_without_grip_estimate() -> None:
    """No finite grip estimate, or no second preview sample: the nominal limits."""
    from tsmpc.control.governor import GovernorParams, rate_limit

    p = GovernorParams(margin=0.8, rate_down=0.15, rate_up=0.05, rate_min=0.3, mu_plan=0.9, deadband=0.05,
                       traction_factor=2.0, drag_per_kg=0.0, g=10.0, Tc=0.1, grip_alpha=0.5)
    v, w = np.array([10.0, 9.0]), np.zeros(2)  # a braking reference: with grip 0.5, no room (0)
    assert rate_limit(p, 0.5, 1.0, v, w, -1.0) == 0.0
    assert rate_limit(p, math.nan, 1.0, v, w, -1.0) == 0.15
    assert rate_limit(p, math.nan, 1.0, v, w, 1.0) == 0.05
    assert rate_limit(p, 0.5, 1.0, v[:1], w[:1], -1.0) == 0.15


def test_interp_unit_by_hand() -> None:
    """np.interp on the unit grid for one point: NaN in, NaN out; the end values outside; an exact
    sample as it is; else slope · (s − j) + a[j], numpy's other-end form when that is NaN, and the
    value itself between equal infinite neighbours."""
    from tsmpc.control.governor import interp_unit

    a = np.array([1.0, 2.0, 4.0])
    assert math.isnan(interp_unit(a, math.nan))
    assert interp_unit(a, -0.5) == 1.0 and interp_unit(a, 2.0) == 4.0 and interp_unit(a, 7.0) == 4.0
    assert interp_unit(a, 1.0) == 2.0 and interp_unit(a, 1.5) == 3.0 and interp_unit(a, 0.25) == 1.25
    inf = math.inf
    with np.errstate(invalid="ignore"):  # inf − inf: numpy scalars warn
        assert interp_unit(np.array([0.0, -inf, inf]), 1.0) == -inf  # exact: not (inf·0 = NaN)
        assert interp_unit(np.array([inf, 1.0]), 0.5) == inf  # −inf·0.5 + inf = NaN; −inf·−0.5 + 1
        assert interp_unit(np.array([inf, inf]), 0.5) == inf  # NaN both ways: the equal value
        assert math.isnan(interp_unit(np.array([1.0, math.nan]), 0.5))
    for s in (-0.5, 0.0, 0.25, 1.0, 1.5, 2.0, 7.0):
        assert interp_unit(a, s) == np.interp(s, np.arange(3.0), a)


def test_cpython_hypot_special_values() -> None:
    """C99's hypot: an infinity wins over a NaN; NaN otherwise NaN; zero for zeros."""
    assert cpython_hypot(math.inf, math.nan) == math.inf and cpython_hypot(math.nan, -math.inf) == math.inf
    assert math.isnan(cpython_hypot(math.nan, 1.0)) and math.isnan(cpython_hypot(2.0, math.nan))
    assert cpython_hypot(0.0, -0.0) == 0.0
    assert cpython_hypot(-3.0, 4.0) == 5.0 and cpython_hypot(1e300, 1e300) == math.hypot(1e300, 1e300)


def test_cpython_hypot_subnormal() -> None:
    """Subnormal and near-subnormal arguments: CPython makes them normal (÷ DBL_MIN) first; plain
    squares underflow (0.0 for 3e-310, 4e-310). Both as Python and compiled."""
    rng = np.random.default_rng(11)
    cases = [(3e-310, 4e-310), (5e-324, 0.0), (5e-324, 5e-324), (1e-308, 3e-308), (2.3e-308, 1e-320),
             *zip(rng.uniform(0, 1, 200) * 10.0 ** rng.uniform(-323, -300, 200),
                  rng.uniform(-1, 1, 200) * 10.0 ** rng.uniform(-323, -300, 200), strict=True)]
    fn = None if kernels.load("mpc") is None else _compiled(cpython_hypot)
    for a, b in cases:
        assert cpython_hypot(a, b) == math.hypot(a, b), (a, b)
        if fn is not None:
            assert fn(a, b) == math.hypot(a, b), (a, b)


def test_friction_programs_outside_their_surfaces() -> None:
    """Off every patch: the base μ (a second patch is looked up past the first); an event is over
    ``ramp`` after its end (at once without a ramp)."""
    patches = np.array([[10.0, 30.0, 0.4, 5.0], [50.0, 60.0, 0.2, 0.0]])
    assert patch_mu(5.0, 0.9, 0.0, patches) == 0.9 and patch_mu(40.0, 0.9, 0.0, patches) == 0.9
    assert patch_mu(55.0, 0.9, 0.0, patches) == 0.2  # no ramp: the patch's μ from its start
    assert patch_mu(60.0, 0.9, 0.0, patches) == 0.9
    assert event_weight(12.0, 2.0, 2.0, 10.0) == 0.0 and event_weight(13.0, 2.0, 2.0, 10.0) == 0.0
    assert event_weight(10.0, 2.0, 0.0, 10.0) == 0.0 and event_weight(9.9, 2.0, 0.0, 10.0) == 1.0


def test_ramp_plateau_and_a_missing_grip_sample() -> None:
    """The paper's earth stretch holds μ = earth between its ramps (t = 30 s, ripple 0); a NaN grip
    sample leaves the governor's filtered grip as it was (the step equals one with that grip
    re-sampled: 0.5 regained at rate α is 0.5)."""
    from tsmpc.control.governor import GovernorParams, GovernorState, governor_update

    assert _ramp(2.5, 1.0, 2.0, 3.0, 4.0, 0.9, 0.3) == 0.3
    assert paper_mu(30.0, 0.9, 0.0, 0.68, 0.1, 0.6) == 0.68
    p = GovernorParams(margin=0.8, rate_down=0.15, rate_up=0.05, rate_min=0.3, mu_plan=0.9, deadband=0.05,
                       traction_factor=2.0, drag_per_kg=0.0, g=10.0, Tc=0.1, grip_alpha=0.5)
    # straight now (all traction left to slow down), then 5 m/s² lateral: more than 0.8 · 0.5 · 10 = 4
    v, w = np.full(6, 10.0), np.array([0.0, 0.5, 0.5, 0.5, 0.5, 0.5])
    s = GovernorState(rate=1.0, grip=0.5, spin_hold=0.0)
    out = governor_update(p, s, math.nan, 100.0, v, w)
    assert out.grip == 0.5 and out == governor_update(p, s, 0.5, 100.0, v, w)
    assert out.rate == pytest.approx(1.0 - 0.15 * 0.1)  # slowing down at rate_down


def test_speed_bounded_yaw_rate_by_hand() -> None:
    """|ω| ≤ max(v, 0) κ_max: 2 m/s · 0.2 /m = 0.4 rad/s either way; within it ω itself; none at a
    negative speed; ω unchanged for a non-finite speed (−inf would clip to 0 without the check)."""
    assert gates.speed_bounded_yaw_rate(0.5, 2.0, 0.2) == pytest.approx(0.4)
    assert gates.speed_bounded_yaw_rate(-0.5, 2.0, 0.2) == pytest.approx(-0.4)
    assert gates.speed_bounded_yaw_rate(0.3, 2.0, 0.2) == 0.3
    assert gates.speed_bounded_yaw_rate(0.3, -1.0, 0.2) == 0.0
    assert gates.speed_bounded_yaw_rate(0.5, -math.inf, 0.2) == 0.5
    assert gates.speed_bounded_yaw_rate(-0.5, math.nan, 0.2) == -0.5


# -- the inner block after the MHE (tsmpc.control.inner_block) -----------------------------------
def _inner_records(friction_step: bool = True, mass: bool = True):
    from tsmpc.control.inner_block import InnerBlockParams
    from tsmpc.control.ts_lqr import InnerParams
    from tsmpc.estimation.fusion import MassParams

    return InnerBlockParams(friction_step, FrictionStepParams(30, 5.0), mass,
                            MassParams(683.0, 0.01, 30, 0.3, True),
                            InnerParams(True, False, True, 2.0, 3000.0))


def _inner_law():
    from tsmpc.control.ts_lqr import LQRLaw

    Kv = np.zeros((8, 2, 6))
    Kv[:, 0, 0], Kv[:, 1, 2], Kv[:, 0, 5] = -100.0, -0.1, 50.0
    bits = np.array([[(i >> j) & 1 for j in range(3)] for i in range(8)], dtype=np.bool_)
    prm = np.array([683.0, 560.0, 25000.0, 25000.0, 0.758, 1.036, 4.9, 0.4])
    return LQRLaw(Kv, np.array([-0.4, 2.0, -0.1]), np.array([0.4, 20.0, 0.1]), bits, prm, 10.0,
                  math.exp(-0.1), 0.01, -2000.0, 3000.0, -0.4, 0.4, True, 0.3)


def _inner_inputs(rng, i):
    """An estimate sequence: speeds through the mass fit's floor, a friction step at sample 400,
    rejected and failed samples, a NaN estimate."""
    v = 1.0 + 0.02 * i + rng.normal(0, 0.05) + (math.sin(i / 25.0) if i > 100 else 0.0)
    Fw = 300.0 + rng.normal(0, 5) + (600.0 if i > 400 else 0.0)
    Fr = Fw + rng.normal(0, 300) + (900.0 if 400 < i < 440 else 0.0)
    status = 1 if rng.random() > 0.05 else int(rng.choice([2, 3, 4]))
    if 400 < i < 440 and i % 6 == 0:  # failed and warm-up samples while the step is compensated
        status = 3 if i % 12 else 4
    om = math.nan if i == 333 else float(rng.normal(0, 0.2))
    return float(v), float(rng.normal(0, 0.02)), om, float(Fw), float(Fr), status


def test_inner_block_composes_its_parts() -> None:
    """compensated_force is the friction-step detector then the mass fit's inertia terms (the
    blocks' own reference wrappers, FrictionStep and MassEstimator); count_step counts by hand."""
    from tsmpc.control.inner_block import (
        IC_FAILED,
        IC_FSTEPS,
        IC_REJECTED,
        IC_SATURATED,
        compensated_force,
        count_step,
        start_state,
    )
    from tsmpc.estimation.friction_step import FrictionStep
    from tsmpc.estimation.fusion import MassEstimator

    p = _inner_records()
    st, ring, cnt = start_state(30)
    fs, me = FrictionStep(30, 5.0), MassEstimator(683.0, 0.01, 30, 0.3, True)
    rng = np.random.default_rng(11)
    moved = 0
    for i in range(1500):
        v, _a, _w, Fw, Fr, status = _inner_inputs(rng, i)
        v_ref = v + float(rng.normal(0, 0.3))
        F_c, F_r = compensated_force(p, st, ring, cnt, v, Fw, Fr, status == 1, v_ref, True)
        want = fs.step(Fw, Fr, status == 1)
        dF = me.inertia_terms(v, Fw, v_ref)
        moved += dF != 0.0
        assert (F_c, F_r) == ((want + dF, Fr + dF) if dF != 0.0 else (want, Fr)), i
    assert moved > 100 and cnt[IC_FSTEPS] == fs.n_steps >= 1
    before = st.copy()  # without the MHE's estimate (the oracle): no mass sample
    compensated_force(p, st, ring, cnt, 10.0, 100.0, 100.0, True, 10.0, False)
    assert np.array_equal(st[5:], before[5:])
    off = _inner_records(False, False)
    st2, ring2, cnt2 = start_state(30)
    assert compensated_force(off, st2, ring2, cnt2, 10.0, 100.0, 7e3, True, 12.0, True) == (100.0, 7e3)
    assert not st2.any()
    c = np.zeros(4, dtype=np.int64)
    for status, sat in ((2, False), (3, True), (3, False), (1, True), (4, False), (2, True), (2, False)):
        count_step(c, status, sat)
    assert (c[IC_REJECTED], c[IC_FAILED], c[IC_SATURATED], c[IC_FSTEPS]) == (3, 2, 3, 0)


def test_inner_block_compiled_equals_python() -> None:
    """The cascade's compiled call of the block (kernels/blocks.py) and the block as Python: the
    same commands, states and counters to the bit; a NaN estimate holds (counted saturated); no
    law hands the step to the numpy law uncounted."""
    from tsmpc.control.inner_block import IC_SATURATED, inner_block, start_state
    from tsmpc.control.ts_lqr import LQR_HELD, LQR_NUMPY, LQR_OK
    from tsmpc.estimation.friction_step import FrictionStep
    from tsmpc.estimation.fusion import MassEstimator

    kern = kernels.load("blocks")
    if kern is None:
        pytest.skip("compiled kernels unavailable")
    p, law = _inner_records(), _inner_law()
    bp = kern.pack(p, law)
    a, b = start_state(30), start_state(30)
    sa, sb = np.zeros(6), np.zeros(6)
    rng = np.random.default_rng(13)
    held = 0
    fs, me = FrictionStep(30, 5.0), MassEstimator(683.0, 0.01, 30, 0.3, True)  # the parts' references
    for i in range(1500):
        v, al, om, Fw, Fr, status = _inner_inputs(rng, i)
        v_ref, w_ref = v + float(rng.normal(0, 0.5)), float(rng.normal(0, 0.2))
        out = inner_block(p, law, sa, *a, v, al, om, Fw, Fr, status, v_ref, w_ref)
        want = fs.step(Fw, Fr, status == 1)  # only an accepted (OK) sample feeds the detector
        dF = me.inertia_terms(v, Fw, v_ref)
        assert out.status != LQR_OK or out.F_comp == (want + dF if dF != 0.0 else want), i
        got = kern.inner_call(bp, law.Kv, law.zlo, law.zhi, law.bits, law.prm, sb, *b, v, al, om, Fw, Fr,
                              status, v_ref, w_ref)
        assert tuple(out) == got, i
        held += out.status == LQR_HELD
        for x, y in zip(a, b, strict=True):
            assert np.array_equal(x, y)
        assert np.array_equal(sa, sb)
    assert held == 1 and 0 < a[2][IC_SATURATED] < 1500
    c0 = a[2].copy()
    out = inner_block(p, None, sa, *a, 10.0, 0.0, 0.0, 100.0, 90.0, 2, 10.0, 0.0)
    assert out.status == LQR_NUMPY
    assert np.array_equal(a[2][:3], c0[:3])  # the numpy law's caller counts the step


def test_pose_gate_by_hand() -> None:
    """The gate block: a repeat is not fresh (counted), a fresh non-finite pose is counted, the
    first pose and a pose the gate owes are taken, a jump is rejected until a run of consistent
    ones has lasted reinit_s (recovery), which re-initialises the pose; without recovery never."""
    gp = gates.GateBlockParams(G, True, 0.05, True)
    gs, c = gates.gate_state()
    a = (True, 10.0, 0.0, 0.0, 5.0, 0.1, -math.inf)
    assert gates.pose_gate(gp, gs, c, 0.0, *a, False, 0.0, 0.0, 0.0, 0.0) == (True, True)  # the first
    assert gates.pose_gate(gp, gs, c, 0.01, *a, True, 10.0, 0.0, 0.0, 0.0) == (False, False)  # a repeat
    b = (True, math.nan, 0.0, 0.0, 5.0, 0.1, -math.inf)
    assert gates.pose_gate(gp, gs, c, 0.02, *b, True, 10.0, 0.0, 0.0, 0.0) == (True, False)
    assert gates.pose_gate(gp, gs, c, 0.02, False, *b[1:], True, 10.0, 0.0, 0.0, 0.0) == (False, False)
    assert (c[gates.GC_REPEATED], c[gates.GC_NAN]) == (1, 1)
    took = []
    for i in range(8):  # 5 m off the dead-reckoned pose, consistent among themselves
        t = 0.03 + 0.01 * i
        took.append(gates.pose_gate(gp, gs, c, t, True, 15.0 + 0.01 * i, 0.0, 0.0, 5.0, 0.1, t, True,
                                    10.0, 0.0, 0.0, 0.0)[1])
    # taken once the run has lasted reinit_s; the next jump starts a new run
    assert took == [False] * 5 + [True] + [False] * 2 and (c[gates.GC_JUMP], c[gates.GC_REINIT]) == (7, 1)
    assert gs[gates.GS_JT0] == 0.03 + 0.01 * 6
    gs, c = gates.gate_state()  # an accepted pose ends a run: the next jump starts a new one

    def jump(t: float) -> bool:  # 5 m off the dead-reckoned pose (10, 0, 0), stamped t
        return gates.pose_gate(gp, gs, c, t, True, 15.0, 0.0, 0.0, 5.0, 0.1, t, True, 10.0, 0.0, 0.0, 0.0)[1]

    assert not jump(0.0)
    assert gates.pose_gate(gp, gs, c, 0.01, True, 10.0, 0.0, 0.0, 5.0, 0.1, 0.01, True, 10.0, 0.0, 0.0,
                           0.0)[1]
    assert [jump(t) for t in (0.02, 0.03, 0.04, 0.05, 0.0625, 0.0725)] == [False] * 5 + [True]
    gs[gates.GS_FREE] = 1.0  # after a blind stop: the next fresh finite pose, wherever it is
    assert gates.pose_gate(gp, gs, c, 1.0, True, 99.0, 0.0, 0.0, 5.0, 0.1, 1.0, True, 10.0, 0.0, 0.0,
                           0.9)[1]
    assert gs[gates.GS_FREE] == 0.0
    no = gates.GateBlockParams(G, False, 0.05, False)
    gs, c = gates.gate_state()
    assert [gates.pose_gate(no, gs, c, 0.01 * i, True, 15.0, 0.0, 0.0, 5.0, 0.1, -math.inf, True, 10.0, 0.0,
                            0.0, 0.0)[1] for i in range(10)] == [False] * 10
    assert (c[gates.GC_JUMP], c[gates.GC_REINIT], c[gates.GC_REPEATED]) == (10, 0, 0)
    assert gates.speed_gate(G, c, 41.0, 0.0) is False and c[gates.GC_SPEED] == 1


def test_gate_block_and_dead_reckoning_by_hand(way) -> None:
    """The gate block's glue (gates.gate_block, gates.reckon_block: Cascade._gate and _dead_reckon,
    the engine's gates and dead reckoning) on its pose record [X, Y, θ, t of the last accepted pose],
    with T_d 0.25 s so that every expected value is exact: an accepted pose replaces the record
    (its time t), an implausible speed is refused and counted while its pose is still gated, a jump
    leaves the record; the dead reckoning moves X, Y, θ one T_d on (v̂ clipped to [0, v_hi]) and
    keeps the time; the next pose is gated against the dead-reckoned one."""
    gate, reckon = way(gates.gate_block), way(gates.reckon_block)
    g = G._replace(Td=0.25)
    gp = gates.GateBlockParams(g, False, 1.0, False)
    gs, c = gates.gate_state()
    pose = np.array([0.0, 0.0, 0.0, 0.0])
    # 0.5 m at t = 0.5 s: within 1 + 2 * 0.5 + 0.05 m of the record: taken, with its time
    assert gate(gp, gs, c, pose, 0.5, True, 0.5, 0.0, 0.0, 5.0, 0.1, -math.inf) == (True, True, True)
    assert pose.tolist() == [0.5, 0.0, 0.0, 0.5] and c.sum() == 0
    # 41 m/s (v_hi 40): the speeds refused and counted; a pose 0.25 m on is still taken
    assert gate(gp, gs, c, pose, 0.75, True, 0.75, 0.0, 0.0, 41.0, 0.1, -math.inf) == (True, False, True)
    assert pose.tolist() == [0.75, 0.0, 0.0, 0.75] and c[gates.GC_SPEED] == 1
    # a jump (9.25 m in 0.25 s, allowance 1.55 m): rejected, counted, the record stands
    assert gate(gp, gs, c, pose, 1.0, True, 10.0, 0.0, 0.0, 5.0, 0.1, -math.inf) == (True, True, False)
    assert pose.tolist() == [0.75, 0.0, 0.0, 0.75] and c[gates.GC_JUMP] == 1
    # not fresh: nothing taken, nothing counted
    assert gate(gp, gs, c, pose, 1.0, False, 0.75, 0.0, 0.0, 5.0, 0.1, -math.inf) == (False, True, False)
    assert c.tolist() == [1, 0, 0, 0, 1]
    # dead reckoning: 2 m/s for 0.25 s on heading 0, ω̂ 0.5 rad/s; the time of the last pose kept
    reckon(g, pose, 2.0, 0.0, 0.5)
    assert pose.tolist() == [1.25, 0.0, 0.125, 0.75]
    reckon(g, pose, math.nan, 0.0, 0.5)  # a non-finite estimate: the pose stands
    assert pose.tolist() == [1.25, 0.0, 0.125, 0.75]
    pose[2] = 0.0
    reckon(g, pose, 100.0, 0.0, 0.0)  # v̂ clipped at v_hi 40: 10 m
    reckon(g, pose, -3.0, 0.0, 0.0)  # and at 0
    assert pose.tolist() == [11.25, 0.0, 0.0, 0.75]
    # the next pose is gated against the dead-reckoned one: 11.5 m at t = 1.25 s (0.25 m from it,
    # 10.75 m from the last accepted one) taken
    assert gate(gp, gs, c, pose, 1.25, True, 11.5, 0.0, 0.0, 5.0, 0.1, -math.inf) == (True, True, True)
    assert pose.tolist() == [11.5, 0.0, 0.0, 1.25]


def test_gate_block_compiled_equals_python() -> None:
    """The cascade's compiled call of the gate block and the block as Python: the same answers,
    states and counters to the bit on random samples (jumps, repeats, NaN)."""
    kern = kernels.load("blocks")
    if kern is None:
        pytest.skip("compiled kernels unavailable")
    gp = gates.GateBlockParams(G, True, 0.05, True)
    bp = kern.pack_gates(gp)
    (ga, ca), (gb, cb) = gates.gate_state(), gates.gate_state()
    rng = np.random.default_rng(17)
    prev = (0.0, 0.0, 0.0)
    for i in range(2000):
        t = 0.01 * i
        X, Y, th = (float(v) for v in rng.normal(0, 1.5, 3))
        if 1000 <= i < 1100:  # a run of poses consistent among themselves, far from the dead reckoning
            X, Y, th = 20.0 + 0.001 * i, 0.0, 0.0
        if i % 7 == 0:
            X, Y, th = prev
        if i % 13 == 0:
            Y = math.nan
        prev = (X, Y, th)
        pa = np.array([*(float(v) for v in rng.normal(0, 1, 3)), t - 0.01])
        pb = pa.copy()
        v, om = (5.0, 0.1) if i % 11 else (99.0, 0.1)  # (an implausible speed)
        args = (t, bool(rng.random() > 0.1), X, Y, th, v, om, -math.inf)
        assert gates.gate_block(gp, ga, ca, pa, *args) == kern.gate_call(bp, gb, cb, pb, *args), i
        assert np.array_equal(ga, gb, equal_nan=True) and np.array_equal(ca, cb) and np.array_equal(pa, pb)
        gates.reckon_block(G, pa, 5.0, 0.01, 0.1)
        kern.reckon_call(bp, pb, 5.0, 0.01, 0.1)
        assert np.array_equal(pa, pb)
    assert ca[gates.GC_REPEATED] > 0 and ca[gates.GC_NAN] > 0 and ca[gates.GC_REINIT] > 0
    assert ca[gates.GC_SPEED] > 0
