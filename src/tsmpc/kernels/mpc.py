"""TS-MPC fast path: the unconstrained minimiser by a backward Riccati recursion (O(N)).

For a fixed scheduling sequence the MPC of :mod:`tsmpc.control.ts_mpc` is a time-varying LQ
problem in the augmented state ``ξ_i = [e_x, e_y, e_θ, u_{i−1}]`` with input ``Δu_i``::

    ξ_{i+1} = Ā_i ξ_i + B̄ Δu_i + d_i,   Ā_i = [[A_i, B_c], [0, I]],  B̄ = [[B_c], [I]],
    d_i = [−B_c r_i; 0],   cost Σ ξ_iᵀ diag(Q, 0) ξ_i + Δu_iᵀ R Δu_i + ξ_Nᵀ diag(P, 0) ξ_N,

with (complex notation of the condensed form) ``e_x⁺ = e_x + c_i e_y − T_c w_v``,
``e_y⁺ = −c_i e_x + e_y + s_i e_θ``, ``e_θ⁺ = e_θ − T_c w_ω`` and ``w = u − r``. Its minimiser is
the condensed QP's unconstrained minimiser ``−H⁻¹f`` (same problem, different factorisation).
The kernel also schedules (FZN/REF/ITER premises, clipping) and iterates ITER's schedule, and
checks every constraint of the hard problem exactly as ``TSMPC._solve`` does (rates, inputs,
terminal ellipsoid); if one is violated it returns code 1 and the caller runs the condensed
QP path (DAQP, cuts, SOCP) from the start.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["fast_step", "guarded_step", "warm"]

FZN, REF, ITER = 0, 1, 2


@njit(cache=True, fastmath=False)
def _sinc(x: float) -> float:
    if x == 0.0:
        return 1.0
    y = x / math.pi  # as numpy's sinc(x/π), so both paths schedule on the same number
    return math.sin(math.pi * y) / (math.pi * y)


@njit(cache=True, fastmath=False)
def _schedule(mode, x0, up, v_d, w_d, om, eth, lo, hi, Tc, c, s, r):
    """c, s, r in place; returns the number of clipped premise points (as TSMPC._schedule)."""
    N = v_d.size
    if mode == FZN:
        e = x0[2]
        z0 = up[1]
        z1 = v_d[0]
        z2 = math.sin(e) / e if e != 0.0 else 1.0
        a0 = min(max(z0, lo[0]), hi[0])
        a1 = min(max(z1, lo[1]), hi[1])
        a2 = min(max(z2, lo[2]), hi[2])
        ce = math.cos(e)
        for i in range(N):
            c[i] = a0 * Tc
            s[i] = a1 * a2 * Tc
            r[i, 0] = v_d[i] * ce
            r[i, 1] = w_d[i]
        return N if (a0 != z0 or a1 != z1 or a2 != z2) else 0
    n_clip = 0
    for i in range(N):
        z0 = om[i]
        z1 = v_d[i]
        z2 = _sinc(eth[i])
        a0 = min(max(z0, lo[0]), hi[0])
        a1 = min(max(z1, lo[1]), hi[1])
        a2 = min(max(z2, lo[2]), hi[2])
        if a0 != z0 or a1 != z1 or a2 != z2:
            n_clip += 1
        c[i] = a0 * Tc
        s[i] = a1 * a2 * Tc
        r[i, 0] = v_d[i] * math.cos(eth[i])
        r[i, 1] = w_d[i]
    return n_clip


@njit(cache=True, fastmath=False)
def riccati(x0, up, c, s, r, Tc, q, P, rd, U, DU, X):
    """Unconstrained minimiser for one schedule: U (N, 2), ΔU (N, 2), X (N+1, 3) in place; returns
    the cost (including x_0ᵀQx_0) or NaN if a pivot is not positive."""
    N = c.size
    K = np.empty((N, 2, 5))
    kf = np.empty((N, 2))
    if not _backward(c, s, r, Tc, q, P, rd, K, kf):
        return np.nan
    return _rollout(x0, up, c, s, r, Tc, q, P, rd, K, kf, U, DU, X)


@njit(cache=True, fastmath=False)
def _backward(c, s, r, Tc, q, P, rd, K, kf):
    """The Riccati recursion from the terminal weight P backwards: the feedback K (N, 2, 5) and
    feed-forward kf (N, 2) of ΔU in place; False if a pivot is not positive."""
    N = c.size
    Pm = np.zeros((5, 5))
    pv = np.zeros(5)
    for a in range(3):
        for b in range(3):
            Pm[a, b] = P[a, b]
    # B̄ columns: Δv → [−Tc, 0, 0, 1, 0], Δω → [0, 0, −Tc, 0, 1]
    PA = np.empty((5, 5))
    PB = np.empty((5, 2))
    Pd = np.empty(5)
    Hux = np.empty((2, 5))
    for i in range(N - 1, -1, -1):
        ci = c[i]
        si = s[i]
        d0 = Tc * r[i, 0]
        d2 = Tc * r[i, 1]
        # Ā = I + (Ā₀₁ = c, Ā₁₀ = −c, Ā₁₂ = s, Ā₀₃ = Ā₂₄ = −T_c): the products below take only its
        # non-zero entries, in the order of the dense sums they replace (bit-identical results:
        # the dense sums only added exact zeros).
        for a in range(5):
            p0, p1, p2, p3, p4 = Pm[a, 0], Pm[a, 1], Pm[a, 2], Pm[a, 3], Pm[a, 4]
            PA[a, 0] = p0 + p1 * -ci
            PA[a, 1] = p0 * ci + p1
            PA[a, 2] = p1 * si + p2
            PA[a, 3] = p0 * -Tc + p3
            PA[a, 4] = p2 * -Tc + p4
            PB[a, 0] = -Tc * p0 + p3
            PB[a, 1] = -Tc * p2 + p4
            Pd[a] = pv[a] + p0 * d0 + p2 * d2
        h00 = rd[0] + (-Tc * PB[0, 0] + PB[3, 0])
        h01 = -Tc * PB[0, 1] + PB[3, 1]
        h11 = rd[1] + (-Tc * PB[2, 1] + PB[4, 1])
        for b in range(5):
            Hux[0, b] = -Tc * PA[0, b] + PA[3, b]
            Hux[1, b] = -Tc * PA[2, b] + PA[4, b]
        hu0 = -Tc * Pd[0] + Pd[3]
        hu1 = -Tc * Pd[2] + Pd[4]
        det = h00 * h11 - h01 * h01
        if not (h00 > 0.0 and det > 0.0):
            return False
        i00, i01, i11 = h11 / det, -h01 / det, h00 / det
        for b in range(5):
            K[i, 0, b] = -(i00 * Hux[0, b] + i01 * Hux[1, b])
            K[i, 1, b] = -(i01 * Hux[0, b] + i11 * Hux[1, b])
        kf[i, 0] = -(i00 * hu0 + i01 * hu1)
        kf[i, 1] = -(i01 * hu0 + i11 * hu1)
        # P ← Q + ĀᵀPĀ + HuxᵀK,  p ← Āᵀ(P d + p) + Huxᵀ k  (column a of Ā: its non-zeros in order)
        for a in range(5):
            ka, kb = Hux[0, a], Hux[1, a]
            for b in range(a, 5):
                acc = ka * K[i, 0, b] + kb * K[i, 1, b]
                if a == 0:
                    acc = acc + PA[0, b] + -ci * PA[1, b]
                elif a == 1:
                    acc = acc + ci * PA[0, b] + PA[1, b]
                elif a == 2:
                    acc = acc + si * PA[1, b] + PA[2, b]
                elif a == 3:
                    acc = acc + -Tc * PA[0, b] + PA[3, b]
                else:
                    acc = acc + -Tc * PA[2, b] + PA[4, b]
                if a == b and a < 3:
                    acc += q[a]
                Pm[a, b] = acc
            acc = ka * kf[i, 0] + kb * kf[i, 1]
            if a == 0:
                acc = acc + Pd[0] + -ci * Pd[1]
            elif a == 1:
                acc = acc + ci * Pd[0] + Pd[1]
            elif a == 2:
                acc = acc + si * Pd[1] + Pd[2]
            elif a == 3:
                acc = acc + -Tc * Pd[0] + Pd[3]
            else:
                acc = acc + -Tc * Pd[2] + Pd[4]
            pv[a] = acc
        for a in range(5):
            for b in range(a):
                Pm[a, b] = Pm[b, a]
    return True


@njit(cache=True, fastmath=False)
def _rollout(x0, up, c, s, r, Tc, q, P, rd, K, kf, U, DU, X):
    """The forward pass of the recursion's law from x0: U, ΔU, X in place; returns the cost
    (including x_0ᵀQx_0 and the terminal x_NᵀPx_N)."""
    N = c.size
    e0, e1, e2 = x0[0], x0[1], x0[2]
    u0, u1 = up[0], up[1]
    X[0, 0], X[0, 1], X[0, 2] = e0, e1, e2
    cost = 0.0
    for i in range(N):
        cost += q[0] * e0 * e0 + q[1] * e1 * e1 + q[2] * e2 * e2
        dv = kf[i, 0] + K[i, 0, 0] * e0 + K[i, 0, 1] * e1 + K[i, 0, 2] * e2 + K[i, 0, 3] * u0 \
            + K[i, 0, 4] * u1
        dw = kf[i, 1] + K[i, 1, 0] * e0 + K[i, 1, 1] * e1 + K[i, 1, 2] * e2 + K[i, 1, 3] * u0 \
            + K[i, 1, 4] * u1
        cost += rd[0] * dv * dv + rd[1] * dw * dw
        u0 += dv
        u1 += dw
        DU[i, 0], DU[i, 1] = dv, dw
        U[i, 0], U[i, 1] = u0, u1
        n0 = e0 + c[i] * e1 - Tc * (u0 - r[i, 0])
        n1 = -c[i] * e0 + e1 + s[i] * e2
        n2 = e2 - Tc * (u1 - r[i, 1])
        e0, e1, e2 = n0, n1, n2
        X[i + 1, 0], X[i + 1, 1], X[i + 1, 2] = e0, e1, e2
    for a in range(3):
        xa = X[N, a]
        for b in range(3):
            cost += xa * P[a, b] * X[N, b]
    return cost


@njit(cache=True, fastmath=False)
def feasible(up, U, DU, X, S, du_max, umin, umax, use_term, tol, term_tol):
    """Every constraint of the hard problem, with the tolerances of ``TSMPC._solve``."""
    N = U.shape[0]
    for i in range(N):
        for j in range(2):
            if DU[i, j] < -du_max[j] - tol or DU[i, j] > du_max[j] + tol:
                return False
            if U[i, j] < umin[j] - tol or U[i, j] > umax[j] + tol:
                return False
    if use_term:
        lvl = 0.0
        for a in range(3):
            for b in range(3):
                lvl += X[N, a] * S[a, b] * X[N, b]
        if not lvl <= 1.0 + term_tol:
            return False
    return True


@njit(cache=True, fastmath=False)
def fast_step(mode, x0, up, v_d, w_d, omega, has_omega, e_th, has_eth, lo, hi, Tc, q, P, rd, S,
              du_max, umin, umax, use_term, n_iter, iter_tol):
    """One MPC step when every scheduling iteration's unconstrained minimiser is feasible.

    Returns (code, U, ΔU, X, cost, n_clipped): code 0 = accepted; 1 = a constraint is active (or a
    pivot failed) and the caller must run the condensed QP path."""
    N = v_d.size
    c = np.empty(N)
    s = np.empty(N)
    r = np.empty((N, 2))
    U = np.empty((N, 2))
    DU = np.empty((N, 2))
    X = np.empty((N + 1, 3))
    om = np.empty(N)
    eth = np.zeros(N)
    if has_omega:
        om[:] = omega
    else:
        om[:] = w_d
    if has_eth:
        eth[:] = e_th
    else:
        eth[0] = x0[2]
    cost = np.nan
    n_clip = 0
    have_sched = has_omega  # ITER's change test needs a previous schedule
    for _ in range(n_iter):
        n_clip = _schedule(mode, x0, up, v_d, w_d, om, eth, lo, hi, Tc, c, s, r)
        cost = riccati(x0, up, c, s, r, Tc, q, P, rd, U, DU, X)
        if not math.isfinite(cost):
            return 1, U, DU, X, cost, n_clip
        if not feasible(up, U, DU, X, S, du_max, umin, umax, use_term, 1e-9, 1e-9):
            return 1, U, DU, X, cost, n_clip
        if mode != ITER:
            break
        change = 0.0
        for i in range(N):
            a = abs(U[i, 1] - om[i])
            b = abs((x0[2] if i == 0 else X[i, 2]) - eth[i])
            change = max(change, a, b)
        converged = have_sched and change < iter_tol
        for i in range(N):
            om[i] = U[i, 1]
            eth[i] = x0[2] if i == 0 else X[i, 2]
        have_sched = True
        if converged:
            break
    return 0, U, DU, X, cost, n_clip


@njit(cache=True, fastmath=False)
def guarded_step(ints, prm, PS, x0, u_raw, v_all, w_all, prev_X, prev_U):
    """:func:`fast_step` with what ``TSMPC.step`` did around it in Python: the inputs' sizes and
    finiteness, u_prev clipped into the input box, the horizon's slices of the reference and the
    previous plan's schedule (e_θ for REF/ITER, ω for ITER). Few arguments (the constants packed
    once by the controller): numba's dispatch checks every argument's type on each call.

    ``ints`` = [mode, N, use_term, n_iter]; ``prm`` = [T_c, iter_tol, lo (3), hi (3), Q (3),
    R (2), Δu_max (2), u_min (2), u_max (2)]; ``PS`` = [P, S] (2, 3, 3); ``prev_X`` (N+1, 3) and
    ``prev_U`` (N, 2), or empty without a previous plan.

    Returns (code, U, ΔU, X, cost, n_clipped, u_prev clipped): code 0 = accepted, 1 = the caller
    runs the condensed QP path, 2 = a non-finite or missing input (the caller falls back)."""
    mode, N, use_term, n_iter = ints[0], ints[1], ints[2] != 0, ints[3]
    up = np.empty(2)
    U = np.empty((0, 2))
    X = np.empty((0, 3))
    if x0.size != 3 or u_raw.size != 2 or v_all.size < N or w_all.size < N:
        return 2, U, U, X, np.nan, 0, up
    total = 0.0  # one finiteness test for all inputs, as the numpy path
    for j in range(2):
        uj = u_raw[j]
        up[j] = prm[15 + j] if uj < prm[15 + j] else (prm[17 + j] if uj > prm[17 + j] else uj)
        total += up[j]
    for j in range(3):
        total += x0[j]
    for i in range(N):
        total += v_all[i] + w_all[i]
    if not math.isfinite(total):
        return 2, U, U, X, np.nan, 0, up
    v_d = v_all[:N]
    w_d = w_all[:N]
    has_prev = prev_X.shape[0] > N and mode != FZN
    eth = np.empty(N)
    om = np.empty(N)
    if has_prev:
        eth[0] = x0[2]
        for i in range(1, N):
            eth[i] = prev_X[i + 1, 2]
    has_om = has_prev and mode == ITER
    if has_om:
        for i in range(N - 1):
            om[i] = prev_U[i + 1, 1]
        om[N - 1] = prev_U[N - 1, 1]
    code, U, DU, X, cost, n_clip = fast_step(
        mode, x0, up, v_d, w_d, om, has_om, eth, has_prev, prm[2:5], prm[5:8], prm[0], prm[8:11],
        PS[0], prm[11:13], PS[1], prm[13:15], prm[15:17], prm[17:19], use_term, n_iter, prm[1])
    return code, U, DU, X, cost, n_clip, up


def warm() -> None:
    """Compile (or load from the cache) the signatures the controller uses."""
    N = 4
    z3, z2, zN = np.zeros(3), np.zeros(2), np.ones(N)
    eye3 = np.eye(3)
    ro = np.ones(N)
    ro.setflags(write=False)  # Reference.window hands out read-only views: another numba type
    for vd in (zN, ro):
        fast_step(1, z3, z2, vd, vd, zN, True, zN, True, -np.ones(3), np.ones(3), 0.1, np.ones(3), eye3,
                  np.ones(2), eye3, np.ones(2), -np.ones(2), np.ones(2), True, 1, 1e-3)
        prm = np.zeros(19)
        prm[0], prm[5:8], prm[15:17], prm[17:19] = 0.1, 1.0, -1.0, 1.0
        for prev in ((np.zeros((0, 3)), np.zeros((0, 2))), (np.zeros((N + 1, 3)), np.zeros((N, 2)))):
            guarded_step(np.array([1, N, 1, 1]), prm, np.stack([eye3, eye3]), z3, z2, vd, vd, *prev)
