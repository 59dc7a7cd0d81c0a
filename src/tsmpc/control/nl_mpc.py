"""NL-MPC baseline (the paper's TS-MPC): the TS-MPC problem with the nonlinear kinematic error model.

Same cost, constraints, terminal cost P and terminal set S as :class:`~tsmpc.control.ts_mpc.TSMPC`,
with the nonlinear Euler error model ``x⁺ = x + T_c f(x, u, v_d, ω_d)`` (paper eq. "error model").
Multiple shooting (states and inputs are decision variables: sparse, well conditioned for IPOPT).
The NLP is built once as a CasADi SX graph and an ``nlpsol`` instance; each step only passes new
parameters and the warm start (the shifted previous primal solution and multipliers), so the
per-step time is IPOPT's, not graph construction. A hard solve that fails (infeasible terminal
set at start-up) is retried with the exactly penalised soft terminal constraint; if that fails too
the shifted previous plan is returned (status FALLBACK).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import MPCSettings
from tsmpc.control.ts_mpc import MPCResult, MPCStatus, shifted_plan
from tsmpc.models.kinematic import KinematicTS

__all__ = ["NLMPC"]

_IPOPT_OPTIONS: dict[str, bool | int | float | str] = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "ipopt.tol": 1e-8,
    "ipopt.max_iter": 200,
    "ipopt.warm_start_init_point": "yes",
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.mu_init": 1e-6,
}


class NLMPC:
    """Nonlinear MPC with CasADi + IPOPT, built once; same API as TSMPC."""

    def __init__(
        self, settings: MPCSettings, model: KinematicTS, P: NDArray[np.float64], S: NDArray[np.float64],
    ) -> None:
        self.settings = settings
        self.model = model
        self.N = settings.N
        self.P = np.asarray(P, dtype=float)
        self.S = np.asarray(S, dtype=float)
        self._umin = np.asarray(settings.u_min, dtype=float)
        self._umax = np.asarray(settings.u_max, dtype=float)
        self._hard = self._build(soft=False)
        self._soft = self._build(soft=True)
        self.reset()

    @property
    def dt(self) -> float:
        """Sample time T_c [s] (the runtime protocol's name)."""
        return self.model.Tc

    def reset(self) -> None:
        """Forget the warm start."""
        self._prev: MPCResult | None = None
        self._w0: NDArray[np.float64] | None = None
        self._lam_x: NDArray[np.float64] | None = None
        self._lam_g: NDArray[np.float64] | None = None

    def _build(self, soft: bool) -> dict[str, Any]:
        import casadi as ca

        N, Tc = self.N, self.model.Tc
        st = self.settings
        Q, R = np.diag(st.Q), np.diag(st.R)
        nx = 3 * N + 2 * N + (1 if soft else 0)
        w = ca.SX.sym("w", nx)
        par = ca.SX.sym("p", 3 + 2 + 2 * N)  # x0, u_prev, v_d, ω_d
        x0, up = par[0:3], par[3:5]
        vd, wd = par[5:5 + N], par[5 + N:5 + 2 * N]
        X = [x0] + [w[3 * i:3 * i + 3] for i in range(N)]
        U = [w[3 * N + 2 * i:3 * N + 2 * i + 2] for i in range(N)]
        J = ca.mtimes([x0.T, Q, x0])
        g, lbg, ubg = [], [], []
        u_last = up
        for i in range(N):
            x, u = X[i], U[i]
            du = u - u_last
            u_last = u
            J += ca.mtimes([du.T, R, du])
            if i > 0:
                J += ca.mtimes([x.T, Q, x])
            ex, ey, eth = x[0], x[1], x[2]
            v, om = u[0], u[1]
            xn = ca.vertcat(ex + Tc * (om * ey - v + vd[i] * ca.cos(eth)),
                            ey + Tc * (-om * ex + vd[i] * ca.sin(eth)),
                            eth + Tc * (wd[i] - om))
            g.append(X[i + 1] - xn)
            lbg += [0.0] * 3
            ubg += [0.0] * 3
            g.append(du)
            lbg += [-d for d in st.du_max]
            ubg += list(st.du_max)
        xN = X[N]
        J += ca.mtimes([xN.T, self.P, xN])
        if st.terminal_constraint:
            term = ca.mtimes([xN.T, self.S, xN])
            if soft:
                sig = w[nx - 1]
                J += st.soft_penalty * sig
                g.append(term - sig)
            else:
                g.append(term)
            lbg.append(-np.inf)
            ubg.append(1.0)
        nlp = {"x": w, "p": par, "f": J, "g": ca.vertcat(*g)}
        solver = ca.nlpsol("nlmpc_soft" if soft else "nlmpc", "ipopt", nlp, _IPOPT_OPTIONS)
        lbx = np.concatenate([np.full(3 * N, -np.inf), np.tile(self._umin, N)])
        ubx = np.concatenate([np.full(3 * N, np.inf), np.tile(self._umax, N)])
        if soft:
            lbx, ubx = np.append(lbx, 0.0), np.append(ubx, np.inf)
        return {"solver": solver, "lbx": lbx, "ubx": ubx, "lbg": np.array(lbg), "ubg": np.array(ubg),
                "nx": nx}

    def _initial_guess(self, x0: NDArray[np.float64], up: NDArray[np.float64],
                       v_d: NDArray[np.float64], w_d: NDArray[np.float64]) -> NDArray[np.float64]:
        """Shifted previous solution, or a rollout of u = u_prev from x0 at start-up."""
        N, Tc = self.N, self.model.Tc
        if self._prev is not None:
            U = np.vstack([self._prev.u_pred[1:], self._prev.u_pred[-1:]])
            X = np.vstack([self._prev.x_pred[2:], self._prev.x_pred[-1:]])
        else:
            U = np.tile(up, (N, 1))
            X = np.empty((N, 3))
            x = x0.copy()
            for i in range(N):
                ex, ey, eth = x
                x = x + Tc * np.array([U[i, 1] * ey - U[i, 0] + v_d[i] * np.cos(eth),
                                       -U[i, 1] * ex + v_d[i] * np.sin(eth), w_d[i] - U[i, 1]])
                X[i] = x
        return np.concatenate([X.reshape(-1), U.reshape(-1)])

    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One receding-horizon step (same contract as :meth:`TSMPC.step`)."""
        t0 = time.perf_counter()
        N = self.N
        x0 = np.asarray(errors, dtype=float).reshape(3)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        v_d = np.asarray(reference.v, dtype=float)[:N]
        w_d = np.asarray(reference.omega, dtype=float)[:N]
        if not (np.all(np.isfinite(x0)) and v_d.size == N and w_d.size == N
                and np.all(np.isfinite(v_d)) and np.all(np.isfinite(w_d))):
            return self._fallback(x0, up, t0, 0)
        par = np.concatenate([x0, up, v_d, w_d])
        guess = self._initial_guess(x0, up, v_d, w_d)
        iters = 0
        for prob, status in ((self._hard, MPCStatus.OPTIMAL), (self._soft, MPCStatus.SOFT)):
            wx = guess if prob is self._hard else np.append(guess, 0.0)
            kw: dict[str, Any] = {}
            if prob is self._hard and self._lam_x is not None and self._lam_g is not None:
                kw = {"lam_x0": self._lam_x, "lam_g0": self._lam_g}
            try:
                sol = prob["solver"](x0=wx, p=par, lbx=prob["lbx"], ubx=prob["ubx"], lbg=prob["lbg"],
                                     ubg=prob["ubg"], **kw)
                stats = prob["solver"].stats()
            except RuntimeError:
                continue
            iters += int(stats.get("iter_count", 0))
            if not stats.get("success", False):
                continue
            w = np.asarray(sol["x"]).reshape(-1)
            if prob is self._hard:
                self._lam_x = np.asarray(sol["lam_x"]).reshape(-1)
                self._lam_g = np.asarray(sol["lam_g"]).reshape(-1)
            else:
                self._lam_x = self._lam_g = None
            X = np.vstack([x0, w[:3 * N].reshape(N, 3)])
            U = w[3 * N:5 * N].reshape(N, 2)
            du = np.diff(np.vstack([up, U]), axis=0)
            res = MPCResult(u=U[0].copy(), x_pred=X, u_pred=U, du=du, cost=float(sol["f"]),
                            status=status, iterations=1 if prob is self._hard else 2,
                            qp_iterations=iters, solve_time_s=time.perf_counter() - t0, n_clipped=0)
            self._prev = res
            return res
        return self._fallback(x0, up, t0, iters)

    def _fallback(self, x0: NDArray[np.float64], up: NDArray[np.float64], t0: float, iters: int) -> MPCResult:
        res = shifted_plan(self._prev, x0, up, self.N, t0, 2, iters, 0)
        self._prev = res
        self._lam_x = self._lam_g = None
        return res
