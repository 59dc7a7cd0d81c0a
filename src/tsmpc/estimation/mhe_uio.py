"""TS-MHE-UIO: moving-horizon estimation of [v, α, ω] and of the friction force (paper eqs. "MHE",
"disturb_estimation"; the paper's TS-MHE-UIO).

Measurements ``y = C x = [v, ω]`` (α is not measured). Model along the window: the dynamic model
evaluated directly at each sample's scheduling ϑ_k = (δ_k, v_k, α̂_k) (online, the exact
A_d(ϑ), B_d(ϑ), not the vertex blend), ``x_{k+1} = A_k x_k + B_k u_k + E_k F + w_k``.

Unknown input. The paper's UIO removes F from the state equation with ``Θ = (C E)⁺`` and
recovers it as ``F̂_raw = Θ(y_k − C(A x̂ + B u))`` — with ``Θ = −M/T_d`` that estimate carries the
speed-sensor noise amplified ×68 300 (σ ≈ 340 N for σ_v = 5 mm/s): compensated as is, it puts
that noise on the force command. We return that formula as ``F_fr_raw`` (compensated only by the
``paper`` preset, ``lqr.friction_estimate = "uio"``) and estimate F as a *window-constant
unknown input* inside the MHE: the least-squares fit over the 30 samples of the same decoupled
relation, with the previous window's F as arrival prior (``F_fr``, the default's compensation).
It reaches the controller without further filtering. The paper's own form, with F eliminated
from the window model through E_d, is :mod:`tsmpc.estimation.mhe_paper_uio` (``mhe.form = "uio"``).

Window QP (variables ``z = [x_0, F, w_0 … w_{N−1}]``, 3 + 1 + 3N)::

    min ‖x_0 − x̄_0‖²_P + p_F (F − F̄)² + Σ ‖w_k‖²_Q + Σ ρ_k ‖y_k − C x_k‖²_R
    s.t. x_min ≤ x_k ≤ x_max

with ``x̄_0`` the previous solution's estimate of the window's first sample (arrival cost) and
``ρ_k = 0`` for rejected samples. Solved as a dense QP: the unconstrained minimiser (Cholesky)
when it satisfies the bounds, else DAQP (fresh solve); no cvxpy in the loop.
"""

from __future__ import annotations

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

from tsmpc._records import StateField, quick_init
from tsmpc.config import MHESettings, VehicleParams
from tsmpc.control.qp import QPStatus, solve_daqp
from tsmpc.errors import ConfigError
from tsmpc.estimation.mhe_margin import MP_MARGIN, MS_MARGIN, N_MARGIN_MP, margin_params, margin_update
from tsmpc.models.dynamic import Discretization, DynamicTS

__all__ = ["MHEUIO", "Estimate", "EstimatorStatus", "WindowQP"]

#: The yaw-rate process weight's slot in ``mp`` (tsmpc.kernels.mhe's MP_Q + 2)
MP_QW = 2

#: Weight of the friction-force prior (the previous window's F̂), per N²: a weak tie that keeps
#: F̂ continuous between windows without biasing it (σ_F ≈ 1 / √p_F ≈ 300 N).
F_PRIOR_WEIGHT = 1e-10


class EstimatorStatus(StrEnum):
    """Outcome of an estimator step."""

    OK = "ok"
    REJECTED = "rejected"  #: non-finite measurement: not used, the model prediction is returned
    FAILED = "failed"  #: solver failure: the model prediction is returned
    WARMUP = "warmup"  #: window not full yet (estimate from the samples so far)


@quick_init
@dataclass(frozen=True)
class Estimate:
    """State and friction-force estimate delivered to the controller.

    Attributes:
        x: [v̂, α̂, ω̂].
        F_fr: friction-force estimate that reaches the controller [N].
        F_fr_raw: the paper's one-step UIO formula (P-disturb_estimation), logged only [N].
        status: estimator status of this step.
        solve_time_s: window update + build + solve.
    """

    x: NDArray[np.float64]
    F_fr: float
    F_fr_raw: float
    status: EstimatorStatus
    solve_time_s: float


@dataclass(frozen=True)
class WindowQP:
    """The window's QP ``½zᵀHz + fᵀz`` with bounds ``lo ≤ M z + c ≤ hi`` on the stacked states."""

    H: NDArray[np.float64]
    f: NDArray[np.float64]
    M: NDArray[np.float64]  #: (3(n+1), 4 + 3n): states x_0 … x_n as a map of z
    c: NDArray[np.float64]  #: (3(n+1),)
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]


_EYE3 = np.eye(3)
#: EstimatorStatus of the compiled step's status codes (tsmpc.kernels.mhe.MHE_OK … MHE_WARMUP)
_STATUS = (EstimatorStatus.FAILED, EstimatorStatus.OK, EstimatorStatus.REJECTED, EstimatorStatus.FAILED,
           EstimatorStatus.WARMUP)


#: MHEUIO._kernel_model_agrees's answers in this process, by the model's inputs
_AGREES: dict[tuple[Any, ...], bool] = {}


class MHEUIO:
    """Moving-horizon estimator with an unknown-input (friction force) estimate.

    Args:
        settings: horizon, weights, bounds.
        model: dynamic TS model (its ``matrices`` are evaluated at each sample's scheduling).
        vehicle: vehicle parameters (mass for the UIO gain).
        Td: sample time [s] (must equal ``model.Td``).
        x0: initial state guess [v, α, ω].
        jit: solve the window by the compiled block-tridiagonal kernel (:mod:`tsmpc.kernels.mhe`);
            None = unless ``TSMPC_NO_JIT`` is set. False: the dense QP only (the tests' oracle).
            The dense QP also remains the path whenever a state bound is active.
    """

    def __init__(
        self, settings: MHESettings, model: DynamicTS, vehicle: VehicleParams, Td: float,
        x0: NDArray[np.float64] | None = None, jit: bool | None = None,
    ) -> None:
        if abs(model.Td - Td) > 1e-12:
            raise ConfigError(f"MHEUIO: Td = {Td} differs from the model's Td = {model.Td}")
        self.settings = settings
        self.model = model
        self.vehicle = vehicle
        self.Td = float(Td)
        # Q, R, P are the paper's covariances: the QP weights are their inverses.
        self._q = 1.0 / np.asarray(settings.Q, dtype=float)
        self._r = 1.0 / np.asarray(settings.R, dtype=float)
        self._p = 1.0 / np.asarray(settings.P, dtype=float)
        self._xmin = np.asarray(settings.x_min, dtype=float)
        self._xmax = np.asarray(settings.x_max, dtype=float)
        self._sqrt_r = np.sqrt(self._r)
        self._tiles: dict[tuple[str, int], Any] = {}
        # The estimator's state as the compiled step's records (tsmpc.kernels.mhe: ms = [x̂ (3), F̂,
        # arrival (3)], mi = [samples in the window, rejected, failed]; _x, _F, … are their views).
        self._ms, self._mi = np.zeros(MS_MARGIN + 1), np.zeros(3, dtype=np.int64)
        self._uk = np.zeros(2)  # the input the window holds for this step (the block's scratch)
        self._kern: Any = None  # the compiled block (tsmpc.kernels.load("mhe")), or None
        if jit is None or jit:
            from tsmpc import kernels

            self._kern = kernels.load("mhe")
        if self._kern is not None:
            n = settings.N
            p, box = getattr(model, "params", vehicle), model.premise_box
            try:
                cf = getattr(p, "C_f", p.cornering_stiffness)  # per axle where known
                cr = getattr(p, "C_r", p.cornering_stiffness)
                phys = (float(p.mass), float(p.inertia), float(cf), float(cr), float(p.a),
                        float(p.b), float(p.mu_nominal * p.g), float(p.drag_factor))
                euler = getattr(model, "method", None) == Discretization.EULER
            except (AttributeError, TypeError):
                phys, euler = (1.0,) * 8, False
            self._kargs: tuple[Any, ...] = (
                self._q, self._r, self._p, F_PRIOR_WEIGHT, self._xmin, self._xmax,
                # Writable copies: numba types read-only arrays apart, and the kernels are compiled
                # ahead of time for writable ones (a read-only box would compile inside a timed step).
                np.array(box.lower, dtype=float), np.array(box.upper, dtype=float),
                *phys, self.Td, euler,
            )
            self._Ab, self._Bb, self._Xb = np.zeros((n, 3, 3)), np.zeros((n, 3, 2)), np.zeros((n + 1, 3))
            if self._kargs[-1] and not self._model_agrees_once():
                # The model is not the one the kernel evaluates: numpy evaluates it, the kernel solves.
                self._kargs = (*self._kargs[:-1], False)
            k = self._kargs  # the block's parameters mp (tsmpc.kernels.mhe.MP_*: the same values)
            self._mp = np.array([*k[0], *k[1], *k[2], k[3], *k[4], *k[5], *k[6], *k[7], *k[8:17],
                                 *self._margin_params()],
                                dtype=float)
        else:  # the numpy path's: the yaw-model margin's slots (its own, the model's M … μ_o g)
            self._mp = np.zeros(MP_MARGIN + N_MARGIN_MP)
            self._mp[MP_MARGIN:] = self._margin_params()
            p = getattr(model, "params", vehicle)
            try:  # (the stiffness fit's changes do not reach them here: the test's slips only)
                cf = getattr(p, "C_f", p.cornering_stiffness)
                cr = getattr(p, "C_r", p.cornering_stiffness)
                self._mp[21:28] = [float(p.mass), float(p.inertia), float(cf), float(cr), float(p.a),
                                   float(p.b), float(p.mu_nominal * p.g)]
            except (AttributeError, TypeError):  # a model without them: no linear-tyre test
                self._mp[MP_MARGIN + 5] = 0.0
        self.reset(x0)

    def _margin_params(self) -> list[float]:
        """The yaw-model margin's entries of ``mp`` (tsmpc.estimation.mhe_margin)."""
        s = self.settings
        return margin_params(float(s.margin_slip_rate), float(s.margin_max), float(s.margin_rise_s),
                             float(s.margin_decay_s), float(s.Q[2]), self.Td, float(s.margin_linear_share))

    def _model_agrees_once(self) -> bool:
        """:meth:`_kernel_model_agrees`, answered once per model in a process (a batch builds one
        estimator per run)."""
        m = self.model
        try:
            key = (type(m), repr(m.box), repr(m.params), float(m.Td), str(m.method), self._kargs[8:17])
        except AttributeError:
            return self._kernel_model_agrees()
        agrees = _AGREES.get(key)
        if agrees is None:
            agrees = _AGREES[key] = self._kernel_model_agrees()
        return agrees

    def _kernel_model_agrees(self) -> bool:
        """The kernel's Euler matrices equal ``model.matrices`` at a few premise points (guards
        against a model edited on one side only)."""
        try:
            lo, hi = (np.array(b, dtype=float) for b in (self.model.premise_box.lower,
                                                             self.model.premise_box.upper))
            z = lo + (hi - lo) * np.array([[0.1, 0.2, 0.3], [0.9, 0.5, 0.7], [0.5, -0.2, 1.3]])
            A, B = self.model.matrices(z)
            U = np.column_stack([np.zeros(3), z[:, 0]])
            Ak, Bk = np.empty((3, 3, 3)), np.empty((3, 3, 2))
            k = self._kargs
            self._kern.euler_matrices(U, z[:, [1, 2, 0]], 3, k[6], k[7], *k[8:17], Ak, Bk)
            return bool(np.allclose(Ak, A, rtol=1e-12, atol=1e-14)
                        and np.allclose(Bk, B, rtol=1e-12, atol=1e-14))
        except Exception:  # any mismatch of shapes or attributes: do not trust the kernel's model
            return False

    @property
    def dt(self) -> float:
        """Sample time T_d [s] (the runtime protocol's name)."""
        return self.Td

    def set_cornering_stiffness(self, C_f: float, C_r: float, inertia: float | None = None,
                                a: float | None = None, b: float | None = None) -> None:
        """Use axle stiffnesses C_f, C_r [N/rad] (and, given, the yaw inertia I_z [kg m²] and the
        CoG's distances a, b [m]) in the window model from the next step on (an online estimate,
        ``fusion.stiffness_estimate``): the numpy model and the kernel's parameters alike; the
        window and the estimate are kept."""
        self.model_stiffness(C_f, C_r, inertia, a, b)
        if self._kern is not None:  # the kernel's parameters (the cascade's stiffness block writes them)
            # (imported here: the block module brings numba, which the estimator alone does not need)
            from tsmpc.control.stiffness_block import MP_A, MP_B, MP_CF, MP_CR, MP_I, give_model

            v = self.vehicle
            give_model(self._mp, MP_I, MP_CF, MP_CR, MP_A, MP_B, float(C_f), float(C_r), float(v.inertia),
                       float(v.a), float(v.b))

    def model_stiffness(self, C_f: float, C_r: float, inertia: float | None = None, a: float | None = None,
                        b: float | None = None) -> None:
        """The lateral model of the Python side (the vehicle, the numpy model, the kernel's argument
        tuple): C_f, C_r and, given, I_z, a, b; the kernel's parameters ``_mp`` left as they are:
        the cascade's stiffness block (control/stiffness_block.py) writes those."""
        veh = self.vehicle.with_lateral_model(C_f, C_r, inertia, a, b)
        m = self.model
        self.model = DynamicTS(m.box, veh, m.Td, m.method)
        self.vehicle = veh
        if self._kern is not None:
            k = list(self._kargs)
            # phys = (M, I, C_f, C_r, a, b, μ_o g, d) from 8
            k[9], k[10], k[11], k[12], k[13] = veh.inertia, veh.C_f, veh.C_r, veh.a, veh.b
            self._kargs = tuple(k)

    def reset(self, x0: NDArray[np.float64] | None = None) -> None:
        """Empty the window; start from ``x0`` (or rest) with F̂ = 0."""
        self._x = np.zeros(3) if x0 is None else np.asarray(x0, dtype=float).copy()
        self._F = 0.0
        n = self.settings.N
        # Window as fixed arrays (oldest first), shifted in place: no per-step list conversions.
        self._Y = np.zeros((n + 1, 2))  # measurements
        self._W = np.zeros(n + 1)  # 1 = measurement used, 0 = rejected
        self._U = np.zeros((n, 2))  # inputs between samples
        self._XS = np.zeros((n + 1, 3))  # estimates at the samples (scheduling, arrival)
        self._ny = 0  # samples in the window
        self._arrival = self._x.copy()
        self._n_rejected = 0
        self._n_failed = 0
        self._ms[MS_MARGIN] = 0.0  # the yaw-model margin: none, the configured Q_ω
        self._mp[MP_QW] = self._mp[MP_MARGIN + 4]

    # the state, views of the block's records (_ms, _mi; kernels.mhe's MS_* and MI_* slots)
    _x: StateField = StateField("_ms", slice(0, 3))
    _F: StateField = StateField("_ms", 3, float)
    _arrival: StateField = StateField("_ms", slice(4, 7))
    _ny: StateField = StateField("_mi", 0, int)
    _n_rejected: StateField = StateField("_mi", 1, int)
    _n_failed: StateField = StateField("_mi", 2, int)

    @property
    def n_rejected(self) -> int:
        """Measurements rejected (non-finite) since the last reset."""
        return self._n_rejected

    @property
    def n_failed(self) -> int:
        """Solver failures since the last reset."""
        return self._n_failed

    # -- model along the window ------------------------------------------------------------
    def build(self, ys: NDArray[np.float64], us: NDArray[np.float64], weights: NDArray[np.float64],
              xs: NDArray[np.float64], arrival: NDArray[np.float64], F_prior: float,
              matrices: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None) -> WindowQP:
        """Window QP for measurements ys (n+1, 2), inputs us (n, 2), sample weights (n+1,),
        scheduling states xs (n+1, 3) (previous estimates; v replaced by the measurement).
        ``matrices`` = the model's (A (n, 3, 3), B (n, 3, 2)) at that scheduling, if already known."""
        n = us.shape[0]
        nz = 4 + 3 * n
        if matrices is None:
            # Scheduling ϑ_k = (δ_k, v_k, α̂_k), all samples at once (vectorised model evaluation).
            matrices = self.model.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
        A, B = matrices  # (n, 3, 3), (n, 3, 2)
        Bu = (B @ us[:, :, None])[:, :, 0]
        # States as a map of z by forward recursion, x_{k+1} = A_k x_k + B_k u_k + E_k F + w_k: row
        # block k+1 = A_k · row block k, plus E_k in the F column and I in the w_k columns. No
        # product is inverted (at low speed or with stiff tyres the A_k contract strongly and
        # A_{k−1}⋯A_0 is numerically singular, see issue 14 item 6).
        M = np.zeros((3 * (n + 1), nz))
        M3 = M.reshape(n + 1, 3, nz)
        M3[0, :, :3] = _EYE3
        c3 = np.zeros((n + 1, 3))
        for k in range(n):
            w = 4 + 3 * k  # columns used so far: x_0, F, w_0 … w_{k−1}
            np.matmul(A[k], M3[k, :, :w], out=M3[k + 1, :, :w])
            M3[k + 1, :, 3] -= B[k, :, 0]  # the unknown input F enters as E_d = −B_d[:, :1]
            M3[k + 1, :, w:w + 3] = _EYE3
            c3[k + 1] = A[k] @ c3[k] + Bu[k]
        c = c3.reshape(-1)
        # Measurement rows: v and ω (state rows 0 and 2) of every sample, weighted.
        sw = np.sqrt(weights)[:, None] * self._sqrt_r  # (n+1, 2)
        Cm2 = (M3[:, 0::2, :] * sw[:, :, None]).reshape(-1, nz)
        res = (ys - c3[:, 0::2]) * sw
        H = Cm2.T @ Cm2
        f = Cm2.T @ res.reshape(-1)
        f *= -1.0
        diag = H.reshape(-1)[:: nz + 1]  # a view: the regularising terms add to the diagonal
        diag[:3] += self._p
        diag[3] += F_PRIOR_WEIGHT
        diag[4:] += self._q_tiled(n)
        f[0:3] -= self._p * arrival
        f[3] -= F_PRIOR_WEIGHT * F_prior
        lo_t, hi_t = self._bounds_tiled(n)
        H *= 2.0
        f *= 2.0
        return WindowQP(H=H, f=f, M=M, c=c, lo=lo_t - c, hi=hi_t - c)

    def _q_tiled(self, n: int) -> NDArray[np.float64]:
        t = self._tiles.get(("q", n))
        if t is None:
            t = self._tiles[("q", n)] = np.tile(self._q, n)
        t[2::3] = self._mp[MP_QW]  # the yaw-rate weight in force (the yaw-model margin's)
        return t

    def _bounds_tiled(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        t = self._tiles.get(("b", n))
        if t is None:
            t = self._tiles[("b", n)] = (np.tile(self._xmin, n + 1), np.tile(self._xmax, n + 1))
        return t

    def _solve(self, qp: WindowQP) -> NDArray[np.float64] | None:
        fac, info = _potrf(qp.H, lower=False, clean=False, overwrite_a=False)
        if info == 0:
            z, info = _potrs(fac, -qp.f, lower=False)
            if info == 0:
                s = qp.M @ z
                if np.all(s >= qp.lo - 1e-9) and np.all(s <= qp.hi + 1e-9):
                    return z
        nz = qp.f.size
        inf = np.full(nz, 1e30)
        res = solve_daqp(qp.H, qp.f, -inf, inf, qp.M, qp.lo, qp.hi)
        return res.z if res.status == QPStatus.OPTIMAL else None

    # -- online step -----------------------------------------------------------------------
    def _push(self, y: NDArray[np.float64], w: float, u: NDArray[np.float64] | None) -> int:
        """Append a sample (and the input that led to it, None for the first); returns the number
        of inputs in the window (samples − 1)."""
        if self._ny == self.settings.N + 1:  # full: drop the oldest sample and input
            self._Y[:-1], self._W[:-1], self._XS[:-1] = self._Y[1:], self._W[1:], self._XS[1:]
            self._U[:-1] = self._U[1:]
            self._ny -= 1
        self._Y[self._ny], self._W[self._ny] = y, w
        self._ny += 1
        if u is not None:
            self._U[self._ny - 2] = u
        return self._ny - 1

    def step(self, y: Any, u: Any) -> Estimate:
        """Add the measurement ``y = [v, ω]`` of this sample and the input ``u = [F_xR, δ]`` that the
        plant received over the previous interval (including any friction compensation: the
        model must see what the plant saw); return the estimate at this sample."""
        y0, y1 = y if type(y) is tuple else np.asarray(y, dtype=float).reshape(2).tolist()
        u0, u1 = u if type(u) is tuple else np.asarray(u, dtype=float).reshape(2).tolist()
        return self.step_values(float(y0), float(y1), float(u0), float(u1))

    def step_values(self, v: float, omega: float, F_xR: float, delta: float) -> Estimate:
        """:meth:`step` of ``y = [v, omega]``, ``u = [F_xR, delta]`` (no arrays made): with the
        kernel one compiled call (:func:`tsmpc.kernels.mhe.mhe_step`, which the cascade's MHE block
        :func:`tsmpc.control.mhe_block.mhe_block` calls too), then :meth:`estimate`."""
        t0 = time.perf_counter()
        k = self._kern
        if k is None:
            return self._step_numpy(np.array([v, omega]), np.array([F_xR, delta]), t0)
        try:
            if self._kargs[-1]:  # the model evaluated in the block (Euler)
                st, F_raw, n, ok = k.mhe_step(v, omega, F_xR, delta, self.vehicle.mass, self._Y, self._W,
                                              self._U, self._XS, self._Ab, self._Bb, self._Xb, self._mp,
                                              self._ms, self._mi, self._uk, True, False)
            else:
                st, F_raw, n, ok = self._step_zoh(v, omega, F_xR, delta)
        except (np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            return self._failed(float("nan"), t0, f"{type(err).__name__}")
        return self.estimate(st, F_raw, n, ok, t0)

    def estimate(self, status: int, F_raw: float, n: int, ok: bool, t0: float) -> Estimate:
        """The estimate of a step the compiled kernel ran (:func:`tsmpc.kernels.mhe.mhe_step`, in
        :meth:`step_values` or the cascade's MHE block, :func:`tsmpc.control.mhe_block.mhe_block`)
        from its status code: the estimator's state, or — ``MHE_DENSE`` — the dense QP's
        (:meth:`dense_step`). ``t0``: when the step began."""
        if status == 0:  # MHE_DENSE: a state bound is active (or a pivot failed)
            return self.dense_step(ok, n, F_raw, t0)
        return Estimate(self._ms[0:3].copy(), float(self._ms[3]), F_raw, _STATUS[status],
                        time.perf_counter() - t0)

    def dense_step(self, ok: bool, n: int, F_raw: float, t0: float) -> Estimate:
        """The step the kernel handed over (a window of ``n`` inputs, updated, the model along it
        in ``_Ab``/``_Bb``, the input in ``_uk``; ``ok``: the sample was accepted): the dense QP
        decides (a linear-algebra error: FAILED). The cascade's, the run engine's and the
        batch's one Python path."""
        try:
            with np.errstate(all="ignore"):
                return self._step_dense(self._Y[n].copy(), self._uk.copy(), ok, n, n == self.settings.N,
                                        self._U[:n], self._XS[: n + 1],
                                        (self._Ab[:n].copy(), self._Bb[:n].copy()), t0, F_raw)
        except (np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            return self._failed(float("nan"), t0, f"{type(err).__name__}")

    def _step_zoh(self, v: float, omega: float, F_xR: float, delta: float) -> tuple[int, float, int, bool]:
        """The block's step with the model evaluated by numpy (ZOH) between the window's update
        (:func:`~tsmpc.kernels.mhe.mhe_push`) and its solve (:func:`~tsmpc.kernels.mhe.mhe_solve`)."""
        k = self._kern
        st, n, ok, u0, u1 = k.mhe_push(v, omega, F_xR, delta, self._Y, self._W, self._U, self._XS, self._mp,
                                       self._ms, self._mi)
        self._uk[0], self._uk[1] = u0, u1
        if st != k.MHE_DENSE:
            return st, 0.0, n, ok
        us, xs = self._U[:n], self._XS[: n + 1]
        xs[n - 1] = self._x
        self._Ab[:n], self._Bb[:n] = self.model.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
        st, F_raw = k.mhe_solve(v, ok, n, self.vehicle.mass, self._Y, self._W, self._U, self._XS, self._Ab,
                                self._Bb, self._Xb, self._mp, self._ms, self._mi, self._uk, False, False)
        return st, F_raw, n, ok

    def _step_numpy(self, y: NDArray[np.float64], u: NDArray[np.float64], t0: float) -> Estimate:
        """The step without the kernel (numpy window update and dense QP: the tests' oracle)."""
        first = self._ny == 0
        ok = math.isfinite(y[0]) and math.isfinite(y[1])  # on floats: numpy's scalar test is slow
        if not (math.isfinite(u[0]) and math.isfinite(u[1])):
            # A non-finite input is a caller bug upstream; never poison the window with it.
            u = np.zeros(2)
            ok = False
        if not ok:
            self._n_rejected += 1
        n = self._push(y if ok else np.zeros(2), 1.0 if ok else 0.0, None if first else u)
        if first:
            self._XS[0] = self._x
            if not ok:
                return Estimate(self._x.copy(), self._F, 0.0, EstimatorStatus.REJECTED,
                                time.perf_counter() - t0)
            status = EstimatorStatus.WARMUP
            self._XS[0, 0], self._XS[0, 2] = y[0], y[1]
            self._x = np.clip(self._XS[0], self._xmin, self._xmax)
            return Estimate(self._x.copy(), self._F, 0.0, status, time.perf_counter() - t0)
        us, xs = self._U[:n], self._XS[: n + 1]
        full = n == self.settings.N
        try:
            with np.errstate(all="ignore"):  # overflow is detected below, not warned about
                return self._step_dense(y, u, ok, n, full, us, xs, None, t0)
        except (np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            # A linear-algebra failure is a failed estimate, never an exception in the loop.
            return self._failed(float("nan"), t0, f"{type(err).__name__}")

    def _failed(self, F_raw: float, t0: float, why: str = "") -> Estimate:
        """FAILED: keep the last estimate (the prediction may be unusable)."""
        self._n_failed += 1
        x = self._x if np.all(np.isfinite(self._x)) else np.clip(np.nan_to_num(self._x), self._xmin,
                                                                   self._xmax)
        self._x = x
        F_raw = F_raw if np.isfinite(F_raw) else 0.0
        return Estimate(self._x.copy(), self._F, F_raw, EstimatorStatus.FAILED, time.perf_counter() - t0)

    def _predict(self, y: NDArray[np.float64], ok: bool, n: int, xs: NDArray[np.float64],
                 x_pred: NDArray[np.float64], F_raw: float, t0: float) -> Estimate | None:
        """Store the one-step prediction ``x_pred`` (with the measured v, ω) as the window's last
        sample; the estimate to return without a window solve (non-finite prediction: FAILED;
        warm-up or a rejected sample: the prediction), else None."""
        if not (np.all(np.isfinite(x_pred)) and np.isfinite(F_raw)):
            return self._failed(F_raw, t0)
        xs[n] = x_pred
        if ok:
            xs[n, 0], xs[n, 2] = y[0], y[1]
        if n < 2 or not ok:
            self._x = np.clip(xs[n], self._xmin, self._xmax)
            status = EstimatorStatus.REJECTED if not ok else EstimatorStatus.WARMUP
            return Estimate(self._x.copy(), self._F, F_raw, status, time.perf_counter() - t0)
        return None

    def _step_dense(self, y: NDArray[np.float64], u: NDArray[np.float64], ok: bool, n: int, full: bool,
                    us: NDArray[np.float64], xs: NDArray[np.float64],
                    matrices: tuple[NDArray[np.float64], NDArray[np.float64]] | None, t0: float,
                    F_raw: float | None = None) -> Estimate:
        """The numpy window step: dense QP (Cholesky, DAQP when a bound is active). With
        ``matrices`` given, the prediction is already in ``xs[n]`` (kernel hand-over)."""
        if matrices is None:
            # Model along the window at the current scheduling; its last interval (from the
            # previous estimate, with this input) is also the one-step prediction.
            xs[n - 1] = self._x
            A, B = self.model.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
            pred = A[-1] @ self._x + B[-1] @ u
            x_pred = pred - B[-1, :, 0] * self._F  # E_d = −B_d[:, :1]
            F_raw = float((pred[0] - y[0]) * self.vehicle.mass / self.Td) if ok else 0.0
            early = self._predict(y, ok, n, xs, x_pred, F_raw, t0)
            if early is not None:
                return early
        else:
            A, B = matrices
            x_pred = A[-1] @ self._x + B[-1] @ u - B[-1, :, 0] * self._F
        assert F_raw is not None
        # Arrival prior: the previous solution's estimate of the window's first sample.
        qp = self.build(self._Y[: n + 1], us, self._W[: n + 1], xs, xs[0] if full else self._arrival,
                        self._F, matrices=(A, B))
        z = self._solve(qp)
        if z is None or not np.all(np.isfinite(z)):
            self._n_failed += 1
            self._x = np.clip(x_pred, self._xmin, self._xmax)
            return Estimate(self._x.copy(), self._F, F_raw, EstimatorStatus.FAILED,
                            time.perf_counter() - t0)
        # Keep the smoothed trajectory for the next window's scheduling and arrival cost.
        X = (qp.M @ z + qp.c).reshape(-1, 3)
        xs[:] = X
        self._x = X[-1].copy()
        self._F = float(z[3])
        status = EstimatorStatus.OK if full else EstimatorStatus.WARMUP
        if full:  # the yaw-model margin on the solved window (the compiled step's, mhe_margin.py)
            margin_update(self._mp, self._ms, xs, A, B, us, n)
        return Estimate(self._x.copy(), self._F, F_raw, status, time.perf_counter() - t0)
