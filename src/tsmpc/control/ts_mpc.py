"""Kinematic TS-MPC (paper eq. "MPC"): FZN, REF and ITER scheduling, one dense QP per step.

Problem, for a given scheduling sequence ρ_0 … ρ_{N−1}::

    min_ΔU  Σ_{i=0}^{N−1} x_iᵀ Q x_i + Δu_iᵀ R Δu_i + x_Nᵀ P x_N
    s.t.    x_{i+1} = A_c(ρ_i) x_i + B_c (u_i − r_i),  u_i = u_{i−1} + Δu_i,
            u ∈ Π,  Δu ∈ ΔΠ,  x_Nᵀ S x_N ≤ 1.

Condensing in closed form. ``A_c(ρ)`` is ``[[M, b], [0, 1]]`` with ``M = I + ωT_c J`` — in complex
notation ``p = e_x + i e_y`` the map ``p ↦ M p`` is the multiplication by ``z = 1 − iωT_c``. Products
along the horizon are then cumulative products ``C_n = Π_{l<n} z_l`` and every block of the
prediction matrix is a ratio ``C_n / C_{j+1}`` or a difference of prefix sums: the whole
(3N × 2N) matrix is built with a few vectorised outer operations, no loop over the horizon.

Solving. (1) The unconstrained minimiser (Cholesky) is accepted when it satisfies every
constraint — on closed-loop data the usual case. (2) Otherwise DAQP solves the QP with the input
and rate constraints; the ellipsoid is handled by supporting-hyperplane (tangent) cuts at the
radial projection of the current terminal state, re-solved until ``x_NᵀSx_N ≤ 1 + 1e-9``.
(3) If the cuts do not converge, Clarabel solves the exact SOCP; its answer is re-checked and,
when it leaves the ellipsoid by the interior-point tolerance, re-solved with a slightly tightened
radius (no solver answer is returned unchecked). (4) If the hard problem is
infeasible, the exactly penalised soft problem (slack σ on ``‖S^½ x_N‖ ≤ 1 + σ``, L1 weight
``soft_penalty``) is solved by Clarabel: status SOFT. (5) If everything fails, the shifted
previous plan is returned: status FALLBACK. Nothing raises inside :meth:`TSMPC.step`.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

# (generated from the Fortran module: scipy's stubs do not list them)
from scipy.linalg.lapack import dpotrf as _potrf  # pyright: ignore[reportAttributeAccessIssue]
from scipy.linalg.lapack import dpotrs as _potrs  # pyright: ignore[reportAttributeAccessIssue]

from tsmpc.config import MPCSettings, SchedulingMode
from tsmpc.control.qp import QPStatus, solve_daqp, solve_qcqp_clarabel
from tsmpc.errors import ConfigError
from tsmpc.models.kinematic import KinematicTS, sinc

__all__ = [
    "TSMPC",
    "CondensedQP",
    "MPCResult",
    "MPCStatus",
    "condense",
    "shifted_plan",
]


#: Terminal-ellipsoid tolerance of the cutting-plane loop (relative to the level 1).
TERMINAL_TOL = 1e-9
#: Cuts before switching to the exact SOCP.
MAX_CUTS = 30
#: Radii of the exact SOCP, tried in turn until its answer passes the re-check (1, then tightened).
SOCP_RADII = (1.0, 1.0 - 1e-7, 1.0 - 1e-5)
#: Absolute tolerance on input/rate limits accepted from the soft (interior-point) answer.
SOFT_LIMIT_TOL = 1e-7


class MPCStatus(StrEnum):
    """Outcome of an MPC step."""

    OPTIMAL = "optimal"  #: the hard problem was solved
    SOFT = "soft"  #: the hard problem is infeasible; the exactly penalised soft one was solved
    FALLBACK = "fallback"  #: the solver failed; the shifted previous plan was returned


@dataclass(frozen=True)
class MPCResult:
    """One MPC step.

    Attributes:
        u: first move [v_ref, ω_ref] for the inner loop.
        x_pred: (N+1, 3) predicted errors, x_pred[0] = current errors.
        u_pred: (N, 2) planned inputs; du: (N, 2) their increments.
        cost: optimal cost (paper eq. "MPC", including x_0ᵀQx_0).
        status: OPTIMAL, SOFT or FALLBACK.
        iterations: QPs solved this step (scheduling iterations × cuts).
        qp_iterations: active-set iterations summed over the solves.
        solve_time_s: scheduling + build + solve.
        n_clipped: scheduling values clipped into the box this step.
    """

    u: NDArray[np.float64]
    x_pred: NDArray[np.float64]
    u_pred: NDArray[np.float64]
    du: NDArray[np.float64]
    cost: float
    status: MPCStatus
    iterations: int
    qp_iterations: int
    solve_time_s: float
    n_clipped: int

    @property
    def success(self) -> bool:
        """False only for a fallback step."""
        return self.status != MPCStatus.FALLBACK


@dataclass(frozen=True)
class CondensedQP:
    """``J(ΔU) = ΔUᵀHΔU + 2fᵀΔU + c0`` and the prediction ``X = x_aff + G ΔU``.

    Layout (blocked, so every block is a contiguous outer product): ΔU = [Δv_0…Δv_{N−1},
    Δω_0…Δω_{N−1}], X = [e_x,1…e_x,N, e_y,1…e_y,N, e_θ,1…e_θ,N].
    """

    H: NDArray[np.float64]
    f: NDArray[np.float64]
    c0: float
    G: NDArray[np.float64]
    x_aff: NDArray[np.float64]


def condense(
    x0: NDArray[np.float64], u_prev: NDArray[np.float64], r: NDArray[np.float64],
    c: NDArray[np.float64], s: NDArray[np.float64], Tc: float,
    q: NDArray[np.float64], P: NDArray[np.float64], rdiag: NDArray[np.float64],
) -> CondensedQP:
    """Condensed QP in ΔU for the scheduling ``c_i = ω_i T_c``, ``s_i = v_d,i sinc(e_θ,i) T_c`` and
    the reference inputs r (N, 2); weights diag q on x_1…x_{N−1}, P on x_N, diag R on Δu.

    With ``C_n = Π_{l<n}(1 − i c_l)`` and ``w_j = u_j − r_j``::

        p_n = C_n p_0 + Σ_{j<n} (C_n / C_{j+1}) (i s_j e_θ,j − T_c w_v,j),
        e_θ,n = e_θ,0 − T_c Σ_{l<n} w_ω,l,

    so every entry is a ratio of cumulative products or a difference of prefix sums.
    """
    N = c.size
    C = np.cumprod(1.0 - 1j * c)  # C_n, n = 1…N
    invC = 1.0 / C  # 1 / C_{j+1}
    Sd = np.cumsum(s * invC)  # Sd_n = Σ_{j<n} s_j / C_{j+1}
    Qs = np.cumsum(invC)  # Σ_{j<n} 1 / C_{j+1}
    SS = np.cumsum(Sd)  # Σ_{l<n} Sd_{l+1}
    Q0 = np.concatenate(([0.0], Qs[:-1]))
    SS0 = np.concatenate(([0.0], SS[:-1]))
    lag = _lag(N)  # n − j on and below the diagonal, 0 above
    # Response to ΔU_j (it acts on every w_l, l ≥ j); x_n depends on ΔU_j for j < n only, so
    # the blocks are lower triangular (the formulas are masked by multiplying with tri).
    tri = _tri(N)
    Gv = (-Tc * C)[:, None] * (Qs[:, None] - Q0[None, :])
    Gw = (-1j * Tc * C)[:, None] * (lag * Sd[:, None] - (SS[:, None] - SS0[None, :]))
    G = np.zeros((3 * N, 2 * N))
    np.multiply(Gv.real, tri, out=G[:N, :N])
    np.multiply(Gv.imag, tri, out=G[N:2 * N, :N])
    np.multiply(Gw.real, tri, out=G[:N, N:])
    np.multiply(Gw.imag, tri, out=G[N:2 * N, N:])
    np.multiply(lag, -Tc, out=G[2 * N:, N:])
    # Affine part: ΔU = 0, i.e. u_j = u_prev for all j.
    wv, ww = u_prev[0] - r[:, 0], u_prev[1] - r[:, 1]
    cw = np.cumsum(ww)
    p = C * (x0[0] + 1j * x0[1] + 1j * x0[2] * Sd - Tc * np.cumsum(wv * invC)
             - 1j * Tc * (Sd * cw - np.cumsum(Sd * ww)))
    x_aff = np.concatenate([p.real, p.imag, x0[2] - Tc * cw])
    qbar = np.repeat(q, N)
    # Hessian: the (e_x, e_y) rows by one product of √q-weighted rows; the e_θ rows only touch the
    # Δω block and do not depend on the scheduling (cached).
    sq = np.sqrt(qbar[: 2 * N])[:, None]
    Gs = G[: 2 * N] * sq
    H = Gs.T @ Gs
    H[N:, N:] += _theta_hessian(N, Tc, float(q[2]))
    term = np.array([N - 1, 2 * N - 1, 3 * N - 1])
    GN, xN = G[term], x_aff[term]
    Pd = P.copy()  # the terminal rows carry P instead of Q
    Pd.flat[::4] -= q
    PG = Pd @ GN
    H += GN.T @ PG
    H.flat[:: 2 * N + 1] += np.repeat(rdiag, N)
    f = G.T @ (qbar * x_aff) + PG.T @ xN
    c0 = float(x_aff @ (qbar * x_aff) + xN @ Pd @ xN + x0 @ (q * x0))
    return CondensedQP(H=H, f=f, c0=c0, G=G, x_aff=x_aff)


# Constant matrices of a horizon, built once per N and shared read-only (explicit caches).
@functools.lru_cache(maxsize=32)
def _tri(N: int) -> NDArray[np.float64]:
    """(N, N) lower-triangular ones (cached)."""
    m = np.tri(N)
    m.setflags(write=False)
    return m


@functools.lru_cache(maxsize=32)
def _theta_hessian(N: int, Tc: float, q_theta: float) -> NDArray[np.float64]:
    """q_θ T_c² ΛᵀΛ, the e_θ rows' share of the Δω Hessian block (cached)."""
    lag = _lag(N)
    m = q_theta * Tc * Tc * (lag.T @ lag)
    m.setflags(write=False)
    return m


@functools.lru_cache(maxsize=32)
def _lag(N: int) -> NDArray[np.float64]:
    """(N, N) matrix of n − j for row n−1, column j, j < n (0 elsewhere); cached per N."""
    n = np.arange(1, N + 1)[:, None] - np.arange(N)[None, :]
    m = np.where(n > 0, n, 0).astype(float)
    m.setflags(write=False)
    return m


def shifted_plan(
    prev: MPCResult | None, x0: NDArray[np.float64], up: NDArray[np.float64], N: int, t0: float,
    iterations: int, qp_iterations: int, n_clipped: int,
) -> MPCResult:
    """The fallback of every outer MPC: the previous plan shifted by one step (or u_prev held
    when there is none), status FALLBACK; ``t0`` is the step's start (perf_counter)."""
    if prev is not None:
        U = np.vstack([prev.u_pred[1:], prev.u_pred[-1:]])
        X = np.vstack([prev.x_pred[1:], prev.x_pred[-1:]])
    else:
        U = np.tile(up, (N, 1))
        X = np.tile(np.nan_to_num(x0), (N + 1, 1))
    du = np.diff(np.vstack([up, U]), axis=0)
    return MPCResult(u=U[0].copy(), x_pred=X, u_pred=U, du=du, cost=float("nan"),
                     status=MPCStatus.FALLBACK, iterations=iterations, qp_iterations=qp_iterations,
                     solve_time_s=time.perf_counter() - t0, n_clipped=n_clipped)


class TSMPC:
    """Kinematic TS-MPC with the terminal ingredients (P, S) of the LMI design (paper eq. "MPC").

    Args:
        settings: horizon, weights, bounds, scheduling mode, soft penalty.
        model: kinematic TS model (box, T_c).
        P: terminal cost (3, 3).
        S: terminal set matrix (3, 3), χ = {x : xᵀSx ≤ 1}.
        mode: scheduling mode; defaults to ``settings.mode``.
        jit: use the compiled Riccati fast path (:mod:`tsmpc.kernels.mpc`); None = unless
            ``TSMPC_NO_JIT`` is set. False runs the numpy condensed path only (the tests' oracle).
    """

    def __init__(
        self, settings: MPCSettings, model: KinematicTS, P: NDArray[np.float64], S: NDArray[np.float64],
        mode: SchedulingMode | None = None, jit: bool | None = None,
    ) -> None:
        self.settings = settings
        self.model = model
        self.mode = SchedulingMode(mode or settings.mode)
        if not self.mode.is_ts_mpc:
            raise ConfigError(f"TSMPC: {self.mode} is not a TS-MPC scheduling mode (fzn, ref, iter)")
        self.P = np.asarray(P, dtype=float)
        self.S = np.asarray(S, dtype=float)
        N = self.N = settings.N
        self._q = np.asarray(settings.Q, dtype=float)
        self._r = np.asarray(settings.R, dtype=float)
        self._umin = np.asarray(settings.u_min, dtype=float)
        self._umax = np.asarray(settings.u_max, dtype=float)
        du = np.asarray(settings.du_max, dtype=float)
        # Blocked layout (see CondensedQP): [v_0…v_{N−1}, ω_0…ω_{N−1}].
        self._dlb, self._dub = np.repeat(-du, N), np.repeat(du, N)
        self._dlb2, self._dub2 = -du[:, None], du[:, None]  # the same, broadcast on (2, N)
        self._umin2, self._umax2 = self._umin[:, None], self._umax[:, None]
        self._L = np.kron(np.eye(2), np.tri(N)).astype(np.float64, copy=False)  # U = u_prev + L ΔU
        self._term = np.array([N - 1, 2 * N - 1, 3 * N - 1])
        # Writable copies of the (read-only) box: numba compiles a separate specialisation for
        # read-only arrays, which would otherwise happen inside the first timed step.
        self._lo = np.array(model.premise_box.lower, dtype=float)
        self._hi = np.array(model.premise_box.upper, dtype=float)
        self._kern = None
        if jit is None or jit:
            from tsmpc import kernels

            self._kern = kernels.load("mpc")
        self._mode_id = {SchedulingMode.FZN: 0, SchedulingMode.REF: 1, SchedulingMode.ITER: 2}[self.mode]
        self._du = du
        self._dummy = np.zeros(N)
        # C-ordered copies for the kernel (one compiled signature whatever the caller passed)
        self._Pc, self._Sc = np.ascontiguousarray(self.P), np.ascontiguousarray(self.S)
        # The constants of kernels.mpc.guarded_step, packed once (see its docstring)
        n_iter = settings.iter_max if self.mode == SchedulingMode.ITER else 1
        self._ints = np.array([self._mode_id, N, int(settings.terminal_constraint), n_iter], dtype=np.int64)
        self._prm = np.concatenate([[model.Tc, settings.iter_tol], self._lo, self._hi, self._q, self._r,
                                    du, self._umin, self._umax]).astype(float)
        self._PS = np.ascontiguousarray(np.stack([self._Pc, self._Sc]))
        self._no_X, self._no_U = np.zeros((0, 3)), np.zeros((0, 2))
        self.reset()

    @property
    def dt(self) -> float:
        """Sample time T_c [s] (the runtime protocol's name)."""
        return self.model.Tc

    def reset(self) -> None:
        """Forget the previous plan (start-up)."""
        self._prev: MPCResult | None = None

    # -- scheduling -----------------------------------------------------------------------
    def _schedule(
        self, errors: NDArray[np.float64], u_prev: NDArray[np.float64], v_d: NDArray[np.float64],
        w_d: NDArray[np.float64], omega: NDArray[np.float64] | None, e_th: NDArray[np.float64] | None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], int]:
        """(c, s, r, n_clipped) for premises (ω_i, v_d,i, e_θ,i) along the horizon."""
        N = self.N
        Tc = self.model.Tc
        r = np.empty((N, 2))
        if self.mode == SchedulingMode.FZN:
            # One premise point for the whole horizon: scalars, broadcast at the end.
            e = float(errors[2])
            z0 = (float(u_prev[1]), float(v_d[0]), math.sin(e) / e if e != 0.0 else 1.0)
            zc = [min(max(a, lo), hi) for a, lo, hi in zip(z0, self._lo, self._hi, strict=True)]
            r[:, 0], r[:, 1] = v_d * math.cos(e), w_d
            return (np.full(N, zc[0] * Tc), np.full(N, zc[1] * zc[2] * Tc), r,
                    N if zc != list(z0) else 0)
        else:
            vd = v_d
            om = w_d if omega is None else omega
            if e_th is None:
                eth = np.zeros(N)
                eth[0] = errors[2]
            else:
                eth = e_th
        z = np.empty((N, 3))
        z[:, 0], z[:, 1], z[:, 2] = om, vd, sinc(eth)
        n_clip = 0
        if (z < self._lo).any() or (z > self._hi).any():  # rare: count, then clip
            zclip = np.clip(z, self._lo, self._hi)
            n_clip = int(np.count_nonzero(np.any(zclip != z, axis=-1)))
            z = zclip
        c = z[:, 0] * Tc
        s = z[:, 1] * z[:, 2] * Tc
        r[:, 0], r[:, 1] = v_d * np.cos(eth), w_d
        return c, s, r, n_clip

    # -- one QP ---------------------------------------------------------------------------
    def _solve(
        self, qp: CondensedQP, u_prev: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64] | None, MPCStatus, int, int]:
        """(ΔU, status, QPs solved, active-set iterations); ΔU None on failure."""
        N, S = self.N, self.S
        GN, cN = qp.G[self._term], qp.x_aff[self._term]
        use_term = self.settings.terminal_constraint

        def feasible(z: NDArray[np.float64], tol: float = 1e-9) -> bool:
            if not self._within_limits(z, u_prev, tol):
                return False
            xN = cN + GN @ z
            return not use_term or float(xN @ S @ xN) <= 1.0 + TERMINAL_TOL

        # (1) Unconstrained minimiser. H is symmetric: its transpose is the Fortran-ordered array
        # LAPACK wants, so no copy is made for the call.
        c_fac, info = _potrf(qp.H.T, lower=True, clean=False, overwrite_a=False)
        if info == 0:
            z, info = _potrs(c_fac, -qp.f, lower=True)
            if info == 0 and feasible(z):
                return z, MPCStatus.OPTIMAL, 0, 0
        bl, bu = np.repeat(self._umin - u_prev, N), np.repeat(self._umax - u_prev, N)
        # (2) DAQP with tangent cuts.
        A, lo, hi = self._L, bl, bu
        n_qp = n_it = 0
        sense = None
        for _ in range(MAX_CUTS + 1):
            res = solve_daqp(qp.H, qp.f, self._dlb, self._dub, A, lo, hi, sense)
            n_qp += 1
            n_it += res.iterations
            if res.status == QPStatus.INFEASIBLE:
                break
            if res.status != QPStatus.OPTIMAL:
                break
            z = res.z
            xN = cN + GN @ z
            lvl = float(xN @ S @ xN)
            if not use_term or lvl <= 1.0 + TERMINAL_TOL:
                return z, MPCStatus.OPTIMAL, n_qp, n_it
            # Supporting hyperplane of the ellipsoid at the radial projection x̂ of x_N.
            a = (S @ xN) / np.sqrt(lvl)
            A = np.vstack([A, a @ GN]).astype(np.float64, copy=False)
            lo = np.append(lo, -1e30)
            hi = np.append(hi, 1.0 - a @ cN)
            sense = np.append(res.active, 0).astype(np.int32) if res.active is not None else None
        # (3)/(4) Exact SOCP; soft version when the hard one is infeasible. An interior-point answer
        # meets the cone only to the solver's tolerance (level 1 + a few 1e-9 on current Clarabel):
        # every answer is re-checked, and when it is outside the ellipsoid the SOCP is re-solved
        # with the radius tightened by a margin larger than that tolerance (the cost changes by
        # O(margin · multiplier), far below any tracking effect).
        if not use_term:
            return None, MPCStatus.FALLBACK, n_qp, n_it
        H2, f2 = 2.0 * qp.H, 2.0 * qp.f  # Clarabel minimises ½zᵀPz + qᵀz; J = zᵀHz + 2fᵀz
        for radius in SOCP_RADII:
            res = solve_qcqp_clarabel(H2, f2, self._dlb, self._dub, self._L, bl, bu, S, cN, GN,
                                      radius=radius)
            n_qp += 1
            n_it += res.iterations
            if res.status != QPStatus.OPTIMAL:
                break
            if feasible(res.z):
                return res.z, MPCStatus.OPTIMAL, n_qp, n_it
        res = solve_qcqp_clarabel(H2, f2, self._dlb, self._dub, self._L, bl, bu, S, cN, GN,
                                  soft_penalty=self.settings.soft_penalty)
        n_qp += 1
        n_it += res.iterations
        # The soft answer relaxes only the ellipsoid: its input and rate limits are re-checked.
        if res.status == QPStatus.OPTIMAL and self._within_limits(res.z, u_prev, SOFT_LIMIT_TOL):
            return res.z, MPCStatus.SOFT, n_qp, n_it
        return None, MPCStatus.FALLBACK, n_qp, n_it

    def _within_limits(self, z: NDArray[np.float64], u_prev: NDArray[np.float64], tol: float) -> bool:
        """Input and rate limits of ΔU (the terminal set excluded), with an absolute tolerance."""
        dz = z.reshape(2, self.N)
        if (dz < self._dlb2 - tol).any() or (dz > self._dub2 + tol).any():
            return False
        U = np.cumsum(dz, axis=1) + u_prev[:, None]
        return not ((U < self._umin2 - tol).any() or (U > self._umax2 + tol).any())

    # -- online step ----------------------------------------------------------------------
    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One receding-horizon step.

        Args:
            errors: current [e_x, e_y, e_θ] (vehicle frame).
            u_prev: input applied at the previous step [v, ω] (u_{k−1}).
            reference: object with arrays ``.v`` and ``.omega`` of at least N samples
                (v_d, ω_d at k … k+N−1), e.g. ``Reference.window(k, N + 1)``.
        """
        t0 = time.perf_counter()
        N = self.N
        x0 = np.asarray(errors, dtype=float).reshape(3)
        if self._kern is not None:
            # Fast path: the checks, the schedule and the Riccati recursion in one compiled call;
            # accepted when its answer satisfies every constraint, else the condensed QP path below.
            prev = self._prev
            u_raw = np.asarray(u_prev, dtype=float).reshape(2)
            code, U, du, X, cost, n_clip, up = self._kern.guarded_step(
                self._ints, self._prm, self._PS, x0, u_raw, np.asarray(reference.v, dtype=float),
                np.asarray(reference.omega, dtype=float), self._no_X if prev is None else prev.x_pred,
                self._no_U if prev is None else prev.u_pred)
            if code == 0:
                res = MPCResult(u=U[0].copy(), x_pred=X, u_pred=U, du=du, cost=cost,
                                status=MPCStatus.OPTIMAL, iterations=0, qp_iterations=0,
                                solve_time_s=time.perf_counter() - t0, n_clipped=n_clip)
                self._prev = res
                return res
            if code == 2:
                return self._fallback(x0, up, t0, 0, 0, 0)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        v_d = np.asarray(reference.v, dtype=float)[:N]
        w_d = np.asarray(reference.omega, dtype=float)[:N]
        # One finiteness test for all inputs: a NaN or inf anywhere makes the sum non-finite.
        if not (v_d.size == N and w_d.size == N
                and np.isfinite(x0.sum() + up.sum() + v_d.sum() + w_d.sum())):
            return self._fallback(x0, up, t0, 0, 0, 0)

        omega = e_th = None
        prev = self._prev
        if prev is not None and self.mode != SchedulingMode.FZN:
            e_th = np.empty(N)
            e_th[0] = x0[2]
            e_th[1:] = prev.x_pred[2:N + 1, 2]
            if self.mode == SchedulingMode.ITER:
                omega = np.empty(N)
                omega[:-1] = prev.u_pred[1:, 1]
                omega[-1] = prev.u_pred[-1, 1]
        n_iter = self.settings.iter_max if self.mode == SchedulingMode.ITER else 1
        n_qp = n_it = n_clip = 0
        z = None
        for _ in range(n_iter):
            c, s, r, n_clip = self._schedule(x0, up, v_d, w_d, omega, e_th)
            qp = condense(x0, up, r, c, s, self.model.Tc, self._q, self.P, self._r)
            z, status, a, b = self._solve(qp, up)
            n_qp += a
            n_it += b
            if z is None:
                return self._fallback(x0, up, t0, n_qp, n_it, n_clip)
            if self.mode != SchedulingMode.ITER:
                break
            U = up + (self._L @ z).reshape(2, N).T
            X = (qp.x_aff + qp.G @ z).reshape(3, N).T
            new_om = U[:, 1]
            new_eth = np.concatenate([[x0[2]], X[:-1, 2]])
            change = 0.0 if omega is None else float(max(np.max(np.abs(new_om - omega)),
                                                           np.max(np.abs(new_eth - e_th))))
            converged = omega is not None and change < self.settings.iter_tol
            omega, e_th = new_om, new_eth
            if converged:
                break

        # (ignores: the loop runs at least once, and z is not None after it; this method's syntax
        # tree is fingerprinted for the run engine, tsmpc.sim.engine._PORTED, so no assert here)
        du = z.reshape(2, N).T  # type: ignore[union-attr]
        U = up + np.cumsum(du, axis=0)
        X = np.empty((N + 1, 3))
        X[0] = x0
        X[1:] = (qp.x_aff + qp.G @ z).reshape(3, N).T  # type: ignore[operator]
        cost = float(z @ qp.H @ z + 2.0 * qp.f @ z + qp.c0)  # type: ignore[operator]
        res = MPCResult(u=U[0].copy(), x_pred=X, u_pred=U, du=du, cost=cost, status=status,  # pyright: ignore[reportPossiblyUnboundVariable]
                        iterations=n_qp, qp_iterations=n_it,
                        solve_time_s=time.perf_counter() - t0, n_clipped=n_clip)
        self._prev = res
        return res

    def _fallback(
        self, x0: NDArray[np.float64], up: NDArray[np.float64], t0: float, n_qp: int, n_it: int,
        n_clip: int,
    ) -> MPCResult:
        """The previous plan shifted by one step (or hold u_prev when there is none)."""
        res = shifted_plan(self._prev, x0, up, self.N, t0, n_qp, n_it, n_clip)
        self._prev = res
        return res
