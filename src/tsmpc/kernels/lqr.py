"""TS-LQR step (:class:`tsmpc.control.ts_lqr.TSLQR`, the paper's inner loop) in one compiled call.

Law (issue 13's): ``u_f = N̄(ϑ) r + K(ϑ) x`` with the blended LMI gain ``K(ϑ) = Σ μ_i(ϑ) K_i`` and
the static reference gain ``N̄ = −[C (A + B K₅)⁻¹ B]⁻¹`` of the continuous plant + Apkarian filter
at ϑ; the filter, the yaw-rate integrator with anti-windup, the force terms outside the filter
(speed-error feedback, friction compensation) and the saturations as in the numpy step.

Structure: :func:`reference_gain` (the feed-forward: change it here if the law changes),
:func:`blend` (memberships and K(ϑ)), :func:`lqr_step` (filter, integrator, saturation). The
controller state lives in a float vector ``[f_F, f_δ, ζ, started, applied_F, applied_δ]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["lqr_step", "warm"]


@njit(cache=True, fastmath=False)
def blend(z0, z1, z2, Kv, zlo, zhi, bits, K):
    """K (2, 6) = Σ μ_i(z) K_i with the box memberships of z = (δ, v, α) (clipped)."""
    e0 = min(max((z0 - zlo[0]) / (zhi[0] - zlo[0]), 0.0), 1.0)
    e1 = min(max((z1 - zlo[1]) / (zhi[1] - zlo[1]), 0.0), 1.0)
    e2 = min(max((z2 - zlo[2]) / (zhi[2] - zlo[2]), 0.0), 1.0)
    for r in range(2):
        for c in range(6):
            K[r, c] = 0.0
    for i in range(Kv.shape[0]):
        m = 1.0
        m *= e0 if bits[i, 0] else 1.0 - e0
        m *= e1 if bits[i, 1] else 1.0 - e1
        m *= e2 if bits[i, 2] else 1.0 - e2
        for r in range(2):
            for c in range(6):
                K[r, c] += m * Kv[i, r, c]


@njit(cache=True, fastmath=False)
def _plant_filter(delta, v, zlo, zhi, prm, lam, Aa):
    """Continuous plant + filter matrix (5, 5) at (δ, v) clipped into the box; B_a = λ [0; I]."""
    delta = min(max(delta, zlo[0]), zhi[0])
    v = min(max(v, zlo[1]), zhi[1])
    M, I, Cf, Cr, a, b, mug, kd = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7]
    sd, cd = math.sin(delta), math.cos(delta)
    for i in range(5):
        for j in range(5):
            Aa[i, j] = 0.0
    Aa[0, 0] = -mug / v - kd * v / M
    Aa[0, 1] = Cf * sd / M
    Aa[0, 2] = Cf * a * sd / (M * v)
    Aa[1, 1] = -(Cr + Cf * cd) / (M * v)
    Aa[1, 2] = (Cr * b - Cf * a * cd) / (M * v**2) - 1.0
    Aa[2, 1] = (Cr * b - Cf * a * cd) / I
    Aa[2, 2] = -(Cf * a**2 * cd + Cr * b**2) / (I * v)
    Aa[0, 3] = 1.0 / M
    Aa[0, 4] = -Cf * sd / M
    Aa[1, 4] = Cf * cd / (M * v)
    Aa[2, 4] = Cf * a * cd / I
    Aa[3, 3] = -lam
    Aa[4, 4] = -lam


@njit(cache=True, fastmath=False)
def _solve5(Mx, Rhs):
    """Solve Mx X = Rhs (5×5, 5×k) in place in Rhs by LU with partial pivoting; False if singular."""
    n = 5
    k = Rhs.shape[1]
    for c in range(n):
        p = c
        best = abs(Mx[c, c])
        for r in range(c + 1, n):
            if abs(Mx[r, c]) > best:
                best = abs(Mx[r, c])
                p = r
        if not best > 0.0:
            return False
        if p != c:
            for j in range(n):
                t = Mx[c, j]
                Mx[c, j] = Mx[p, j]
                Mx[p, j] = t
            for j in range(k):
                t = Rhs[c, j]
                Rhs[c, j] = Rhs[p, j]
                Rhs[p, j] = t
        piv = Mx[c, c]
        for r in range(c + 1, n):
            f = Mx[r, c] / piv
            if f != 0.0:
                for j in range(c + 1, n):
                    Mx[r, j] -= f * Mx[c, j]
                for j in range(k):
                    Rhs[r, j] -= f * Rhs[c, j]
    for j in range(k):
        for r in range(n - 1, -1, -1):
            acc = Rhs[r, j]
            for c in range(r + 1, n):
                acc -= Mx[r, c] * Rhs[c, j]
            Rhs[r, j] = acc / Mx[r, r]
    return True


@njit(cache=True, fastmath=False)
def reference_gain(delta, v, K, zlo, zhi, prm, lam, Nbar, Aa):
    """N̄ (2, 2) = −[C (A + B K₅)⁻¹ B]⁻¹ at (δ, v); Aa is left holding A + B K₅ factored, so
    callers needing it again must rebuild it. False if singular."""
    _plant_filter(delta, v, zlo, zhi, prm, lam, Aa)
    for j in range(5):
        Aa[3, j] += lam * K[0, j]
        Aa[4, j] += lam * K[1, j]
    X = np.zeros((5, 2))
    X[3, 0] = lam
    X[4, 1] = lam
    if not _solve5(Aa, X):
        return False
    a, b, c, d = X[0, 0], X[0, 1], X[2, 0], X[2, 1]
    det = a * d - b * c
    if det == 0.0 or not math.isfinite(det):
        return False
    Nbar[0, 0], Nbar[0, 1] = -d / det, b / det
    Nbar[1, 0], Nbar[1, 1] = c / det, -a / det
    return True


@njit(cache=True, fastmath=False)
def lqr_step(s, v, al, om, F_hat, v_ref, w_ref, Kv, zlo, zhi, bits, prm, lam, afilt, Td,
             Fmin, Fmax, dmin, dmax, speed_fb, tau):
    """One step; updates the state vector s in place. Returns (F_xR, δ, saturated, ok) — ok False
    when N̄ is singular (the caller then runs the numpy step, which decides)."""
    K = np.empty((2, 6))
    Nbar = np.empty((2, 2))
    Aa = np.empty((5, 5))
    if s[3] == 0.0:  # bumpless start: filter at the steady-state input of r, ζ = 0
        blend(0.0, v, al, Kv, zlo, zhi, bits, K)
        if not reference_gain(0.0, v, K, zlo, zhi, prm, lam, Nbar, Aa):
            return 0.0, 0.0, False, False
        _plant_filter(0.0, v, zlo, zhi, prm, lam, Aa)
        for j in range(5):
            Aa[3, j] += lam * K[0, j]
            Aa[4, j] += lam * K[1, j]
        rhs = np.zeros((5, 1))
        rhs[3, 0] = lam * (Nbar[0, 0] * v_ref + Nbar[0, 1] * w_ref)
        rhs[4, 0] = lam * (Nbar[1, 0] * v_ref + Nbar[1, 1] * w_ref)
        if not _solve5(Aa, rhs):
            return 0.0, 0.0, False, False
        s[0] = min(max(-rhs[3, 0], Fmin), Fmax)
        s[1] = min(max(-rhs[4, 0], dmin), dmax)
        s[3] = 1.0
    f0, f1, zeta = s[0], s[1], s[2]
    blend(f1, v, al, Kv, zlo, zhi, bits, K)
    if not reference_gain(f1, v, K, zlo, zhi, prm, lam, Nbar, Aa):
        return 0.0, 0.0, False, False
    x0, x1, x2, x3, x4, x5 = v, al, om, f0, f1, zeta
    kx0 = K[0, 0] * x0 + K[0, 1] * x1 + K[0, 2] * x2 + K[0, 3] * x3 + K[0, 4] * x4 + K[0, 5] * x5
    kx1 = K[1, 0] * x0 + K[1, 1] * x1 + K[1, 2] * x2 + K[1, 3] * x3 + K[1, 4] * x4 + K[1, 5] * x5
    u0 = (Nbar[0, 0] * v_ref + Nbar[0, 1] * w_ref) + kx0  # N̄ r + K x, as the numpy step
    u1 = (Nbar[1, 0] * v_ref + Nbar[1, 1] * w_ref) + kx1
    u0 = min(max(u0, Fmin), Fmax)
    u1 = min(max(u1, dmin), dmax)
    F_add = prm[0] * (v_ref - v) / tau if speed_fb else 0.0
    out0 = f0 + F_add + F_hat
    o0 = min(max(out0, Fmin), Fmax)
    o1 = min(max(f1, dmin), dmax)
    saturated = o0 != out0 or o1 != f1
    s[0] = min(max(afilt * f0 + (1.0 - afilt) * u0, Fmin), Fmax)
    s[1] = min(max(afilt * f1 + (1.0 - afilt) * u1, dmin), dmax)
    if not saturated:
        s[2] = zeta + Td * (w_ref - om)
    s[4], s[5] = o0, o1
    return o0, o1, saturated, True


def warm() -> None:
    """Compile (or load from the cache) the signature the controller uses."""
    Kv = np.zeros((8, 2, 6))
    Kv[:, 0, 0] = -100.0
    Kv[:, 1, 2] = -0.1
    bits = np.array([[(i >> j) & 1 for j in range(3)] for i in range(8)], dtype=np.bool_)
    prm = np.array([683.0, 560.0, 25000.0, 25000.0, 0.758, 1.036, 4.9, 0.4])
    lqr_step(np.zeros(6), 10.0, 0.0, 0.0, 0.0, 10.0, 0.0, Kv, np.array([-0.4, 2.0, -0.1]),
             np.array([0.4, 20.0, 0.1]), bits, prm, 10.0, 0.9, 0.01, -2000.0, 10000.0, -0.4, 0.4, True, 0.3)
