"""The paper's TS-MHE-UIO form (paper eqs. "MHE", "disturb_estimation"; SPEC §9): the friction force
is *eliminated* from the window model through E_d instead of being estimated inside it
(``mhe.form = "uio"``; ours, the window-constant unknown input, is :mod:`tsmpc.estimation.mhe_uio`).

With ``x_{k+1} = A_k x_k + B_k u_k + E_k F`` and ``y = C x`` (C picks v and ω), the UIO gain
``Θ_k = (C E_k)⁺`` recovers ``F = Θ_k (y_{k+1} − C (A_k x_k + B_k u_k))``; substituted, the
transition no longer contains F::

    x_{k+1} = A_o,k x_k + B_o,k u_k + E_k Θ_k y_{k+1} + w_k,
    A_o = (I − E Θ C) A,   B_o = (I − E Θ C) B

(Euler: ``E = [−T_d/M, 0, 0]ᵀ``, ``Θ = [−M/T_d, 0]``: the speed row of A_o and B_o is zero and the
transition sets v to its next measurement). The window QP over ``z = [x_0, w_0 … w_{N−1}]``::

    min ‖x_0 − x̄_0‖²_P + Σ ‖w_k‖²_Q + Σ ρ_k ‖y_k − C x_k‖²_R    s.t.  x_min ≤ x_k ≤ x_max

has the arrival cost, weights and bounds of ours; a rejected sample (ρ = 0) has no measurement to
decouple with, so its transition is the plain model with the last friction estimate. After each
solve, ``F̂ = Θ (y_k − C (A x̂_{k−1} + B u_{k−1}))`` from the window's smoothed x̂_{k−1} (P-disturb_
estimation) is the estimate that reaches the controller (``Estimate.F_fr``); ``F_fr_raw`` is the
same formula from the previous step's estimate, as in ours. With Θ = −M/T_d both carry the speed
sensor's noise amplified by M/T_d (SPEC §9).

Speed: this form runs on the numpy dense-QP path only (no compiled kernel): it is not the default.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import MHESettings, VehicleParams
from tsmpc.estimation.mhe_uio import MHEUIO, Estimate, EstimatorStatus, WindowQP
from tsmpc.models.dynamic import DynamicTS

__all__ = ["PaperUIOMHE", "uio_gain"]

_EYE3 = np.eye(3)


def uio_gain(E: NDArray[np.float64]) -> NDArray[np.float64]:
    """Θ (3,) = (C E)⁺ written on the state (zero on α): ``Θ·x`` reads Θ (C x). ``E`` is (3,)."""
    ce = np.array([E[0], E[2]])
    den = float(ce @ ce)
    th = np.zeros(3)
    if den > 0.0:
        th[0], th[2] = ce / den
    return th


class PaperUIOMHE(MHEUIO):
    """The paper's UIO form of the MHE (module docstring); the interface of
    :class:`~tsmpc.estimation.mhe_uio.MHEUIO`. Always the numpy path (``jit`` is ignored)."""

    def __init__(self, settings: MHESettings, model: DynamicTS, vehicle: VehicleParams, Td: float,
                 x0: NDArray[np.float64] | None = None, jit: bool | None = None) -> None:
        super().__init__(settings, model, vehicle, Td, x0=x0, jit=False)

    def build_uio(self, ys: NDArray[np.float64], us: NDArray[np.float64],
                  weights: NDArray[np.float64], A: NDArray[np.float64], B: NDArray[np.float64],
                  arrival: NDArray[np.float64], F_prev: float) -> WindowQP:
        """Window QP ``½zᵀHz + fᵀz`` over ``z = [x_0, w_0 … w_{n−1}]`` for measurements ys
        (n+1, 2), inputs us (n, 2), sample weights (n+1,) and the model (A (n, 3, 3), B (n, 3, 2))
        along the window; ``M z + c`` are the states x_0 … x_n."""
        n = us.shape[0]
        nz = 3 + 3 * n
        M = np.zeros((3 * (n + 1), nz))
        M3 = M.reshape(n + 1, 3, nz)
        M3[0, :, :3] = _EYE3
        c3 = np.zeros((n + 1, 3))
        for k in range(n):
            E = -B[k, :, 0]  # E_d = −B_d[:, :1] (F enters as a negative drive force)
            if weights[k + 1] > 0.0:  # decouple F with the next measurement
                th = uio_gain(E)
                Pi = _EYE3 - np.outer(E, th)  # I − E Θ C
                Ak = Pi @ A[k]
                bk = Pi @ (B[k] @ us[k]) + E * (th[0] * ys[k + 1, 0] + th[2] * ys[k + 1, 1])
            else:  # no measurement: the plain model with the last friction estimate
                Ak = A[k]
                bk = B[k] @ us[k] + E * F_prev
            w = 3 + 3 * k
            np.matmul(Ak, M3[k, :, :w], out=M3[k + 1, :, :w])
            M3[k + 1, :, w:w + 3] = _EYE3
            c3[k + 1] = Ak @ c3[k] + bk
        sw = np.sqrt(weights)[:, None] * self._sqrt_r
        Cm2 = (M3[:, 0::2, :] * sw[:, :, None]).reshape(-1, nz)
        res = (ys - c3[:, 0::2]) * sw
        H = Cm2.T @ Cm2
        f = -(Cm2.T @ res.reshape(-1))
        diag = H.reshape(-1)[:: nz + 1]
        diag[:3] += self._p
        diag[3:] += self._q_tiled(n)
        f[0:3] -= self._p * arrival
        lo_t, hi_t = self._bounds_tiled(n)
        c = c3.reshape(-1)
        return WindowQP(H=2.0 * H, f=2.0 * f, M=M, c=c, lo=lo_t - c, hi=hi_t - c)

    def _step_dense(self, y: NDArray[np.float64], u: NDArray[np.float64], ok: bool, n: int, full: bool,
                    us: NDArray[np.float64], xs: NDArray[np.float64],
                    matrices: tuple[NDArray[np.float64], NDArray[np.float64]] | None, t0: float,
                    F_raw: float | None = None) -> Estimate:
        """One window step of the UIO form (called by :meth:`MHEUIO.step`)."""
        xs[n - 1] = self._x
        A, B = self.model.matrices(np.stack([us[:, 1], xs[:n, 0], xs[:n, 1]], axis=-1))
        E = -B[-1, :, 0]
        th = uio_gain(E)
        pred = A[-1] @ self._x + B[-1] @ u
        F_raw = float(th[0] * (y[0] - pred[0]) + th[2] * (y[1] - pred[2])) if ok else 0.0
        x_pred = pred + E * self._F
        early = self._predict(y, ok, n, xs, x_pred, F_raw, t0)
        if early is not None:
            return early
        arrival = xs[0] if full else self._arrival
        qp = self.build_uio(self._Y[: n + 1], us, self._W[: n + 1], A, B, arrival, self._F)
        z = self._solve(qp)
        if z is None or not np.all(np.isfinite(z)):
            self._n_failed += 1
            self._x = np.clip(x_pred, self._xmin, self._xmax)
            return Estimate(self._x.copy(), self._F, F_raw, EstimatorStatus.FAILED,
                            time.perf_counter() - t0)
        X = (qp.M @ z + qp.c).reshape(-1, 3)
        xs[:] = X
        self._x = X[-1].copy()
        # P-disturb_estimation from the smoothed previous sample of this window.
        prev = A[-1] @ X[-2] + B[-1] @ us[-1]
        F = float(th[0] * (y[0] - prev[0]) + th[2] * (y[1] - prev[2]))
        self._F = F if np.isfinite(F) else self._F
        status = EstimatorStatus.OK if full else EstimatorStatus.WARMUP
        return Estimate(self._x.copy(), self._F, F_raw, status, time.perf_counter() - t0)
