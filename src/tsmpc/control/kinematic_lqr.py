"""Kinematic LQR on the error model (issue 26 baseline): the gain-scheduled state feedback of the
kinematic LMI design (paper eq. "Feasibility-LMI"), alone — no horizon, no constraints.

The design's vertex gains K_i make u_c − r_c = K_i x_c stabilising at vertex i of the TS error
model x⁺ = A_c(ρ) x + B_c (u − r); the online law blends them with the TS memberships::

    u = r + Σ_i μ_i(ρ) K_i x,    r = [v_d cos e_θ, ω_d],    ρ = (ω, v_d, sinc e_θ),

with ω the yaw-rate command of the previous step (as the TS-MPC's FZN mode schedules), v_d and ω_d
the reference at sample k; premises outside the box are clipped (counted in ``n_clipped``). The
law is the TS-MPC's terminal controller: with the LMI's Q_TS = diag(1, 1.5, 3), R_TS = diag(1, 3)
it is a (certified, guaranteed-cost) LQR of the TS model. The command is saturated to the MPC's
input box Π; that is the only limit (no rate limits, no terminal set).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import MPCSettings
from tsmpc.control.law import law_result
from tsmpc.control.ts_mpc import MPCResult, shifted_plan
from tsmpc.errors import ConfigError
from tsmpc.models.kinematic import KinematicTS

__all__ = ["KinematicLQR"]


class KinematicLQR:
    """u = r + K(ρ) x with the kinematic design's vertex gains; the outer MPC's step protocol.

    Args:
        settings: the MPC settings (input box Π, horizon N for the result's shape).
        model: the kinematic TS model (scheduling box, memberships, T_c).
        K: (n_vertices, 2, 3) vertex gains, :attr:`tsmpc.synthesis.kinematic.KinematicDesign.K`.
    """

    def __init__(self, settings: MPCSettings, model: KinematicTS, K: NDArray[np.float64]) -> None:
        self.model = model
        self.K = np.asarray(K, dtype=float)
        if self.K.shape != (model.n_vertices, 2, 3):
            raise ConfigError(f"KinematicLQR: K must have shape ({model.n_vertices}, 2, 3), "
                              f"got {self.K.shape}")
        self.N = settings.N
        self._umin = np.asarray(settings.u_min, dtype=float)
        self._umax = np.asarray(settings.u_max, dtype=float)
        self.reset()

    @property
    def dt(self) -> float:
        """Sample time T_c [s] (the runtime protocol's name)."""
        return self.model.Tc

    def reset(self) -> None:
        """Forget the previous result (used only by the fallback)."""
        self._prev: MPCResult | None = None

    def gain(self, omega: float, v_d: float, e_theta: float) -> tuple[NDArray[np.float64], int]:
        """(K(ρ) (2, 3), 1 if a premise was clipped into the box else 0)."""
        z, n_out = self.model.clip(self.model.premises(omega, v_d, e_theta))
        mu = self.model.memberships(z)
        return np.tensordot(mu, self.K, axes=([-1], [0])), n_out

    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One step: ``errors`` [e_x, e_y, e_θ], ``u_prev`` [v, ω] (u_{k−1}), ``reference`` with
        ``.v`` and ``.omega`` from sample k."""
        t0 = time.perf_counter()
        x0 = np.asarray(errors, dtype=float).reshape(3)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        v_d = float(np.asarray(reference.v, dtype=float)[0])
        w_d = float(np.asarray(reference.omega, dtype=float)[0])
        if not math.isfinite(float(x0.sum() + up.sum()) + v_d + w_d):
            self._prev = shifted_plan(self._prev, x0, up, self.N, t0, 0, 0, 0)
            return self._prev
        Kr, n_clip = self.gain(float(up[1]), v_d, float(x0[2]))
        r = np.array([v_d * math.cos(float(x0[2])), w_d])
        u = np.clip(r + Kr @ x0, self._umin, self._umax)
        self._prev = law_result(x0, u, up, self.N, t0, n_clipped=n_clip)
        return self._prev
