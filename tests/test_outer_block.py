"""The outer step's block (tsmpc.control.outer_block): its reference windows read as
Reference.window and governed_window read them (to the bit, past the end too), its errors, offset
correction, governed window and governor step pinned by hand, and the cascade's compiled calls
equal to the block as Python."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.control.governor import (
    Governor,
    GovernorParams,
    GripParams,
    governed_window,
    governor_inputs,
)
from tsmpc.control.offset_free import OffsetParams
from tsmpc.control.outer_block import (
    MPC_FALLBACK,
    MPC_SOFT,
    N_GBP,
    N_OBP,
    OB_GATEN,
    OB_HX,
    OB_OFFB,
    OB_RATE,
    OB_TOFF,
    OC_CLIPPED,
    OC_FALLBACK,
    OC_GACT,
    OC_GSTEPS,
    OC_POSE_REJ,
    OC_SOFT,
    GovernBlockParams,
    OuterBlockParams,
    RefArrays,
    governed_sample,
    outer_after,
    outer_errors,
    outer_state,
    pack_govern,
    pack_outer,
    pose_errors,
    scratch_size,
    unpack_govern,
    unpack_outer,
    window_fill,
    window_pose,
)
from tsmpc.control.slip_aware import BASELINE
from tsmpc.estimation.fusion import SlipFit
from tsmpc.models.kinematic import pose_to_errors
from tsmpc.planning.reference import Reference

N = 4
PREVIEW = 6
NOSLIP = SlipFit(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _ref(closed: bool, n: int = 12) -> Reference:
    """A curving reference of ``n`` samples at T = 0.1 s (speeds and yaw rates that change)."""
    t = np.arange(n) * 0.1
    v = 8.0 + np.sin(t)
    w = 0.2 + 0.1 * np.cos(2 * t)
    th = np.cumsum(w) * 0.1
    x, y = np.cumsum(v * np.cos(th)) * 0.1, np.cumsum(v * np.sin(th)) * 0.1
    return Reference(t, x, y, th, v, w, w / v, closed=closed)


def _params(ref: Reference, **kw) -> OuterBlockParams:
    turn = ref.theta[-1] - ref.theta[0] + ref.omega[0] * ref.dt
    p = OuterBlockParams(False, False, False, True, 0.0, False, OffsetParams(0.0, 0.1), False, 0.1, N, ref.dt,
                         ref.closed, float(2 * np.pi * np.round(turn / (2 * np.pi))), ref.dt, ref.closed)
    return p._replace(**kw)


def _arrays(ref: Reference) -> RefArrays:
    tan = ref.tangent_heading()
    signals = (ref.x, ref.y, ref.theta, ref.v, ref.omega, tan, ref.v, ref.omega)
    return RefArrays(*(np.ascontiguousarray(a, dtype=float) for a in signals))


@pytest.mark.parametrize("closed", [False, True])
def test_the_windows_read_the_reference_as_reference_window(closed: bool, way) -> None:
    """window_fill (v, ω) and window_pose (x, y, θ) are Reference.window's samples to the bit, inside
    the reference and past its end (a closed lap wraps, θ continued by whole turns; an open one
    holds v, ω and continues the pose from its last sample)."""
    fill, pose = way(window_fill), way(window_pose)
    ref = _ref(closed)
    p, r = _params(ref), _arrays(ref)
    for n in (3, N + 3):
        for k in range(0, 2 * len(ref) + 3):
            w = ref.window(k, n)
            v, om, x, y, th = (np.empty(n) for _ in range(5))
            fill(r.v, k, closed, v)
            fill(r.omega, k, closed, om)
            pose(p, r, k, x, y, th)
            for got, want in ((v, w.v), (om, w.omega), (x, w.x), (y, w.y), (th, w.theta)):
                np.testing.assert_array_equal(got, want, err_msg=f"k={k} n={n}")


@pytest.mark.parametrize("closed", [False, True])
def test_the_governed_sample_is_the_governed_windows_first(closed: bool, way) -> None:
    """governed_sample = governed_window(ref, τ, r, 1)'s sample to the bit (inside, between
    samples, and past the end)."""
    f = way(governed_sample)
    ref = _ref(closed)
    p, r = _params(ref), _arrays(ref)
    rng = np.random.default_rng(34)
    buf = np.zeros(15)
    for tau in [0.0, 0.1, 0.25, *rng.uniform(0.0, 2.0 * ref.duration, 60)]:
        rate = float(rng.uniform(0.3, 1.0))
        w = governed_window(ref, float(tau), rate, 1)
        assert f(p, r, float(tau), rate, buf) == (w.x[0], w.y[0], w.theta[0], w.v[0], w.omega[0]), tau


def _errors(p: OuterBlockParams, r: RefArrays, ob, oc, *, t: float = 0.2, k: int = 2, pose_ok: bool = True,
            pose=(1.0, 0.5, 0.1), has_last: bool = False, alpha: float = 0.0, has_pred: bool = False,
            pred_y: float = 0.0, v_prev: float = 8.0, f=outer_errors, gate=None):
    e, wv, ww = np.empty(3), np.empty(N + 1), np.empty(N + 1)
    gate = np.zeros((BASELINE + 1, 3)) if gate is None else gate
    governed = f(p, r, ob, oc, gate, NOSLIP, t, k, pose_ok, *pose, has_last, alpha, has_pred, pred_y, v_prev,
                 e, wv, ww, np.zeros(scratch_size(N, PREVIEW)))
    return governed, e, wv, ww


def test_the_errors_by_hand(way) -> None:
    """Body frame against sample k (the paper); a rejected pose counted and — predict_pose off —
    the held one used; slip-aware: the velocity pose θ + α̂; tangent heading: against the path's
    tangent; offset-free: e_θ + b̂, b̂ from the innovation e_y − the previous plan's prediction."""
    f = way(outer_errors)
    ref = _ref(False)
    r = _arrays(ref)
    X, Y, th = 1.0, 0.5, 0.1
    want = pose_to_errors(X, Y, th, ref.x[2], ref.y[2], ref.theta[2])
    p = _params(ref)
    ob, oc = outer_state(np.array([0.0, 0.0, 0.0]))
    governed, e, wv, ww = _errors(p, r, ob, oc, f=f)
    assert not governed
    np.testing.assert_array_equal(e, want)
    np.testing.assert_array_equal(wv, ref.window(2, N + 1).v)
    np.testing.assert_array_equal(ww, ref.window(2, N + 1).omega)
    assert ob[OB_HX:OB_HX + 3].tolist() == [X, Y, th] and oc[OC_POSE_REJ] == 0
    # a rejected pose: counted; held (the paper) or the dead-reckoned one given (predict_pose)
    _, e2, _, _ = _errors(p._replace(predict_pose=False), r, ob, oc, pose_ok=False, pose=(5.0, 5.0, 1.0), f=f)
    np.testing.assert_array_equal(e2, want)
    _, e3, _, _ = _errors(p, r, ob, oc, pose_ok=False, pose=(5.0, 5.0, 1.0), f=f)
    np.testing.assert_array_equal(e3, pose_to_errors(5.0, 5.0, 1.0, ref.x[2], ref.y[2], ref.theta[2]))
    assert oc[OC_POSE_REJ] == 2
    # slip-aware (the gate holds one pose: α̂ as given) and tangent heading
    _, e4, _, _ = _errors(p._replace(slip_aware=True, tangent_heading=True), r, ob, oc, has_last=True,
                          alpha=0.03, f=f)
    np.testing.assert_array_equal(e4, pose_to_errors(X, Y, th + 0.03, ref.x[2], ref.y[2], r.tangent[2]))
    assert ob[OB_GATEN] == 1
    _, e5, _, _ = _errors(p._replace(tangent_heading=True), r, ob, oc, has_last=True, alpha=0.03, f=f)
    np.testing.assert_array_equal(e5, pose_to_errors(X, Y, th, ref.x[2], ref.y[2], r.tangent[2]))
    # offset-free: b̂ = g (e_y − pred_y) / (T_c v) = 0.01 (e_y − 0.05) / (0.1 · 8), added to e_θ
    po = p._replace(offset=True, off=OffsetParams(0.01, 0.1))
    _, e6, _, _ = _errors(po, r, ob, oc, has_pred=True, pred_y=0.05, f=f)
    b = 0.01 * (want[1] - 0.05) / (0.1 * 8.0)
    assert ob[OB_OFFB] == pytest.approx(b, rel=1e-12)
    assert e6[:2].tolist() == want[:2].tolist() and e6[2] == pytest.approx(want[2] + b, rel=1e-12)
    _, e7, _, _ = _errors(po, r, ob, oc, f=f)  # no previous plan: b̂ held, still added
    assert e7[2] == pytest.approx(want[2] + b, rel=1e-12)


@pytest.mark.parametrize("closed", [False, True])
def test_the_governed_errors_and_window(closed: bool, way) -> None:
    """Once the governor has acted (r < 1, or an action counted), the errors are against the
    reference at τ = t − offset and the window is governed_window's (v, ω times r), to the bit;
    the tangent heading is interpolated between the samples around τ."""
    f = way(outer_errors)
    ref = _ref(closed)
    r = _arrays(ref)
    p = _params(ref, governor=True, tangent_heading=True)
    ob, oc = outer_state(np.zeros(3))
    assert not _errors(p, r, ob, oc, f=f)[0]  # rate 1, no action: sample k
    for t, toff, rate in ((0.4, 0.05, 0.5), (0.95, 0.33, 0.8), (1.1, 0.0, 0.7)):
        ob[OB_TOFF], ob[OB_RATE] = toff, rate
        governed, e, wv, ww = _errors(p, r, ob, oc, t=t, k=99, f=f)
        tau = t - toff
        at, w = governed_window(ref, tau, rate, 1), governed_window(ref, tau, rate, N + 1)
        x = tau / 0.1
        k0 = min(max(math.floor(x), 0), len(ref) - 2)
        fr = min(max(x - k0, 0.0), 1.0)
        tan = (1.0 - fr) * r.tangent[k0] + fr * r.tangent[k0 + 1]
        assert governed
        np.testing.assert_array_equal(e, pose_to_errors(1.0, 0.5, 0.1, at.x[0], at.y[0], tan))
        np.testing.assert_array_equal(wv, w.v)
        np.testing.assert_array_equal(ww, w.omega)
    ob[OB_RATE], oc[OC_GACT] = 1.0, 1  # back at rate 1 after an action: still the governed time
    assert _errors(p, r, ob, oc, f=f)[0]


def _gov() -> GovernBlockParams:
    gp = GovernorParams(margin=0.8, rate_down=0.5, rate_up=0.2, rate_min=0.4, mu_plan=1.0, deadband=0.05,
                        traction_factor=3.0, drag_per_kg=0.0005, g=9.81, Tc=0.1, grip_alpha=0.1)
    grip = GripParams(False, 0.015, 1.0, 1.0, 1.0, 0.05, 9.81, 683.0, 0.45, 5000.0)
    return GovernBlockParams(gp, grip, PREVIEW, 1.0, False)


def test_after_the_plan_by_hand(way) -> None:
    """The plan's events counted; the governor off does nothing else; on, its rate is
    Governor.step's on the same grip and preview, an action counted when r leaves 1, and the
    reference time offset advances by (1 − r) T_c."""
    f = way(outer_after)
    ref = _ref(True, 40)
    r = _arrays(ref)
    p, g = _params(ref), _gov()
    ob, oc = outer_state(np.zeros(3))
    buf = np.zeros(scratch_size(N, PREVIEW))
    for status, clip in ((1, 0), (MPC_SOFT, 2), (MPC_FALLBACK, 1), (MPC_SOFT, 0)):
        f(p, g, r, ob, oc, status, clip, 0.0, False, 0, math.nan, math.nan, False, 0.0, math.nan, 0.0, buf)
    assert (oc[OC_SOFT], oc[OC_FALLBACK], oc[OC_CLIPPED]) == (2, 1, 3)
    assert ob[OB_RATE] == 1.0 and ob[OB_TOFF] == 0.0 and oc[OC_GACT] == 0
    p = p._replace(governor=True)
    ref_gov = Governor(g.gov, g.preview, g.grip)
    toff = 0.0
    for i, F_fr in enumerate([0.0, -3000.0, -3000.0, -3000.0, 0.0]):  # a grip drop (μ̂ ≈ 0.57), then back
        t = 0.1 * i
        f(p, g, r, ob, oc, 1, 0, t, True, 1, 8.0, F_fr, False, 0.0, math.nan, 0.0, buf)
        grip, spin, fpk = governor_inputs(g.grip, F_fr, True, 683.0, False, 0.0, math.nan)
        k = min(max(math.floor((t - toff) / 0.1 + 1e-6), 0), len(ref) - 1)
        w = ref.window(k, PREVIEW + 1)
        rate = ref_gov.step(grip, fpk, w.v, w.omega, spin)
        toff += (1.0 - rate) * 0.1
        assert ob[OB_RATE] == rate and ob[OB_TOFF] == toff, i
    assert ref_gov.actions == 1 and oc[OC_GACT] == 1 and oc[OC_GSTEPS] == ref_gov.steps > 0


def test_the_records_pack_and_unpack() -> None:
    ref = _ref(True)
    p = _params(ref, slip_aware=True, offset=True, off=OffsetParams(0.01, 0.1), governor=True)
    assert pack_outer(p).size == N_OBP and unpack_outer(pack_outer(p)) == p
    g = _gov()
    assert pack_govern(g).size == N_GBP and unpack_govern(pack_govern(g)) == g


def test_pose_errors_is_pose_to_errors(way) -> None:
    f = way(pose_errors)
    rng = np.random.default_rng(3)
    e = np.empty(3)
    for a in rng.normal(0, 5, (200, 6)):
        f(*a, e)
        np.testing.assert_array_equal(e, pose_to_errors(*a))


def test_the_compiled_calls_equal_the_block_as_python() -> None:
    """The cascade's compiled calls (kernels/blocks.py: the records rebuilt from packed vectors, the
    reference from its (8, L) stack) and the block as Python: the same errors, windows, states
    and counters to the bit over random steps (slip gate, offset, governor on)."""
    kern = kernels.load("blocks")
    if kern is None:
        pytest.skip("compiled kernels unavailable")
    ref = _ref(True, 40)
    refs = np.ascontiguousarray(np.vstack([*_arrays(ref)]))
    r = RefArrays(*refs)
    p = _params(ref, slip_aware=True, tangent_heading=True, course_slip=True, slip_sigma=0.01, offset=True,
                off=OffsetParams(0.01, 0.1), governor=True)
    g = _gov()
    opk, gpk = pack_outer(p), pack_govern(g)
    a, b = outer_state(np.zeros(3)), outer_state(np.zeros(3))
    ga, gb = np.zeros((BASELINE + 1, 3)), np.zeros((BASELINE + 1, 3))
    bufa, bufb = np.zeros(scratch_size(N, PREVIEW)), np.zeros(scratch_size(N, PREVIEW))
    slip = SlipFit(0.002, -0.001, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    rng = np.random.default_rng(36)
    for i in range(300):
        t = 0.1 * i
        k = max(math.floor((t - a[0][OB_TOFF]) / 0.1 + 1e-6), 0)
        kk = k % len(ref)
        pose = (float(ref.x[kk] + rng.normal(0, 0.3)), float(ref.y[kk] + rng.normal(0, 0.3)),
                float(ref.theta[kk] + rng.normal(0, 0.05)))
        args = (slip, t, k, bool(rng.random() > 0.1), *pose, i > 0, float(rng.normal(0, 0.02)), i > 1,
                float(rng.normal(0, 0.2)), float(rng.uniform(0, 12)))
        ea, eb = [np.empty(3) for _ in range(2)], [np.empty(3) for _ in range(2)]
        wa, wb = [np.empty(N + 1) for _ in range(2)], [np.empty(N + 1) for _ in range(2)]
        got_a = outer_errors(p, r, *a, ga, *args, ea[0], wa[0], wa[1], bufa)
        got_b = kern.outer_call(opk, refs, *b, gb, *args, eb[0], wb[0], wb[1], bufb)
        assert got_a == got_b, i
        np.testing.assert_array_equal(ea[0], eb[0])
        np.testing.assert_array_equal(wa[0], wb[0])
        np.testing.assert_array_equal(wa[1], wb[1])
        st = (MPC_SOFT if rng.random() < 0.1 else 1, int(rng.integers(0, 3)), t, True, 1,
              float(rng.uniform(0, 12)), float(rng.normal(-1500, 1500)), bool(rng.random() < 0.1),
              float(rng.normal(0, 1000)), math.nan, 0.0)
        outer_after(p, g, r, *a, *st, bufa)
        kern.after_call(opk, gpk, refs, *b, *st, bufb)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y, err_msg=str(i))
        np.testing.assert_array_equal(ga, gb)
    assert a[1][OC_GACT] > 0 and a[1][OC_POSE_REJ] > 0 and a[0][OB_OFFB] != 0.0
