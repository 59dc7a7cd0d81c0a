"""Linear time-varying MPC on the kinematic error model (issue 26 baseline): the classic LTV-MPC,
the model linearised along the reference, no TS scheduling.

Linearising ẋ = f(x, u) = [ω e_y − v + v_d cos e_θ, −ω e_x + v_d sin e_θ, ω_d − ω] at
the reference (x = 0, u = r = [v_d, ω_d]) and discretising by Euler at T_c as the TS-MPC does::

    x_{i+1} = A_i x_i + B_c (u_i − r_i),   A_i = [[1, ω_d,i T_c, 0], [−ω_d,i T_c, 1, v_d,i T_c], [0, 0, 1]],
    r_i = [v_d,i, ω_d,i]

(f(0, r) = 0, ∂f/∂u at the reference = the TS model's B_c). This is the TS model's A_c(ρ) at
ρ_i = (ω_d,i, v_d,i, e_θ = 0), unclipped: the LTV-MPC schedules on the reference alone, where the
TS-MPC's REF mode also carries the predicted heading error ê_θ (sinc ê_θ in A, cos ê_θ in r) and
keeps ρ inside the certified box.

Cost, constraints and terminal ingredients are the TS-MPC's (``mpc`` settings: N, Q, R, Π, ΔΠ;
the kinematic design's P and χ = {xᵀSx ≤ 1}), so the comparison isolates the model. The solve is
the TS-MPC's, reused: the compiled Riccati recursion's unconstrained minimiser when it satisfies
every constraint, else the condensed QP with DAQP, tangent cuts, the exact SOCP and the exactly
penalised soft terminal set (:class:`tsmpc.control.ts_mpc.TSMPC`), else the shifted previous plan.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Method, MPCSettings
from tsmpc.control.ts_mpc import TSMPC, MPCResult, MPCStatus, condense
from tsmpc.models.kinematic import KinematicTS

__all__ = ["LTVMPC", "linearisation"]


def linearisation(
    v_d: NDArray[np.float64], omega_d: NDArray[np.float64], Tc: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(c, s, r) of the model linearised along the reference in the condensed QP's notation
    (:func:`tsmpc.control.ts_mpc.condense`): c_i = ω_d,i T_c, s_i = v_d,i T_c, r_i = [v_d,i, ω_d,i]."""
    v = np.array(v_d, dtype=float)
    w = np.array(omega_d, dtype=float)
    r = np.empty((v.size, 2))
    r[:, 0], r[:, 1] = v, w
    return w * Tc, v * Tc, r


class LTVMPC(TSMPC):
    """LTV-MPC with the TS-MPC's cost, constraints and solver; ``step`` as :meth:`TSMPC.step`.

    Args:
        settings: horizon, weights, bounds, soft penalty (``mode`` is not used).
        model: kinematic TS model (only its T_c is used: no scheduling box).
        P: terminal cost (3, 3) of the kinematic design.
        S: terminal set matrix (3, 3) of the kinematic design, χ = {x : xᵀSx ≤ 1}.
        jit: the compiled Riccati fast path (None = unless ``TSMPC_NO_JIT`` is set).
    """

    def __init__(self, settings: MPCSettings, model: KinematicTS, P: NDArray[np.float64],
                 S: NDArray[np.float64], jit: bool | None = None) -> None:
        super().__init__(settings, model, P, S, mode=Method.REF, jit=jit)
        self.mode = Method.LTV
        if self._kern is not None:  # compile/load the two kernels outside the first timed step
            N, z = self.N, np.zeros(3)
            U, DU, X = np.empty((N, 2)), np.empty((N, 2)), np.empty((N + 1, 3))
            c, s, r = linearisation(np.ones(N), np.zeros(N), self.model.Tc)
            self._kern.riccati(z, np.zeros(2), c, s, r, self.model.Tc, self._q, self._Pc, self._r,
                               U, DU, X)
            self._kern.feasible(np.zeros(2), U, DU, X, self._Sc, self._du, self._umin, self._umax,
                                True, 1e-9, 1e-9)

    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One receding-horizon step (same contract as :meth:`TSMPC.step`)."""
        t0 = time.perf_counter()
        N, Tc = self.N, self.model.Tc
        x0 = np.asarray(errors, dtype=float).reshape(3)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        v_d = np.asarray(reference.v, dtype=float)[:N]
        w_d = np.asarray(reference.omega, dtype=float)[:N]
        if not (v_d.size == N and w_d.size == N
                and np.isfinite(x0.sum() + up.sum() + v_d.sum() + w_d.sum())):
            return self._fallback(x0, up, t0, 0, 0, 0)
        c, s, r = linearisation(v_d, w_d, Tc)
        use_term = self.settings.terminal_constraint
        if self._kern is not None:
            U, DU, X = np.empty((N, 2)), np.empty((N, 2)), np.empty((N + 1, 3))
            cost = self._kern.riccati(x0, up, c, s, r, Tc, self._q, self._Pc, self._r, U, DU, X)
            if np.isfinite(cost) and self._kern.feasible(up, U, DU, X, self._Sc, self._du, self._umin,
                                                         self._umax, use_term, 1e-9, 1e-9):
                res = MPCResult(u=U[0].copy(), x_pred=X, u_pred=U, du=DU, cost=float(cost),
                                status=MPCStatus.OPTIMAL, iterations=0, qp_iterations=0,
                                solve_time_s=time.perf_counter() - t0, n_clipped=0)
                self._prev = res
                return res
        qp = condense(x0, up, r, c, s, Tc, self._q, self.P, self._r)
        z, status, n_qp, n_it = self._solve(qp, up)
        if z is None:
            return self._fallback(x0, up, t0, n_qp, n_it, 0)
        du = z.reshape(2, N).T
        X = np.empty((N + 1, 3))
        X[0] = x0
        X[1:] = (qp.x_aff + qp.G @ z).reshape(3, N).T
        res = MPCResult(u=(up + du[0]).copy(), x_pred=X, u_pred=up + np.cumsum(du, axis=0), du=du,
                        cost=float(z @ qp.H @ z + 2.0 * qp.f @ z + qp.c0), status=status,
                        iterations=n_qp, qp_iterations=n_it, solve_time_s=time.perf_counter() - t0,
                        n_clipped=0)
        self._prev = res
        return res
