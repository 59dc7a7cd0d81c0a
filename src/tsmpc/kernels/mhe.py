"""MHE-UIO window solve in O(N): block-tridiagonal elimination bordered by the window-constant
friction force (paper eq. "MHE"; :mod:`tsmpc.estimation.mhe_uio`).

In the state variables ``x_0 … x_n`` and F (``w_k = x_{k+1} − A_k x_k − B_k u_k − E_k F``) the
window cost ::

    ‖x_0 − x̄_0‖²_P + p_F (F − F̄)² + Σ_k ‖x_{k+1} − A_k x_k − b_k − e_k F‖²_Q + Σ_k ρ_k ‖y_k − C x_k‖²_R

has a block-tridiagonal Hessian T in x (3×3 blocks ``D_k``, ``O_k = −A_kᵀQ``) with one dense
border column h (F couples to every x_k). Block Cholesky of T for the two right-hand sides
(g, h), then the Schur complement on F::

    F = (g_F − hᵀT⁻¹g) / (h_FF − hᵀT⁻¹h),   x = T⁻¹g − (T⁻¹h) F.

The denominator is ≥ p_F > 0, so the system is never singular while T's pivots are positive
(checked: a non-positive pivot hands the step to the dense path). The model matrices along the
window are evaluated here as well (Euler; the caller provides them for ZOH); nothing is inverted
but the 3×3 Cholesky pivots.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from tsmpc import kernels
from tsmpc.estimation import mhe_margin
from tsmpc.estimation.mhe_margin import MP_MARGIN, MS_MARGIN, N_MARGIN_MP

#: The yaw-model margin's update (estimation/mhe_margin.py), compiled into the callers below
margin_residual = register_jitable(mhe_margin.margin_residual)
margin_apply = register_jitable(mhe_margin.margin_apply)
margin_update = register_jitable(mhe_margin.margin_update)

__all__ = ["MHE_DENSE", "MHE_FAILED", "MHE_OK", "MHE_REJECTED", "MHE_WARMUP", "mhe_push", "mhe_solve",
           "mhe_solved", "mhe_step", "warm", "window_step"]


def _forget_stale_entries() -> None:
    """numba keys this module's cache entries by this file only, but the margin's arithmetic is
    estimation/mhe_margin.py's, compiled in: entries of another version of it are deleted (a stamp
    of its hash beside them; tsmpc.kernels.forget_stale)."""
    try:
        kernels.forget_stale(kernels._tree_folder(kernels.numba_cache_dir()), "mhe", (), "mhe.blocks-sha256",
                             ("tsmpc.estimation.mhe_margin",))
    except OSError:  # an unwritable cache: numba refuses it too (kernels.cache_problem)
        pass


_forget_stale_entries()  # before the first call below loads an entry

# ---------------------------------------------------------------------------- the estimator's records
# mp = [q(3), r(2), p(3), p_F, x_min(3), x_max(3), box lo(3), box hi(3), M, I, C_f, C_r, a, b, μ_o g,
#       drag, T_d]: the window's parameters (C_f, C_r change with the stiffness fit)
MP_Q, MP_R, MP_P, MP_PF, MP_XMIN, MP_XMAX, MP_LO, MP_HI = 0, 3, 5, 8, 9, 12, 15, 18
MP_M, MP_I, MP_CF, MP_CR, MP_A, MP_B, MP_MUG, MP_KD, MP_TD = range(21, 30)
# then the yaw-model margin's (tsmpc.estimation.mhe_margin: MP_MARGIN …)
N_MP = MP_MARGIN + N_MARGIN_MP
assert MP_MARGIN == MP_TD + 1
# ms = [x̂ (3), F̂, the arrival prior x̄_0 (3), the margin's smoothed ratio]: the estimator's float state
MS_X, MS_F, MS_ARR = 0, 3, 4
N_MS = 8
assert MS_MARGIN == MS_ARR + 3

# mi = [samples in the window, samples rejected, solver failures]: its integer state
MI_NY, MI_NREJ, MI_NFAIL = 0, 1, 2
N_MI = 3
# what a step decided: the estimate's status (EstimatorStatus as a code), or the dense QP decides
MHE_DENSE, MHE_OK, MHE_REJECTED, MHE_FAILED, MHE_WARMUP = 0, 1, 2, 3, 4


@njit(cache=True, fastmath=False)
def euler_matrices(U, XS, n, lo, hi, M, I, Cf, Cr, a, b, mug, kd, Td, A, B):
    """A_d (n, 3, 3), B_d (n, 3, 2) at ϑ_k = (δ_k, v̂_k, α̂_k) clipped into the box (as
    ``DynamicTS.matrices`` with Euler; per-axle stiffness C_f, C_r, the paper's C_f = C_r = C)."""
    for k in range(n):
        d = min(max(U[k, 1], lo[0]), hi[0])
        v = min(max(XS[k, 0], lo[1]), hi[1])
        sd, cd = math.sin(d), math.cos(d)
        A[k, 0, 0] = 1.0 + Td * (-mug / v - kd * v / M)
        A[k, 0, 1] = Td * (Cf * sd / M)
        A[k, 0, 2] = Td * (Cf * a * sd / (M * v))
        A[k, 1, 0] = 0.0
        A[k, 1, 1] = 1.0 + Td * (-(Cr + Cf * cd) / (M * v))
        A[k, 1, 2] = Td * ((Cr * b - Cf * a * cd) / (M * v**2) - 1.0)
        A[k, 2, 0] = 0.0
        A[k, 2, 1] = Td * ((Cr * b - Cf * a * cd) / I)
        A[k, 2, 2] = 1.0 + Td * (-(Cf * a**2 * cd + Cr * b**2) / (I * v))
        B[k, 0, 0] = Td * (1.0 / M)
        B[k, 0, 1] = Td * (-Cf * sd / M)
        B[k, 1, 0] = 0.0
        B[k, 1, 1] = Td * (Cf * cd / (M * v))
        B[k, 2, 0] = 0.0
        B[k, 2, 1] = Td * (Cf * a * cd / I)


@njit(cache=True, fastmath=False)
def _chol3(D, L):
    """Lower Cholesky factor of the symmetric 3×3 D into L; False if a pivot is not positive."""
    l00 = D[0, 0]
    if not l00 > 0.0:
        return False
    l00 = math.sqrt(l00)
    l10 = D[1, 0] / l00
    l20 = D[2, 0] / l00
    t = D[1, 1] - l10 * l10
    if not t > 0.0:
        return False
    l11 = math.sqrt(t)
    l21 = (D[2, 1] - l20 * l10) / l11
    t = D[2, 2] - l20 * l20 - l21 * l21
    if not t > 0.0:
        return False
    L[0, 0], L[1, 0], L[2, 0] = l00, l10, l20
    L[0, 1], L[1, 1], L[2, 1] = 0.0, l11, l21
    L[0, 2], L[1, 2], L[2, 2] = 0.0, 0.0, math.sqrt(t)
    return True


@njit(cache=True, fastmath=False)
def banded_solve(Y, W, U, A, B, n, arrival, F_prior, q, r, p, pF, X):
    """Unconstrained window minimiser: states X (n+1, 3) in place; returns F (NaN on a
    non-positive pivot)."""
    m = n + 1
    L = np.empty((m, 3, 3))
    Yk = np.empty((m, 3, 3))  # L_k⁻¹ O_k
    V = np.empty((m, 3, 2))  # L_k⁻¹ ĝ_k for the two right-hand sides (g, h)
    ok, hFF, gF = _eliminate(Y, W, U, A, B, n, arrival, F_prior, q, r, p, pF, L, Yk, V)
    if not ok:
        return np.nan
    return _substitute(A, B, n, q, L, Yk, V, hFF, gF, X)


@njit(cache=True, fastmath=False)
def _eliminate(Y, W, U, A, B, n, arrival, F_prior, q, r, p, pF, L, Yk, V):
    """banded_solve's forward block elimination over x_0 … x_n: the Cholesky factors L, Y_k and the
    reduced right-hand sides V in place; returns (all pivots positive, H_FF, g_F) of the border."""
    m = n + 1
    D = np.empty((3, 3))
    G = np.empty((3, 2))  # right-hand sides of block k
    hFF = pF
    gF = pF * F_prior
    for k in range(m):
        # Diagonal block and right-hand sides of x_k.
        for i in range(3):
            for j in range(3):
                D[i, j] = 0.0
            G[i, 0] = 0.0
            G[i, 1] = 0.0
        if k == 0:
            for i in range(3):
                D[i, i] += p[i]
                G[i, 0] += p[i] * arrival[i]
        wk = W[k]
        D[0, 0] += wk * r[0]
        D[2, 2] += wk * r[1]
        G[0, 0] += wk * r[0] * Y[k, 0]
        G[2, 0] += wk * r[1] * Y[k, 1]
        if k > 0:  # stage k−1: Q (x_k − A x_{k−1} − b − e F)
            kk = k - 1
            for i in range(3):
                D[i, i] += q[i]
                bi = B[kk, i, 0] * U[kk, 0] + B[kk, i, 1] * U[kk, 1]
                G[i, 0] += q[i] * bi
                G[i, 1] += q[i] * B[kk, i, 0]  # −Q e_{k−1}, e = −B[:, 0]
        if k < n:  # stage k: −Aᵀ Q (x_{k+1} − A x_k − b − e F)
            for i in range(3):
                for j in range(3):
                    acc = 0.0
                    for l in range(3):
                        acc += A[k, l, i] * q[l] * A[k, l, j]
                    D[i, j] += acc
                acc_b = 0.0
                acc_e = 0.0
                for l in range(3):
                    bl = B[k, l, 0] * U[k, 0] + B[k, l, 1] * U[k, 1]
                    acc_b += A[k, l, i] * q[l] * bl
                    acc_e += A[k, l, i] * q[l] * (-B[k, l, 0])
                G[i, 0] -= acc_b
                G[i, 1] += acc_e
            for l in range(3):
                e = -B[k, l, 0]
                bl = B[k, l, 0] * U[k, 0] + B[k, l, 1] * U[k, 1]
                hFF += e * q[l] * e
                gF -= e * q[l] * bl
        # Elimination of the previous block: D̃_k = D_k − Y_{k−1}ᵀY_{k−1}, ĝ_k = g_k − Y_{k−1}ᵀV_{k−1}.
        if k > 0:
            for i in range(3):
                for j in range(3):
                    acc = 0.0
                    for l in range(3):
                        acc += Yk[k - 1, l, i] * Yk[k - 1, l, j]
                    D[i, j] -= acc
                for c in range(2):
                    acc = 0.0
                    for l in range(3):
                        acc += Yk[k - 1, l, i] * V[k - 1, l, c]
                    G[i, c] -= acc
        if not _chol3(D, L[k]):
            return False, hFF, gF
        Lk = L[k]
        # V_k = L_k⁻¹ G (forward substitution), Y_k = L_k⁻¹ O_k with O_k = −A_kᵀ Q.
        for c in range(2):
            v0 = G[0, c] / Lk[0, 0]
            v1 = (G[1, c] - Lk[1, 0] * v0) / Lk[1, 1]
            v2 = (G[2, c] - Lk[2, 0] * v0 - Lk[2, 1] * v1) / Lk[2, 2]
            V[k, 0, c], V[k, 1, c], V[k, 2, c] = v0, v1, v2
        if k < n:
            for j in range(3):
                o0 = -A[k, j, 0] * q[j]
                o1 = -A[k, j, 1] * q[j]
                o2 = -A[k, j, 2] * q[j]
                # column j of O_k is (−A_kᵀQ)[:, j] = −A_k[j, :] q_j
                y0 = o0 / Lk[0, 0]
                y1 = (o1 - Lk[1, 0] * y0) / Lk[1, 1]
                y2 = (o2 - Lk[2, 0] * y0 - Lk[2, 1] * y1) / Lk[2, 2]
                Yk[k, 0, j], Yk[k, 1, j], Yk[k, 2, j] = y0, y1, y2
    return True, hFF, gF


@njit(cache=True, fastmath=False)
def _substitute(A, B, n, q, L, Yk, V, hFF, gF, X):
    """banded_solve's back substitution and the border's Schur complement: X in place; returns F
    (NaN on a non-positive complement)."""
    m = n + 1
    # Back substitution: L_kᵀ x_k = V_k − Y_k x_{k+1}, both right-hand sides.
    Xg = np.empty((m, 3, 2))
    for k in range(n, -1, -1):
        Lk = L[k]
        for c in range(2):
            t0, t1, t2 = V[k, 0, c], V[k, 1, c], V[k, 2, c]
            if k < n:
                for j in range(3):
                    xj = Xg[k + 1, j, c]
                    t0 -= Yk[k, 0, j] * xj
                    t1 -= Yk[k, 1, j] * xj
                    t2 -= Yk[k, 2, j] * xj
            x2 = t2 / Lk[2, 2]
            x1 = (t1 - Lk[2, 1] * x2) / Lk[1, 1]
            x0 = (t0 - Lk[1, 0] * x1 - Lk[2, 0] * x2) / Lk[0, 0]
            Xg[k, 0, c], Xg[k, 1, c], Xg[k, 2, c] = x0, x1, x2
    # Border: the second right-hand side was h (H[x_k, F] = A_kᵀQe_k − Qe_{k−1}), so Xg[:, :, 1] =
    # T⁻¹h; the Schur complement needs hᵀT⁻¹g and hᵀT⁻¹h.
    hg = 0.0
    hh = 0.0
    for k in range(m):
        for i in range(3):
            hk = 0.0
            if k > 0:
                hk += q[i] * B[k - 1, i, 0]
            if k < n:
                for l in range(3):
                    hk += A[k, l, i] * q[l] * (-B[k, l, 0])
            hg += hk * Xg[k, i, 0]
            hh += hk * Xg[k, i, 1]
    den = hFF - hh  # the Schur complement, ≥ p_F in exact arithmetic
    if not den > 0.0:
        return np.nan
    F = (gF - hg) / den
    for k in range(m):
        for i in range(3):
            X[k, i] = Xg[k, i, 0] - Xg[k, i, 1] * F
    return F


@njit(cache=True, fastmath=False)
def window_step(Y, W, U, XS, n, x, F, u, ok, full, arrival, q, r, p, pF, xmin, xmax, lo, hi,
                M, I, Cf, Cr, a, b, mug, kd, Td, eval_model, A, B, X, defer):
    """One MHE step after the window update (everything ``MHEUIO.step`` does from the model
    evaluation on). Writes XS[n−1], XS[n] (prediction) and, on success, the smoothed window.

    Returns (code, F̂, pred_v): 0 = solved, within bounds; 1 = bounds active or a pivot failed
    (the caller runs the dense QP with the matrices in A, B); 2 = warm-up or rejected sample
    (XS[n] holds the prediction); 3 = non-finite prediction (FAILED)."""
    XS[n - 1, 0], XS[n - 1, 1], XS[n - 1, 2] = x[0], x[1], x[2]
    if eval_model:
        if defer:  # the last row only: the batch evaluates the others for all its lanes at once
            euler_matrices(U[n - 1:n], XS[n - 1:n], 1, lo, hi, M, I, Cf, Cr, a, b, mug, kd, Td,
                           A[n - 1:n], B[n - 1:n])
        else:
            euler_matrices(U, XS, n, lo, hi, M, I, Cf, Cr, a, b, mug, kd, Td, A, B)
    k = n - 1
    pred = np.empty(3)
    for i in range(3):
        pred[i] = A[k, i, 0] * x[0] + A[k, i, 1] * x[1] + A[k, i, 2] * x[2] \
            + B[k, i, 0] * u[0] + B[k, i, 1] * u[1]
    for i in range(3):
        XS[n, i] = pred[i] - B[k, i, 0] * F
    if not (math.isfinite(XS[n, 0]) and math.isfinite(XS[n, 1]) and math.isfinite(XS[n, 2])):
        return 3, F, pred[0]
    if ok:
        XS[n, 0], XS[n, 2] = Y[n, 0], Y[n, 1]
    if n < 2 or not ok:
        return 2, F, pred[0]
    if defer:  # the batch solves the window (tsmpc.kernels.batch.mhe_window_lanes)
        return 1, F, pred[0]
    arr = XS[0].copy() if full else arrival
    Fn = banded_solve(Y, W, U, A, B, n, arr, F, q, r, p, pF, X)
    if not math.isfinite(Fn):
        return 1, F, pred[0]
    for k in range(n + 1):
        for i in range(3):
            v = X[k, i]
            if not (v >= xmin[i] - 1e-9 and v <= xmax[i] + 1e-9):  # also catches NaN
                return 1, F, pred[0]
    for k in range(n + 1):
        for i in range(3):
            XS[k, i] = X[k, i]
    return 0, Fn, pred[0]


@njit(cache=True, fastmath=False)
def _npclip(x, lo, hi):
    """``np.clip`` of one float (NaN stays NaN)."""
    if x != x:
        return x
    y = x if x >= lo else lo
    return y if y <= hi else hi


@njit(cache=True, fastmath=False, inline="always")  # (no call layers in the engine)
def mhe_push(y0, y1, u0, u1, Y, W, U, XS, mp, ms, mi):
    """``MHEUIO.step`` up to the model: the sample [v, ω] (non-finite: rejected, weight 0) and the
    input [F_xR, δ] the plant received (non-finite: zero, the sample rejected) into the window
    (full: its oldest sample and input dropped); the first sample starts the estimate.

    Returns (status, n, ok, u0, u1): :data:`MHE_WARMUP` / :data:`MHE_REJECTED` for the first
    sample (the estimate in ``ms``), else :data:`MHE_DENSE` (a window of n inputs to solve,
    :func:`mhe_solve`); the input as the window holds it."""
    N = U.shape[0]
    first = mi[MI_NY] == 0
    ok = math.isfinite(y0) and math.isfinite(y1)
    if not (math.isfinite(u0) and math.isfinite(u1)):  # a caller bug upstream: never in the window
        u0, u1 = 0.0, 0.0
        ok = False
    if not ok:
        mi[MI_NREJ] += 1
    ny = mi[MI_NY]
    if ny == N + 1:  # full: drop the oldest sample and input
        for r in range(N):
            Y[r, 0], Y[r, 1] = Y[r + 1, 0], Y[r + 1, 1]
            W[r] = W[r + 1]
            XS[r, 0], XS[r, 1], XS[r, 2] = XS[r + 1, 0], XS[r + 1, 1], XS[r + 1, 2]
        for r in range(N - 1):
            U[r, 0], U[r, 1] = U[r + 1, 0], U[r + 1, 1]
        ny -= 1
    Y[ny, 0], Y[ny, 1] = (y0, y1) if ok else (0.0, 0.0)
    W[ny] = 1.0 if ok else 0.0
    ny += 1
    if not first:
        U[ny - 2, 0], U[ny - 2, 1] = u0, u1
    mi[MI_NY] = ny
    n = ny - 1
    if not first:
        return MHE_DENSE, n, ok, u0, u1
    for i in range(3):
        XS[0, i] = ms[MS_X + i]
    if not ok:
        return MHE_REJECTED, n, ok, u0, u1
    XS[0, 0], XS[0, 2] = y0, y1
    for i in range(3):
        ms[MS_X + i] = _npclip(XS[0, i], mp[MP_XMIN + i], mp[MP_XMAX + i])
    return MHE_WARMUP, n, ok, u0, u1


@njit(cache=True, fastmath=False, inline="always")  # (no call layers in the engine)
def mhe_solve(y0, ok, n, mass, Y, W, U, XS, A, B, X, mp, ms, mi, uk, eval_model, defer):
    """``MHEUIO.step`` from the model on, for a window of ``n`` ≥ 1 inputs after
    :func:`mhe_push` (``uk`` [F_xR, δ] the last one): :func:`window_step`, then the estimate into
    ``ms``. Returns (status, F̂_raw): :data:`MHE_OK` / :data:`MHE_WARMUP` (solved),
    :data:`MHE_REJECTED` / :data:`MHE_WARMUP` (a rejected sample or a short window: the
    prediction), :data:`MHE_FAILED` (a non-finite prediction: the last estimate kept) or
    :data:`MHE_DENSE` (a state bound active or a pivot failed: the caller's dense QP decides,
    the matrices in A, B). ``eval_model`` False: A, B hold the model at the window's scheduling."""
    N = U.shape[0]
    full = n == N
    x = ms[MS_X:MS_X + 3]
    q, r, p = mp[MP_Q:MP_Q + 3], mp[MP_R:MP_R + 2], mp[MP_P:MP_P + 3]
    xmin, xmax = mp[MP_XMIN:MP_XMIN + 3], mp[MP_XMAX:MP_XMAX + 3]
    lo, hi = mp[MP_LO:MP_LO + 3], mp[MP_HI:MP_HI + 3]
    if full:  # the whole arrays (the usual case): no views to make
        code, F, pred_v = window_step(
            Y, W, U, XS, n, x, ms[MS_F], uk, ok, full, ms[MS_ARR:MS_ARR + 3], q, r, p, mp[MP_PF], xmin,
            xmax, lo, hi, mp[MP_M], mp[MP_I], mp[MP_CF], mp[MP_CR], mp[MP_A], mp[MP_B], mp[MP_MUG],
            mp[MP_KD], mp[MP_TD], eval_model, A, B, X, defer)
    else:
        code, F, pred_v = window_step(
            Y[:n + 1], W[:n + 1], U[:n], XS[:n + 1], n, x, ms[MS_F], uk, ok, full, ms[MS_ARR:MS_ARR + 3],
            q, r, p, mp[MP_PF], xmin, xmax, lo, hi, mp[MP_M], mp[MP_I], mp[MP_CF], mp[MP_CR], mp[MP_A],
            mp[MP_B], mp[MP_MUG], mp[MP_KD], mp[MP_TD], eval_model, A[:n], B[:n], X[:n + 1], defer)
    F_raw = (pred_v - y0) * mass / mp[MP_TD] if ok else 0.0
    if code == 3 or not math.isfinite(F_raw):  # FAILED: the last estimate kept (made finite)
        mi[MI_NFAIL] += 1
        if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2])):
            for i in range(3):  # np.clip(np.nan_to_num(x), x_min, x_max)
                xi = x[i]
                if xi != xi:
                    xi = 0.0
                elif xi == math.inf:
                    xi = 1.7976931348623157e308
                elif xi == -math.inf:
                    xi = -1.7976931348623157e308
                x[i] = _npclip(xi, xmin[i], xmax[i])
        return MHE_FAILED, (F_raw if math.isfinite(F_raw) else 0.0)
    if code == 2:  # warm-up or a rejected sample: the prediction
        for i in range(3):
            x[i] = _npclip(XS[n, i], xmin[i], xmax[i])
        return (MHE_WARMUP if ok else MHE_REJECTED), F_raw
    if code == 1:
        return MHE_DENSE, F_raw
    st = mhe_solved(ms, XS, n, F, full)
    if st == MHE_OK:  # the yaw-model margin (estimation/mhe_margin.py) on the solved window
        margin_update(mp, ms, XS, A, B, U, n)
    return st, F_raw


@njit(cache=True, fastmath=False, inline="always")  # (no call layers in the engine)
def mhe_solved(ms, XS, n, F, full):
    """The estimate of a window solved within the bounds (here, or by the batch's lanes): x̂ its
    last state ``XS[n]``, F̂ its force; the status :data:`MHE_OK` (a full window) or
    :data:`MHE_WARMUP`."""
    for i in range(3):
        ms[MS_X + i] = XS[n, i]
    ms[MS_F] = F
    return MHE_OK if full else MHE_WARMUP


@njit(cache=True, fastmath=False, inline="always")  # (no call layers in the engine)
def mhe_step(y0, y1, u0, u1, mass, Y, W, U, XS, A, B, X, mp, ms, mi, uk, eval_model, defer):
    """One ``MHEUIO.step`` with the model evaluated here (Euler): :func:`mhe_push` then
    :func:`mhe_solve`. Returns (status, F̂_raw, n, ok); ``uk`` gets the input as the window
    holds it."""
    st, n, ok, u0, u1 = mhe_push(y0, y1, u0, u1, Y, W, U, XS, mp, ms, mi)
    uk[0], uk[1] = u0, u1
    if st != MHE_DENSE:
        return st, 0.0, n, ok
    st, F_raw = mhe_solve(y0, ok, n, mass, Y, W, U, XS, A, B, X, mp, ms, mi, uk, eval_model, defer)
    return st, F_raw, n, ok


def warm() -> None:
    """Compile (or load from the cache) the signatures the estimator uses."""
    n = 3
    Y, W, U = np.zeros((n + 1, 2)), np.ones(n + 1), np.zeros((n, 2))
    XS = np.ones((n + 1, 3)) * 5.0
    o3 = np.ones(3)
    window_step(Y, W, U, XS, n, o3 * 5.0, 0.0, np.zeros(2), True, False, o3, o3, np.ones(2), o3, 1e-10,
                -o3 * 100, o3 * 100, -o3, o3 * 20, 683.0, 560.0, 25000.0, 25000.0, 0.7, 1.0, 4.9, 0.4,
                0.01, True, np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n + 1, 3)), False)
    mp = np.concatenate([o3, np.ones(2), o3, [1e-10], -o3 * 100, o3 * 100, -o3, o3 * 20,
                         [683.0, 560.0, 25000.0, 25000.0, 0.7, 1.0, 4.9, 0.4, 0.01], np.zeros(N_MARGIN_MP)])
    ms, mi = np.ones(N_MS) * 5.0, np.zeros(N_MI, dtype=np.int64)
    for _ in range(2):
        mhe_step(5.0, 0.1, 0.0, 0.0, 683.0, Y, W, U, XS, np.zeros((n, 3, 3)), np.zeros((n, 3, 2)),
                 np.zeros((n + 1, 3)), mp, ms, mi, np.zeros(2), True, False)
    _st, n1, ok, _u0, _u1 = mhe_push(5.0, 0.1, 0.0, 0.0, Y, W, U, XS, mp, ms, mi)
    mhe_solve(5.0, ok, n1, 683.0, Y, W, U, XS, np.zeros((n, 3, 3)), np.zeros((n, 3, 2)),
              np.zeros((n + 1, 3)), mp, ms, mi, np.zeros(2), False, False)
