"""Batched runs (issue 25 item 2): B engine runs stepped together, the two costly blocks in
structure-of-arrays layout so that LLVM vectorises them across runs.

Every T_d each run ("lane") executes the run engine's own step (:func:`tsmpc.kernels.engine.run`,
the same compiled function, with its ``IP_DEFER`` flag set): the sensors, gates, the TS-MPC, the
MHE-UIO up to its window solve, the TS-LQR and the bookkeeping are the engine's machine code. The
lane stops where it would solve the MHE window and where it would integrate the plant;
:func:`advance` then does both for all lanes at once:

* **MHE window** (:func:`mhe_window_lanes`): the Euler model matrices along the window and the
  bordered block-tridiagonal solve of :func:`tsmpc.kernels.mhe.banded_solve`, lanes innermost,
  with the *same* floating-point operations in the same order, so the result is bit-identical to
  the single-run kernel. The sines/cosines of the window's steering angles come from libm, cached
  per window row (the window shifts by one row per step, so one new pair per step).
* **Plant** (:func:`rk4_lanes`): the RK4 steps of :func:`tsmpc.kernels.plant.rk4_block`, lanes
  innermost. LLVM does not vectorise a loop that calls libm, so the right-hand side uses the
  branch-free polynomial sin/cos/atan/atan2/tanh below (≤ 2 ulp; libm's are ≤ 0.5 ulp except
  tanh) — the one place where a batched run differs from the engine's, by rounding only.
  ``exact_plant`` runs the scalar kernel per lane instead (bit-identical, slower).

Everything a vectorised loop touches lives in one flat workspace with lanes innermost and
compile-time row strides: LLVM then proves the loop's memory accesses independent (separate
arrays, or offsets it cannot bound, make it give up or demand too many run-time checks).

Where a block needs its Python path (the MPC's QP, the MHE's dense QP, a singular TS-LQR gain, a
non-finite plant step) the lane waits and :func:`advance` returns; the caller runs that block's
Python code exactly as the engine's caller does and calls :func:`advance` again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numba.core import cgutils
from numba.core import types as nbtypes
from numba.np.arrayobj import populate_array

from tsmpc.control.mhe_block import N_EO, estimate_out
from tsmpc.kernels import engine as ke
from tsmpc.kernels import mhe as km
from tsmpc.kernels import plant as kplant
from tsmpc.kernels.engine import intrinsic

__all__ = ["LANES", "advance", "atan2_v", "atan_v", "mhe_window_lanes", "rk4_lanes", "sincos_v",
           "tanh_v"]

#: Lanes per vectorised group (the workspaces' inner dimension; batches are padded to it).
LANES = 32

_NJ: dict[str, Any] = {"cache": False, "fastmath": False, "error_model": "numpy"}
_INL = {**_NJ, "inline": "always"}


#: a·b + c rounded once (llvm.fma: one vfmadd instruction, vectorisable)
_fma = ke._fma


# ============================================================================ transcendentals
# Polynomials: near-minimax (Chebyshev-node interpolation in 80-bit long double of the Taylor
# series' remainder, e.g. (sin x − x)/x³ as a polynomial in z = x²), relative error of the
# remainder polynomial ≤ 4e-18; range reduction by Cody–Waite with constants split exactly
# (π/2 in three 33-bit parts, from π to 240 bits by Machin's formula). tests/test_batch.py checks
# every function against long double to ≤ 2 ulp over the ranges the plant needs.
_S = (-0.16666666666666666, 0.008333333333333331, -0.00019841269841264025, 2.7557319218463805e-06,
      -2.5052105915949548e-08, 1.6058480520549716e-10, -7.583672234862226e-13)
_C = (0.041666666666666664, -0.001388888888888889, 2.480158730158593e-05, -2.7557319221950675e-07,
      2.0876755898224696e-09, -1.1470469867712628e-11, 4.746086034250547e-14)
_A = (-0.3333333333333333, 0.19999999999999785, -0.14285714285654963, 0.1111111110468196,
      -0.09090908729978704, 0.07692295696371078, -0.06666412726791905, 0.0587878958575307,
      -0.05229430621980732, 0.045469390641880984, -0.0344512795709746, 0.016154042071986195)
_T = (-0.3333333333333333, 0.1333333333333331, -0.053968253968219915, 0.02186948853404394,
      -0.008863235462279847, 0.0035921267560796812, -0.0014558189616871667, 0.0005899044577066474,
      -0.0002384694059268994, 9.454321198236363e-05, -3.370960579265497e-05, 7.867618454105381e-06)
_E = (0.5, 0.16666666666666666, 0.04166666666666668, 0.008333333333333312, 0.0013888888888877616,
      0.00019841269841346326, 2.4801587339935593e-05, 2.7557319127461054e-06,
      2.7557260115726023e-07, 2.5052143998737075e-08, 2.091913274286947e-09, 1.607106848008057e-10)
S0, S1, S2, S3, S4, S5, S6 = _S
C0, C1, C2, C3, C4, C5, C6 = _C
A0, A1, A2, A3, A4, A5, A6, A7, A8, A9, A10, A11 = _A
T0, T1, T2, T3, T4, T5, T6, T7, T8, T9, T10, T11 = _T
E0, E1, E2, E3, E4, E5, E6, E7, E8, E9, E10, E11 = _E
PIO2_A, PIO2_B, PIO2_C = 1.5707963267341256, 6.077100506303966e-11, 2.0222662487959506e-21
PIO2_HI, PIO2_LO = 1.5707963267948966, 6.123233995736766e-17
PIO4_HI, PIO4_LO = 0.7853981633974483, 3.061616997868383e-17
PI_HI, PI_LO = 3.141592653589793, 1.2246467991473532e-16
TWO_OVER_PI = 0.6366197723675814
LN2_HI, LN2_LO, INV_LN2 = 0.6931471805598903, 5.497923018708371e-14, 1.4426950408889634
TAN_PI8 = 0.41421356237309503
#: |x| up to which sincos_v's reduction is accurate (k·PIO2_A exact for |k| < 2^20)
SINCOS_MAX = 1.0e5


@njit(**_INL)
def sincos_v(x):
    """(sin x, cos x) for |x| ≤ SINCOS_MAX, branch-free: x = k·π/2 + r, |r| ≤ π/4 (+ rounding)."""
    k = np.floor(x * TWO_OVER_PI + 0.5)
    r = ((x - k * PIO2_A) - k * PIO2_B) - k * PIO2_C  # exact first two products (33-bit parts)
    z = r * r
    ps = _fma(_fma(_fma(_fma(_fma(_fma(S6, z, S5), z, S4), z, S3), z, S2), z, S1), z, S0)
    s = _fma(r * z, ps, r)
    pc = _fma(_fma(_fma(_fma(_fma(_fma(C6, z, C5), z, C4), z, C3), z, C2), z, C1), z, C0)
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + _fma(z * z, pc, (1.0 - w) - hz)  # 1 − z/2 with its rounding error carried
    q = k - 4.0 * np.floor(k * 0.25)  # quadrant 0…3
    sn = s if q == 0.0 else (c if q == 1.0 else (-s if q == 2.0 else -c))
    cs = c if q == 0.0 else (-s if q == 1.0 else (-c if q == 2.0 else s))
    return sn, cs


@njit(**_INL)
def _atan01(t):
    """atan t for t ∈ [0, 1]: above tan(π/8) through atan t = π/4 + atan((t − 1)/(t + 1))."""
    hi = t > TAN_PI8
    u = (t - 1.0) / (t + 1.0) if hi else t
    z = u * u
    p = _fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(
        A11, z, A10), z, A9), z, A8), z, A7), z, A6), z, A5), z, A4), z, A3), z, A2), z, A1), z, A0)
    p = u * z * p
    return PIO4_HI + (u + (p + PIO4_LO)) if hi else u + p


@njit(**_INL)
def atan_v(x):
    """atan x, branch-free (|x| > 1 through π/2 − atan(1/x))."""
    ax = abs(x)
    sw = ax > 1.0
    a = _atan01(1.0 / ax if sw else ax)
    a = PIO2_HI + (PIO2_LO - a) if sw else a
    return math.copysign(a, x)


@njit(**_INL)
def atan2_v(y, x):
    """atan2(y, x), branch-free: the octant's ratio min/max(|x|, |y|), then reflections."""
    ax, ay = abs(x), abs(y)
    sw = ay > ax
    a = _atan01((ax if sw else ay) / (ay if sw else ax))
    a = PIO2_HI + (PIO2_LO - a) if sw else a
    a = PI_HI + (PI_LO - a) if x < 0.0 else a
    return math.copysign(a, y)


@njit(**_INL)
def tanh_v(x):
    """tanh x, branch-free: an odd polynomial below 0.55, else 1 − 2/(e^{2|x|} + 1) (e^y by
    Cody–Waite, the power of two applied by exact multiplications)."""
    ax = abs(x)
    z = ax * ax
    p = _fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(
        T11, z, T10), z, T9), z, T8), z, T7), z, T6), z, T5), z, T4), z, T3), z, T2), z, T1), z, T0)
    small = _fma(ax * z, p, ax)
    y = 2.0 * ax
    y = y if y < 45.0 else 45.0  # tanh is 1.0 in double beyond 19.1
    k = np.floor(y * INV_LN2 + 0.5)
    r = (y - k * LN2_HI) - k * LN2_LO
    pe = _fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(_fma(
        E11, r, E10), r, E9), r, E8), r, E7), r, E6), r, E5), r, E4), r, E3), r, E2), r, E1), r, E0)
    e = 1.0 + _fma(r * r, pe, r)
    # e·2^k, k ≤ 65, bit by bit (no float↔int conversions in the vector loop)
    b = k >= 64.0
    e = e * 18446744073709551616.0 if b else e
    k = k - 64.0 if b else k
    b = k >= 32.0
    e = e * 4294967296.0 if b else e
    k = k - 32.0 if b else k
    b = k >= 16.0
    e = e * 65536.0 if b else e
    k = k - 16.0 if b else k
    b = k >= 8.0
    e = e * 256.0 if b else e
    k = k - 8.0 if b else k
    b = k >= 4.0
    e = e * 16.0 if b else e
    k = k - 4.0 if b else k
    b = k >= 2.0
    e = e * 4.0 if b else e
    k = k - 2.0 if b else k
    e = e * 2.0 if k >= 1.0 else e
    big = 1.0 - 2.0 / (e + 1.0)
    return math.copysign(small if ax < 0.55 else big, x)


# ============================================================================ plant, lanes
# Plant workspace: rows of LANES values (lane innermost). State, inputs, cos δ (libm, as the
# scalar kernel), the constants of tsmpc.kernels.plant.pack; then one RK4 stage's state and
# right-hand side, and the slopes k1 … k4 of the step (six rows each).
PW_X, PW_F, PW_D, PW_MU, PW_COSD, PW_CST = 0, 6, 7, 8, 9, 10
PW_S = PW_CST + 18  #: the stage's θ, v, α, ω
PW_R = PW_S + 4  #: the stage's right-hand side (six rows)
PW_K = PW_R + 6  #: the slopes k1 … k4 (six rows each)
PW_ROWS = PW_K + 24


@njit(**_INL)
def _rhs_v(s, lane, th, v, al, om, F, d, mu, cosd):
    """The plant's right-hand side (tsmpc.vehicle.single_track.plant_rhs) for one lane of workspace ``s``,
    every tyre variant computed and selected (no branches), same operation order: the only second
    form of the plant (tests/test_plant_block.py compares it with the scalar one)."""
    o = PW_CST * LANES + lane
    M, I, a, b = s[o + kplant._M * LANES], s[o + kplant._I * LANES], s[o + kplant._A * LANES], \
        s[o + kplant._B * LANES]
    Cf, Cr = s[o + kplant._CF * LANES], s[o + kplant._CR * LANES]
    v_floor = s[o + kplant._VF * LANES]
    ve = v if v > v_floor else v_floor
    sa, ca = sincos_v(al)
    f_res = mu * s[o + kplant._MG * LANES] * tanh_v(v / s[o + kplant._VE * LANES])
    # linear tyres
    fyf_l = Cf * (d - al - a * om / ve)
    fyr_l = Cr * (b * om / ve - al)
    # Pacejka tyres
    vx, vy = ve * ca, ve * sa
    scale = s[o + kplant._SCALE * LANES]
    mu_t = mu * scale if scale != 0.0 else s[o + kplant._MUT0 * LANES]
    Df, Dr = mu_t * s[o + kplant._FZF * LANES], mu_t * s[o + kplant._FZR * LANES]
    cc, ee = s[o + kplant._CC * LANES], s[o + kplant._EE * LANES]
    bs = Cf / (cc * Df) * (atan2_v(vy + a * om, vx) - d)
    fyf_p = -Df * sincos_v(cc * atan_v(bs - ee * (bs - atan_v(bs))))[0]
    bs = Cr / (cc * Dr) * atan2_v(vy - b * om, vx)
    fyr_p = -Dr * sincos_v(cc * atan_v(bs - ee * (bs - atan_v(bs))))[0]
    grip = Df > 0.0
    fyf_p = fyf_p if grip else 0.0
    fyr_p = fyr_p if grip else 0.0
    # combined slip: the rear tyre's friction ellipse
    ft = F - f_res
    ftc = -Dr if ft < -Dr else (Dr if ft > Dr else ft)
    rr = ftc / Dr
    rgrip = Dr > 0.0
    fyr_c = fyr_p * math.sqrt(1.0 - rr * rr) if rgrip else fyr_p
    F_c = ftc if rgrip else 0.0
    lin = s[o + kplant._LIN * LANES] != 0.0
    comb = (s[o + kplant._COMB * LANES] != 0.0) and not lin
    fyf = fyf_l if lin else fyf_p
    fyr = fyr_l if lin else (fyr_c if comb else fyr_p)
    Fe = F_c if comb else F
    fr = 0.0 if comb else f_res
    sda, cda = sincos_v(d - al)
    vdot = (Fe * ca - fyf * sda + fyr * sa - s[o + kplant._KD * LANES] * v * v - fr) / M
    adot = (-Fe * sa + fyf * cda + fyr * ca) / (M * ve) - om
    wdot = (a * fyf * cosd - b * fyr) / I
    s2, c2 = sincos_v(th + al)
    return v * c2, v * s2, om, vdot, adot, wdot


@njit(**_NJ)
def _rhs_lanes(s):
    """The right-hand side of every lane at the stage state (rows PW_S) into rows PW_R: the one
    call site of the inlined :func:`_rhs_v` (numba copies an inlined function's IR per call site,
    seconds of compile each), and compile-time row offsets only, so LLVM vectorises the loop."""
    for lane in range(LANES):
        th, v = s[PW_S * LANES + lane], s[(PW_S + 1) * LANES + lane]
        al, om = s[(PW_S + 2) * LANES + lane], s[(PW_S + 3) * LANES + lane]
        F, d = s[PW_F * LANES + lane], s[PW_D * LANES + lane]
        mu, cosd = s[PW_MU * LANES + lane], s[PW_COSD * LANES + lane]
        r0, r1, r2, r3, r4, r5 = _rhs_v(s, lane, th, v, al, om, F, d, mu, cosd)
        s[PW_R * LANES + lane], s[(PW_R + 1) * LANES + lane] = r0, r1
        s[(PW_R + 2) * LANES + lane], s[(PW_R + 3) * LANES + lane] = r2, r3
        s[(PW_R + 4) * LANES + lane], s[(PW_R + 5) * LANES + lane] = r4, r5


@njit(**_NJ)
def rk4_lanes(s, n, h):
    """``n`` RK4 steps of length h for all LANES lanes of plant workspace ``s`` (in place), with
    the operations of tsmpc.kernels.plant.rk4_block in its order: stage i evaluates the
    right-hand side at x + c_i k_(i−1), c = (0, h/2, h/2, h), and the step is
    x + h/6 (k1 + 2 (k2 + k3) + k4)."""
    h2 = 0.5 * h
    h6 = h / 6.0
    for _ in range(n):
        for stage in range(4):
            c = h if stage == 3 else h2
            kp = (PW_K + 6 * (stage - 1) + 2) * LANES  # the previous slopes' θ̇ row
            for lane in range(LANES):
                for i in range(4):  # θ, v, α, ω (the right-hand side does not read X, Y)
                    x = s[(PW_X + 2 + i) * LANES + lane]
                    s[(PW_S + i) * LANES + lane] = x if stage == 0 else \
                        x + c * s[kp + i * LANES + lane]
            _rhs_lanes(s)
            ko = (PW_K + 6 * stage) * LANES
            for j in range(6 * LANES):
                s[ko + j] = s[PW_R * LANES + j]
        for i in range(6):
            o, k = (PW_X + i) * LANES, (PW_K + i) * LANES
            for lane in range(LANES):
                k1, k2 = s[k + lane], s[k + 6 * LANES + lane]
                k3, k4 = s[k + 12 * LANES + lane], s[k + 18 * LANES + lane]
                s[o + lane] = s[o + lane] + h6 * (k1 + 2.0 * (k2 + k3) + k4)


# ============================================================================ MHE window, lanes
# MHE workspace: a header block of per-lane values, then one block per window row k = 0 … n (block
# 1 + k), each of MR rows of LANES values. Row fields:
MR_A, MR_B, MR_U, MR_Y, MR_W, MR_V, MR_SD, MR_CD, MR_L, MR_YK, MR_G, MR_XG, MR_X = (
    0, 9, 15, 17, 19, 20, 21, 22, 23, 29, 38, 44, 50)
MR = 53
# header fields
MH_Q, MH_R, MH_P, MH_PF, MH_ARR, MH_FP, MH_HFF, MH_GF, MH_BAD, MH_HG, MH_HH, MH_F = (
    0, 3, 5, 8, 9, 12, 13, 14, 15, 16, 17, 18)
MH_TD, MH_M, MH_I, MH_CF, MH_CR, MH_AA, MH_BB, MH_MUG, MH_KD = range(19, 28)
#: the yaw-model margin's linear-tyre share (in), its window's residual mean square and linear flag (out)
MH_LIN, MH_MSQ, MH_MOK = 28, 29, 30
#: window rows the workspace holds at most (blocks 1 … KMAX + 1); the bound also lets LLVM prove
#: the row offsets non-negative (else numba's negative-index wrap-around blocks vectorisation)
KMAX = 126


def mhe_workspace(nw: int) -> np.ndarray:
    """A zeroed MHE workspace for windows of up to ``nw`` intervals."""
    if nw > KMAX:
        raise ValueError(f"MHE window {nw} > {KMAX} intervals")
    return np.zeros((nw + 3) * MR * LANES)


@njit(**_INL)
def _rows(k):
    """Offsets of the blocks of window rows k − 1, k, k + 1, from k clamped into [0, KMAX] (see
    KMAX; deriving all three from one clamped k keeps their distances compile-time constants)."""
    kc = min(max(k, 0), KMAX)
    return kc * MR * LANES, (kc + 1) * MR * LANES, (kc + 2) * MR * LANES


@njit(**_INL)
def _euler_lanes(s, k):
    """tsmpc.kernels.mhe.euler_matrices for row k of every lane (v clipped, sin/cos of the clipped
    δ given): A_k into MR_A (row-major 3×3), B_k into MR_B (3×2)."""
    o = _rows(k)[1]
    for lane in range(LANES):
        v, sd, cd = s[o + MR_V * LANES + lane], s[o + MR_SD * LANES + lane], s[o + MR_CD * LANES + lane]
        M, I = s[MH_M * LANES + lane], s[MH_I * LANES + lane]
        Cf, Cr = s[MH_CF * LANES + lane], s[MH_CR * LANES + lane]
        a, b = s[MH_AA * LANES + lane], s[MH_BB * LANES + lane]
        mug, kd, Td = s[MH_MUG * LANES + lane], s[MH_KD * LANES + lane], s[MH_TD * LANES + lane]
        p = o + MR_A * LANES + lane
        s[p] = 1.0 + Td * (-mug / v - kd * v / M)
        s[p + LANES] = Td * (Cf * sd / M)
        s[p + 2 * LANES] = Td * (Cf * a * sd / (M * v))
        s[p + 3 * LANES] = 0.0
        s[p + 4 * LANES] = 1.0 + Td * (-(Cr + Cf * cd) / (M * v))
        s[p + 5 * LANES] = Td * ((Cr * b - Cf * a * cd) / (M * v**2) - 1.0)
        s[p + 6 * LANES] = 0.0
        s[p + 7 * LANES] = Td * ((Cr * b - Cf * a * cd) / I)
        s[p + 8 * LANES] = 1.0 + Td * (-(Cf * a**2 * cd + Cr * b**2) / (I * v))
        p = o + MR_B * LANES + lane
        s[p] = Td * (1.0 / M)
        s[p + LANES] = Td * (-Cf * sd / M)
        s[p + 2 * LANES] = 0.0
        s[p + 3 * LANES] = Td * (Cf * cd / (M * v))
        s[p + 4 * LANES] = 0.0
        s[p + 5 * LANES] = Td * (Cf * a * cd / I)


@njit(**_INL)
def _forward(s, k, first, has_prev, has_next):
    """Row k of banded_solve's forward elimination for every lane (its operations, its order;
    the uniform conditions are literal at each call site, so every variant is a plain loop).
    The lane's diagonal block D and right-hand sides G (lower triangle, two columns) accumulate
    as a tuple through the terms below, in banded_solve's order; the helpers are inlined."""
    op, o, _ = _rows(k)
    for lane in range(LANES):
        terms = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if first:
            terms = _arrival_terms(s, lane, terms)
        terms = _measurement_terms(s, lane, o, terms)
        if has_prev:
            terms = _previous_stage_terms(s, lane, op, terms)
        if has_next:
            terms = _next_stage_terms(s, lane, o, terms)
        if has_prev:
            terms = _eliminate_previous(s, lane, op, terms)
        _factor_row(s, lane, o, has_next, terms)


@njit(**_INL)
def _arrival_terms(s, lane, terms):
    """The arrival cost of the window's first state (row 0)."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    p0, p1, p2 = s[MH_P * LANES + lane], s[(MH_P + 1) * LANES + lane], s[(MH_P + 2) * LANES + lane]
    d00 += p0
    d11 += p1
    d22 += p2
    g00 += p0 * s[MH_ARR * LANES + lane]
    g10 += p1 * s[(MH_ARR + 1) * LANES + lane]
    g20 += p2 * s[(MH_ARR + 2) * LANES + lane]
    return (d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21)


@njit(**_INL)
def _measurement_terms(s, lane, o, terms):
    """The measurement weight of row k (speed and yaw rate)."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    wk = s[o + MR_W * LANES + lane]
    r0, r1 = s[MH_R * LANES + lane], s[(MH_R + 1) * LANES + lane]
    d00 += wk * r0
    d22 += wk * r1
    g00 += wk * r0 * s[o + MR_Y * LANES + lane]
    g20 += wk * r1 * s[o + (MR_Y + 1) * LANES + lane]
    return (d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21)


@njit(**_INL)
def _wdot3(x0, x1, x2, q0, q1, q2, y0, y1, y2):
    """Σ_l x_l q_l y_l summed from 0.0 in the order l = 0, 1, 2 (the scalar window solve's order:
    the lanes equal it bit for bit)."""
    acc = 0.0
    acc += x0 * q0 * y0
    acc += x1 * q1 * y1
    acc += x2 * q2 * y2
    return acc


@njit(**_INL)
def _previous_stage_terms(s, lane, op, terms):
    """Stage k−1: the state noise weight q and its input term B u."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    q0, q1, q2 = s[MH_Q * LANES + lane], s[(MH_Q + 1) * LANES + lane], s[(MH_Q + 2) * LANES + lane]
    u0, u1 = s[op + MR_U * LANES + lane], s[op + (MR_U + 1) * LANES + lane]
    b00, b01 = s[op + MR_B * LANES + lane], s[op + (MR_B + 1) * LANES + lane]
    b10, b11 = s[op + (MR_B + 2) * LANES + lane], s[op + (MR_B + 3) * LANES + lane]
    b20, b21 = s[op + (MR_B + 4) * LANES + lane], s[op + (MR_B + 5) * LANES + lane]
    d00 += q0
    g00 += q0 * (b00 * u0 + b01 * u1)
    g01 += q0 * b00
    d11 += q1
    g10 += q1 * (b10 * u0 + b11 * u1)
    g11 += q1 * b10
    d22 += q2
    g20 += q2 * (b20 * u0 + b21 * u1)
    g21 += q2 * b20
    return (d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21)


@njit(**_INL)
def _next_stage_terms(s, lane, o, terms):
    """Stage k: Aᵀ q A into D, Aᵀ q (B u) and the F column into G, the F row into HFF, GF."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    q0, q1, q2 = s[MH_Q * LANES + lane], s[(MH_Q + 1) * LANES + lane], s[(MH_Q + 2) * LANES + lane]
    pa = o + MR_A * LANES + lane
    a00, a01, a02 = s[pa], s[pa + LANES], s[pa + 2 * LANES]
    a10, a11, a12 = s[pa + 3 * LANES], s[pa + 4 * LANES], s[pa + 5 * LANES]
    a20, a21, a22 = s[pa + 6 * LANES], s[pa + 7 * LANES], s[pa + 8 * LANES]
    u0, u1 = s[o + MR_U * LANES + lane], s[o + (MR_U + 1) * LANES + lane]
    pb = o + MR_B * LANES + lane
    b00, b01 = s[pb], s[pb + LANES]
    b10, b11 = s[pb + 2 * LANES], s[pb + 3 * LANES]
    b20, b21 = s[pb + 4 * LANES], s[pb + 5 * LANES]
    # D_ij += Σ_l A_li q_l A_lj (the lower triangle, which the Cholesky reads)
    d00 += _wdot3(a00, a10, a20, q0, q1, q2, a00, a10, a20)
    d10 += _wdot3(a01, a11, a21, q0, q1, q2, a00, a10, a20)
    d11 += _wdot3(a01, a11, a21, q0, q1, q2, a01, a11, a21)
    d20 += _wdot3(a02, a12, a22, q0, q1, q2, a00, a10, a20)
    d21 += _wdot3(a02, a12, a22, q0, q1, q2, a01, a11, a21)
    d22 += _wdot3(a02, a12, a22, q0, q1, q2, a02, a12, a22)
    bl0 = b00 * u0 + b01 * u1
    bl1 = b10 * u0 + b11 * u1
    bl2 = b20 * u0 + b21 * u1
    # G_i· −= Σ_l A_li q_l (B u)_l, and the F column Σ_l A_li q_l (−B_l0)
    g00 -= _wdot3(a00, a10, a20, q0, q1, q2, bl0, bl1, bl2)
    g01 += _wdot3(a00, a10, a20, q0, q1, q2, -b00, -b10, -b20)
    g10 -= _wdot3(a01, a11, a21, q0, q1, q2, bl0, bl1, bl2)
    g11 += _wdot3(a01, a11, a21, q0, q1, q2, -b00, -b10, -b20)
    g20 -= _wdot3(a02, a12, a22, q0, q1, q2, bl0, bl1, bl2)
    g21 += _wdot3(a02, a12, a22, q0, q1, q2, -b00, -b10, -b20)
    hff = s[MH_HFF * LANES + lane]
    gf = s[MH_GF * LANES + lane]
    e = -b00
    hff += e * q0 * e
    gf -= e * q0 * bl0
    e = -b10
    hff += e * q1 * e
    gf -= e * q1 * bl1
    e = -b20
    hff += e * q2 * e
    gf -= e * q2 * bl2
    s[MH_HFF * LANES + lane] = hff
    s[MH_GF * LANES + lane] = gf
    return (d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21)


@njit(**_INL)
def _eliminate_previous(s, lane, op, terms):
    """Elimination of block k−1: D −= Y_{k−1}ᵀ Y_{k−1}, G −= Y_{k−1}ᵀ V_{k−1}."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    py = op + MR_YK * LANES + lane
    y00, y01, y02 = s[py], s[py + LANES], s[py + 2 * LANES]
    y10, y11, y12 = s[py + 3 * LANES], s[py + 4 * LANES], s[py + 5 * LANES]
    y20, y21, y22 = s[py + 6 * LANES], s[py + 7 * LANES], s[py + 8 * LANES]
    pv = op + MR_G * LANES + lane
    v00, v01 = s[pv], s[pv + LANES]
    v10, v11 = s[pv + 2 * LANES], s[pv + 3 * LANES]
    v20, v21 = s[pv + 4 * LANES], s[pv + 5 * LANES]
    acc = 0.0
    acc += y00 * y00
    acc += y10 * y10
    acc += y20 * y20
    d00 -= acc
    acc = 0.0
    acc += y01 * y00
    acc += y11 * y10
    acc += y21 * y20
    d10 -= acc
    acc = 0.0
    acc += y01 * y01
    acc += y11 * y11
    acc += y21 * y21
    d11 -= acc
    acc = 0.0
    acc += y02 * y00
    acc += y12 * y10
    acc += y22 * y20
    d20 -= acc
    acc = 0.0
    acc += y02 * y01
    acc += y12 * y11
    acc += y22 * y21
    d21 -= acc
    acc = 0.0
    acc += y02 * y02
    acc += y12 * y12
    acc += y22 * y22
    d22 -= acc
    acc = 0.0
    acc += y00 * v00
    acc += y10 * v10
    acc += y20 * v20
    g00 -= acc
    acc = 0.0
    acc += y00 * v01
    acc += y10 * v11
    acc += y20 * v21
    g01 -= acc
    acc = 0.0
    acc += y01 * v00
    acc += y11 * v10
    acc += y21 * v20
    g10 -= acc
    acc = 0.0
    acc += y01 * v01
    acc += y11 * v11
    acc += y21 * v21
    g11 -= acc
    acc = 0.0
    acc += y02 * v00
    acc += y12 * v10
    acc += y22 * v20
    g20 -= acc
    acc = 0.0
    acc += y02 * v01
    acc += y12 * v11
    acc += y22 * v21
    g21 -= acc
    return (d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21)


@njit(**_INL)
def _factor_row(s, lane, o, has_next, terms):
    """Row k's 3×3 Cholesky factor L_k, V_k = L_k⁻¹ G and, with a next stage, Y_k."""
    d00, d10, d11, d20, d21, d22, g00, g10, g20, g01, g11, g21 = terms
    # 3×3 Cholesky (kernels.mhe._chol3); a non-positive pivot marks the lane, no early exit
    ok = d00 > 0.0
    l00 = math.sqrt(d00)
    l10 = d10 / l00
    l20 = d20 / l00
    t = d11 - l10 * l10
    ok = ok & (t > 0.0)
    l11 = math.sqrt(t)
    l21 = (d21 - l20 * l10) / l11
    t = d22 - l20 * l20 - l21 * l21
    ok = ok & (t > 0.0)
    l22 = math.sqrt(t)
    s[MH_BAD * LANES + lane] = s[MH_BAD * LANES + lane] if ok else 1.0
    pl = o + MR_L * LANES + lane
    s[pl], s[pl + LANES], s[pl + 2 * LANES] = l00, l10, l20
    s[pl + 3 * LANES], s[pl + 4 * LANES], s[pl + 5 * LANES] = l11, l21, l22
    pv = o + MR_G * LANES + lane
    v0 = g00 / l00
    v1 = (g10 - l10 * v0) / l11
    v2 = (g20 - l20 * v0 - l21 * v1) / l22
    s[pv], s[pv + 2 * LANES], s[pv + 4 * LANES] = v0, v1, v2
    v0 = g01 / l00
    v1 = (g11 - l10 * v0) / l11
    v2 = (g21 - l20 * v0 - l21 * v1) / l22
    s[pv + LANES], s[pv + 3 * LANES], s[pv + 5 * LANES] = v0, v1, v2
    if has_next:  # Y_k = L_k⁻¹ O_k, column j of O_k = −A_k[j, :] q_j
        pa = o + MR_A * LANES + lane
        py = o + MR_YK * LANES + lane
        for j in range(3):
            qj = s[(MH_Q + j) * LANES + lane]
            o0 = -s[pa + (3 * j) * LANES] * qj
            o1 = -s[pa + (3 * j + 1) * LANES] * qj
            o2 = -s[pa + (3 * j + 2) * LANES] * qj
            y0 = o0 / l00
            y1 = (o1 - l10 * y0) / l11
            y2 = (o2 - l20 * y0 - l21 * y1) / l22
            s[py + j * LANES], s[py + (3 + j) * LANES], s[py + (6 + j) * LANES] = y0, y1, y2


@njit(**_INL)
def _backward(s, k, has_next):
    """Row k of the back substitution L_kᵀ x_k = V_k − Y_k x_{k+1}, both right-hand sides."""
    _, o, on = _rows(k)
    for lane in range(LANES):
        pl = o + MR_L * LANES + lane
        l00, l10, l20 = s[pl], s[pl + LANES], s[pl + 2 * LANES]
        l11, l21, l22 = s[pl + 3 * LANES], s[pl + 4 * LANES], s[pl + 5 * LANES]
        pv = o + MR_G * LANES + lane
        py = o + MR_YK * LANES + lane
        px = o + MR_XG * LANES + lane
        for c in range(2):
            t0, t1, t2 = s[pv + c * LANES], s[pv + (2 + c) * LANES], s[pv + (4 + c) * LANES]
            if has_next:
                for j in range(3):
                    xj = s[on + (MR_XG + 2 * j + c) * LANES + lane]
                    t0 -= s[py + j * LANES] * xj
                    t1 -= s[py + (3 + j) * LANES] * xj
                    t2 -= s[py + (6 + j) * LANES] * xj
            x2 = t2 / l22
            x1 = (t1 - l21 * x2) / l11
            x0 = (t0 - l10 * x1 - l20 * x2) / l00
            s[px + c * LANES], s[px + (2 + c) * LANES], s[px + (4 + c) * LANES] = x0, x1, x2


@njit(**_INL)
def _border(s, k, has_prev, has_next):
    """Row k's share of hᵀT⁻¹g and hᵀT⁻¹h (the Schur complement on F)."""
    op, o, _ = _rows(k)
    for lane in range(LANES):
        hg = s[MH_HG * LANES + lane]
        hh = s[MH_HH * LANES + lane]
        for i in range(3):
            hk = 0.0
            if has_prev:
                hk += s[(MH_Q + i) * LANES + lane] * s[op + (MR_B + 2 * i) * LANES + lane]
            if has_next:
                for j in range(3):
                    hk += s[o + (MR_A + 3 * j + i) * LANES + lane] * s[(MH_Q + j) * LANES + lane] \
                        * (-s[o + (MR_B + 2 * j) * LANES + lane])
            hg += hk * s[o + (MR_XG + 2 * i) * LANES + lane]
            hh += hk * s[o + (MR_XG + 2 * i + 1) * LANES + lane]
        s[MH_HG * LANES + lane] = hg
        s[MH_HH * LANES + lane] = hh


@njit(**_NJ)
def mhe_window_lanes(s, n):
    """The model matrices of window rows 0 … n−1 and the window minimiser of
    :func:`tsmpc.kernels.mhe.banded_solve` for every lane of workspace ``s`` (window of n
    intervals, n ≥ 2): states into MR_X of rows 0 … n, F into MH_F, MH_BAD = 1 where banded_solve
    returns NaN (a non-positive pivot or Schur complement)."""
    for k in range(n):
        _euler_lanes(s, k)
    for lane in range(LANES):
        pf = s[MH_PF * LANES + lane]
        s[MH_HFF * LANES + lane] = pf
        s[MH_GF * LANES + lane] = pf * s[MH_FP * LANES + lane]
        s[MH_BAD * LANES + lane] = 0.0
        s[MH_HG * LANES + lane] = 0.0
        s[MH_HH * LANES + lane] = 0.0
    _forward(s, 0, True, False, True)
    for k in range(1, n):
        _forward(s, k, False, True, True)
    _forward(s, n, False, True, False)
    _backward(s, n, False)
    for k in range(n - 1, -1, -1):
        _backward(s, k, True)
    _border(s, 0, False, True)
    for k in range(1, n):
        _border(s, k, True, True)
    _border(s, n, True, False)
    for lane in range(LANES):
        den = s[MH_HFF * LANES + lane] - s[MH_HH * LANES + lane]
        s[MH_BAD * LANES + lane] = s[MH_BAD * LANES + lane] if den > 0.0 else 1.0
        s[MH_F * LANES + lane] = (s[MH_GF * LANES + lane] - s[MH_HG * LANES + lane]) / den
    for k in range(n + 1):
        o = _rows(k)[1]
        for i in range(3):
            for lane in range(LANES):
                s[o + (MR_X + i) * LANES + lane] = s[o + (MR_XG + 2 * i) * LANES + lane] \
                    - s[o + (MR_XG + 2 * i + 1) * LANES + lane] * s[MH_F * LANES + lane]


# ============================================================================ the engine's step
# Each lane runs the engine's own compiled run() (the same machine code, loaded from its cache)
# with ip[IP_DEFER] set: run() then returns NEED_PLANT where it would integrate the plant and
# NEED_MHE where it would solve the MHE window (after the window update, the model's last row and
# the prediction); advance() does both for every lane at once and the lane goes on.


@intrinsic
def _lane_of(typingctx, arr, index):
    """``arr[index]`` of a C-contiguous array of ≥ 2 dimensions as a view *without* a reference
    count (no meminfo, like numba.carray's arrays). The lane's step takes ~54 such arrays per
    call and the atomic reference counting of ordinary views would cost more than the step;
    ``arr`` outlives the view (it is advance()'s argument)."""
    if not isinstance(arr, nbtypes.Array) or arr.ndim < 2 or arr.layout != "C":
        return None
    out_t = arr.copy(ndim=arr.ndim - 1, layout="C")

    def codegen(context, builder, signature, args):
        aty, ity = signature.args
        a = context.make_array(aty)(context, builder, args[0])
        out = context.make_array(signature.return_type)(context, builder)
        shape = cgutils.unpack_tuple(builder, a.shape)
        strides = cgutils.unpack_tuple(builder, a.strides)
        i = context.cast(builder, args[1], ity, nbtypes.intp)
        data = cgutils.pointer_add(builder, a.data, builder.mul(i, strides[0]))
        populate_array(out, data=data, shape=shape[1:], strides=strides[1:], itemsize=a.itemsize,
                       meminfo=None)
        return out._getvalue()
    return out_t(arr, index), codegen


# lane states in advance()
READY, AT_MHE, AT_PLANT, NEEDS_PYTHON, FINISHED = range(5)


@njit(**_NJ)
def _angle_cache(U, n, lo0, hi0, key, sn, cs):
    """sin/cos of the clipped steering angles of window rows 0 … n−1 (libm, as euler_matrices),
    reusing last step's row k+1 (the window shifted) or row k (it grew) when the angle is the same
    double."""
    for k in range(n):
        d = min(max(U[k, 1], lo0), hi0)
        if k + 1 < key.size and key[k + 1] == d:
            s_, c_ = sn[k + 1], cs[k + 1]
        elif key[k] == d:
            s_, c_ = sn[k], cs[k]
        else:
            s_, c_ = math.sin(d), math.cos(d)
        key[k], sn[k], cs[k] = d, s_, c_


@njit(**_NJ)
def _mhe_gather(s, slot, n, mY, mW, mU, mXS, mp, sf, si, key, sn, cs):
    """One lane's window (waiting in the deferred solve) into workspace slot ``slot``."""
    full = si[ke.SI_MHEFULL] != 0
    s[MH_TD * LANES + slot] = mp[km.MP_TD]
    for i, f in ((km.MP_M, MH_M), (km.MP_I, MH_I), (km.MP_CF, MH_CF), (km.MP_CR, MH_CR),
                 (km.MP_A, MH_AA), (km.MP_B, MH_BB), (km.MP_MUG, MH_MUG), (km.MP_KD, MH_KD)):
        s[f * LANES + slot] = mp[i]
    for i in range(3):
        s[(MH_Q + i) * LANES + slot] = mp[km.MP_Q + i]
        s[(MH_P + i) * LANES + slot] = mp[km.MP_P + i]
        s[(MH_ARR + i) * LANES + slot] = mXS[0, i] if full else sf[ke.SF_ARR + i]
    s[MH_R * LANES + slot] = mp[km.MP_R]
    s[(MH_R + 1) * LANES + slot] = mp[km.MP_R + 1]
    s[MH_PF * LANES + slot] = mp[km.MP_PF]
    s[MH_FP * LANES + slot] = sf[ke.SF_MF]
    s[MH_LIN * LANES + slot] = mp[km.MP_MARGIN + 5]
    _angle_cache(mU, n, mp[km.MP_LO], mp[km.MP_HI], key, sn, cs)
    lo1, hi1 = mp[km.MP_LO + 1], mp[km.MP_HI + 1]
    for k in range(n + 1):
        o = (k + 1) * MR * LANES + slot
        s[o + MR_Y * LANES] = mY[k, 0]
        s[o + (MR_Y + 1) * LANES] = mY[k, 1]
        s[o + MR_W * LANES] = mW[k]
        if k < n:
            s[o + MR_U * LANES] = mU[k, 0]
            s[o + (MR_U + 1) * LANES] = mU[k, 1]
            s[o + MR_V * LANES] = min(max(mXS[k, 0], lo1), hi1)
            s[o + MR_SD * LANES] = sn[k]
            s[o + MR_CD * LANES] = cs[k]


@njit(**_NJ)
def margin_lanes(s, n):
    """tsmpc.estimation.mhe_margin.margin_residual for every lane of a solved workspace (window of n
    intervals; F̂ in MH_F, the states in MR_X): the same arithmetic in the same order, lane
    innermost — the residual mean square into MH_MSQ, 1/0 into MH_MOK for a window within the
    linear tyres (tests/test_mhe_margin.py compares the two forms)."""
    for lane in range(LANES):
        s[MH_MSQ * LANES + lane] = 0.0
        s[MH_MOK * LANES + lane] = 1.0
    for k in range(n + 1):
        o = _rows(k)[1]
        ou = _rows(min(k, n - 1))[1]
        for lane in range(LANES):
            lin = s[MH_LIN * LANES + lane]
            a, b = s[MH_AA * LANES + lane], s[MH_BB * LANES + lane]
            L = a + b
            mug, M = s[MH_MUG * LANES + lane], s[MH_M * LANES + lane]
            sat_f = mug * M * b / (L * s[MH_CF * LANES + lane])
            sat_r = mug * M * a / (L * s[MH_CR * LANES + lane])
            x0, x1, x2 = s[o + MR_X * LANES + lane], s[o + (MR_X + 1) * LANES + lane], \
                s[o + (MR_X + 2) * LANES + lane]
            v = max(x0, 1.0)
            a_f = s[ou + (MR_U + 1) * LANES + lane] - x1 - a * x2 / v
            a_r = b * x2 / v - x1
            out = lin > 0.0 and (abs(a_f) > lin * sat_f or abs(a_r) > lin * sat_r)
            s[MH_MOK * LANES + lane] = 0.0 if out else s[MH_MOK * LANES + lane]
    for k in range(n):
        o, o1 = _rows(k)[1], _rows(k + 1)[1]
        for lane in range(LANES):
            F = s[MH_F * LANES + lane]
            pred = (s[o + (MR_A + 3) * LANES + lane] * s[o + MR_X * LANES + lane]
                    + s[o + (MR_A + 4) * LANES + lane] * s[o + (MR_X + 1) * LANES + lane]
                    + s[o + (MR_A + 5) * LANES + lane] * s[o + (MR_X + 2) * LANES + lane]
                    + s[o + (MR_B + 2) * LANES + lane] * (s[o + MR_U * LANES + lane] - F)
                    + s[o + (MR_B + 3) * LANES + lane] * s[o + (MR_U + 1) * LANES + lane])
            w = s[o1 + (MR_X + 1) * LANES + lane] - pred
            s[MH_MSQ * LANES + lane] += w * w
    for lane in range(LANES):
        s[MH_MSQ * LANES + lane] = s[MH_MSQ * LANES + lane] / n


@njit(**_NJ)
def _mhe_finish(s, slot, n, mXS, mA, mB, mp, sf, si, sc):
    """window_step's and the MHE block's ends for one lane from its solved slot: True when the
    estimate is in (the window's minimiser within the state bounds), False when the dense QP must
    decide (the model matrices then in mA, mB as window_step leaves them)."""
    F = s[MH_F * LANES + slot]
    good = s[MH_BAD * LANES + slot] == 0.0 and math.isfinite(F)
    if good:
        for k in range(n + 1):
            o = (k + 1) * MR * LANES + slot
            for i in range(3):
                v = s[o + (MR_X + i) * LANES]
                if not (v >= mp[km.MP_XMIN + i] - 1e-9 and v <= mp[km.MP_XMAX + i] + 1e-9):
                    good = False
    if not good:
        for k in range(n):
            o = (k + 1) * MR * LANES + slot
            for i in range(3):
                for j in range(3):
                    mA[k, i, j] = s[o + (MR_A + 3 * i + j) * LANES]
                mB[k, i, 0] = s[o + (MR_B + 2 * i) * LANES]
                mB[k, i, 1] = s[o + (MR_B + 2 * i + 1) * LANES]
        return False
    for k in range(n + 1):
        o = (k + 1) * MR * LANES + slot
        for i in range(3):
            mXS[k, i] = s[o + (MR_X + i) * LANES]
    ms = sf[ke.SF_MX:ke.SF_MX + km.N_MS]  # the estimate: the MHE's own ends (kernels.mhe, mhe_block.py)
    si[ke.SI_ESTSTAT] = km.mhe_solved(ms, mXS, n, F, si[ke.SI_MHEFULL] != 0)
    if si[ke.SI_ESTSTAT] == km.MHE_OK and mp[km.MP_MARGIN] > 0.0:
        # the yaw-model margin (estimation/mhe_margin.py's margin_update, as kernels.mhe.mhe_solve): its
        # window arithmetic done by margin_lanes for every lane, its step here
        km.margin_apply(mp, ms, s[MH_MSQ * LANES + slot], s[MH_MOK * LANES + slot] != 0.0)
    estimate_out(ms, sc[ke.SC_EST:ke.SC_EST + N_EO], sc[ke.SC_ESTFR])
    return True


@njit(**_NJ)
def _plant_gather(s, slot, x, sc, cst):
    """One lane's plant step into workspace slot ``slot``."""
    for i in range(6):
        s[(PW_X + i) * LANES + slot] = x[i]
    d = sc[ke.SC_OD]
    s[PW_F * LANES + slot] = sc[ke.SC_OF]
    s[PW_D * LANES + slot] = d
    s[PW_MU * LANES + slot] = sc[ke.SC_MU]
    s[PW_COSD * LANES + slot] = math.cos(d)
    for i in range(18):
        s[(PW_CST + i) * LANES + slot] = cst[i]


@njit(**_NJ)
def _vector_plant_ok(x, sc):
    """May this lane's plant step go through the vector kernel? (finite inputs, as rk4_block
    demands, and angles within the polynomial sin/cos's reduction range)"""
    for i in range(6):
        if not math.isfinite(x[i]):
            return False
    return (math.isfinite(sc[ke.SC_OF]) and math.isfinite(sc[ke.SC_OD])
            and math.isfinite(sc[ke.SC_MU]) and abs(x[2]) < SINCOS_MAX and abs(x[4]) < SINCOS_MAX)


@njit(cache=True, fastmath=False, error_model="numpy")
def advance(m_end, exact_plant, state, need, tally, pw, mws, akey, asin, acos, lanes,
            x, fp, ip, sf, si, sc, ev, noise, u_drop, gnss, fifo, frb, patches, events,
            ref_x, ref_y, ref_th, ref_v, ref_w, th_tan, mv, mw_, gate, cur, ivs, mass_v,
            mY, mW, mU, mXS, mA, mB, mX, mp, ls, Kv, zlo, zhi, bits, prm,
            mints, mprm, mPS, prevX, prevU, pX, pU, cst, lo, loi, lxp, li, lstat, lsat):
    """Advance every lane (first axis of the engine's arrays, stacked) to step ``m_end`` or until
    a lane needs Python. ``state[l]``: READY / AT_MHE / AT_PLANT / NEEDS_PYTHON (``need[l]``: the
    engine's NEED_* code) / FINISHED (``need[l]``: DONE or DIVERGED). Returns how many lanes need
    Python (0: all FINISHED). ``pw``, ``mws``: plant and MHE workspaces; ``akey``/``asin``/
    ``acos`` (B, N_W): the window angles' sin/cos cache; ``lanes`` (LANES,) scratch;
    ``tally`` [lanes solved, vector plant steps, ticks in the window solves, ticks in the
    plant]."""
    B = x.shape[0]
    while True:
        for b in range(B):
            if state[b] != READY:
                continue
            code = ke.run(m_end, _lane_of(x, b), _lane_of(fp, b), _lane_of(ip, b), _lane_of(sf, b),
                         _lane_of(si, b), _lane_of(sc, b), _lane_of(ev, b), _lane_of(noise, b),
                         _lane_of(u_drop, b), _lane_of(gnss, b), _lane_of(fifo, b),
                         _lane_of(frb, b), _lane_of(patches, b), _lane_of(events, b),
                         _lane_of(ref_x, b), _lane_of(ref_y, b), _lane_of(ref_th, b),
                         _lane_of(ref_v, b), _lane_of(ref_w, b), _lane_of(th_tan, b),
                         _lane_of(mv, b), _lane_of(mw_, b), _lane_of(gate, b), _lane_of(cur, b),
                         _lane_of(ivs, b), _lane_of(mass_v, b), _lane_of(mY, b), _lane_of(mW, b),
                         _lane_of(mU, b), _lane_of(mXS, b), _lane_of(mA, b), _lane_of(mB, b),
                         _lane_of(mX, b), _lane_of(mp, b), _lane_of(ls, b), _lane_of(Kv, b),
                         _lane_of(zlo, b), _lane_of(zhi, b), _lane_of(bits, b), _lane_of(prm, b),
                         _lane_of(mints, b), _lane_of(mprm, b), _lane_of(mPS, b),
                         _lane_of(prevX, b), _lane_of(prevU, b), _lane_of(pX, b), _lane_of(pU, b),
                         _lane_of(cst, b), _lane_of(lo, b), _lane_of(loi, b), _lane_of(lxp, b),
                         _lane_of(li, b), _lane_of(lstat, b), _lane_of(lsat, b))
            if code == ke.NEED_MHE:
                state[b] = AT_MHE
            elif code == ke.NEED_PLANT:
                state[b] = AT_PLANT
            elif code == ke.DONE or code == ke.DIVERGED:
                state[b], need[b] = FINISHED, code
            else:
                state[b], need[b] = NEEDS_PYTHON, code
        _mhe_groups(state, need, tally, mws, lanes, akey, asin, acos, sf, si, sc, li, mY, mW, mU, mXS,
                    mA, mB, mp)
        _plant_lanes(exact_plant, state, need, tally, pw, lanes, x, fp, ip, sf, sc, cst)
        waiting = 0
        running = 0
        for b in range(B):
            if state[b] == NEEDS_PYTHON:
                waiting += 1
            elif state[b] != FINISHED:
                running += 1
        if waiting > 0 or running == 0:
            return waiting


@njit(**_NJ)
def _mhe_groups(state, need, tally, mws, lanes, akey, asin, acos, sf, si, sc, li, mY, mW, mU, mXS,
                mA, mB, mp):
    """advance()'s MHE windows: the lanes waiting AT_MHE, LANES of equal window length at a
    time, gathered, solved together and finished (READY, or NEEDS_PYTHON when the dense QP
    must decide)."""
    B = state.shape[0]
    b0 = 0
    while b0 < B:
        n_sel = 0
        n = -1
        for b in range(b0, B):
            if state[b] == AT_MHE and (n < 0 or si[b, ke.SI_MHEN] == n):
                n = si[b, ke.SI_MHEN]
                lanes[n_sel] = b
                n_sel += 1
                if n_sel == LANES:
                    break
        if n_sel == 0:
            break
        t0 = ke._ticks()
        for j in range(n_sel):
            b = lanes[j]
            _mhe_gather(mws, j, n, mY[b], mW[b], mU[b], mXS[b], mp[b], sf[b], si[b],
                        akey[b], asin[b], acos[b])
        mhe_window_lanes(mws, n)
        margin_lanes(mws, n)
        for j in range(n_sel):
            b = lanes[j]
            if _mhe_finish(mws, j, n, mXS[b], mA[b], mB[b], mp[b], sf[b], si[b], sc[b]):
                state[b] = READY
            else:
                state[b], need[b] = NEEDS_PYTHON, ke.NEED_MHE
        dt = ke._ticks() - t0
        tally[0] += n_sel
        tally[2] += dt
        for j in range(n_sel):  # each lane's share of the batched solve
            b = lanes[j]
            li[b, si[b, ke.SI_M], ke.LI_TMHE] = float(dt) / n_sel


@njit(**_NJ)
def _plant_lanes(exact_plant, state, need, tally, pw, lanes, x, fp, ip, sf, sc, cst):
    """advance()'s plant steps: the lanes waiting AT_PLANT through the vector RK4, LANES at a
    time (the scalar block where a lane's inputs are not for the vector kernel)."""
    B = state.shape[0]
    t0 = ke._ticks()
    n_sel = 0
    for b in range(B):
        if state[b] != AT_PLANT:
            continue
        if exact_plant or not _vector_plant_ok(x[b], sc[b]) or (
                n_sel > 0 and (ip[b, ke.IP_NSUB] != ip[lanes[0], ke.IP_NSUB]
                               or fp[b, ke.FP_H] != fp[lanes[0], ke.FP_H])):
            xn, ok = kplant.rk4_block(x[b], sc[b, ke.SC_OF], sc[b, ke.SC_OD], sc[b, ke.SC_MU],
                                      ip[b, ke.IP_NSUB], fp[b, ke.FP_H], cst[b])
            if ok:
                x[b, :] = xn
                sf[b, ke.SF_PLANTU], sf[b, ke.SF_PLANTU + 1] = sc[b, ke.SC_OF], sc[b, ke.SC_OD]
                state[b] = READY
            else:
                state[b], need[b] = NEEDS_PYTHON, ke.NEED_PLANT
            continue
        _plant_gather(pw, n_sel, x[b], sc[b], cst[b])
        lanes[n_sel] = b
        n_sel += 1
        if n_sel == LANES:
            _plant_group(pw, n_sel, lanes, x, sf, sc, ip, fp, state, need)
            tally[1] += n_sel
            n_sel = 0
    if n_sel > 0:
        _plant_group(pw, n_sel, lanes, x, sf, sc, ip, fp, state, need)
        tally[1] += n_sel
    tally[3] += ke._ticks() - t0


@njit(**_NJ)
def _plant_group(pw, n_sel, lanes, x, sf, sc, ip, fp, state, need):
    """The vector RK4 of the gathered lanes; results back, or the lane to Python when its step
    is not finite (rk4_block's ok)."""
    b0 = lanes[0]
    rk4_lanes(pw, ip[b0, ke.IP_NSUB], fp[b0, ke.FP_H])
    for j in range(n_sel):
        b = lanes[j]
        ok = True
        for i in range(6):
            v = pw[(PW_X + i) * LANES + j]
            if not math.isfinite(v):
                ok = False
        if ok:
            for i in range(6):
                x[b, i] = pw[(PW_X + i) * LANES + j]
            sf[b, ke.SF_PLANTU], sf[b, ke.SF_PLANTU + 1] = sc[b, ke.SC_OF], sc[b, ke.SC_OD]
            state[b] = READY
        else:
            state[b], need[b] = NEEDS_PYTHON, ke.NEED_PLANT
