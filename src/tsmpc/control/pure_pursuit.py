"""Pure pursuit with a speed-scheduled look-ahead (issue 26 baseline; Coulter 1992, as in Autoware's
``pure_pursuit`` and PythonRobotics).

Each T_c: the pose is recovered from the outer loop's errors (:func:`tsmpc.control.geometric.vehicle_pose`);
the goal is the first point of the reference path, after the point nearest to the vehicle, at
distance L_d = clip(t_la · v_ref, L_min, L_max) from it (``baselines.pure_pursuit``); the arc through
the vehicle, tangent to its heading, that reaches the goal has curvature

    κ = 2 y_g / (x_g² + y_g²)        ((x_g, y_g): the goal in the vehicle frame)

and ω_ref = v_ref κ (:func:`tsmpc.control.geometric.yaw_rate_command`, the one conversion). The speed
channel v_ref is :func:`tsmpc.control.geometric.speed_command` (reference-speed feed-forward plus
along-track error feedback). Both commands are saturated to the MPC's input box Π (``mpc.u_min``,
``mpc.u_max``); there are no rate limits and no prediction.

The reference path is the CoG's; the arc is drawn from the pose the outer loop tracks (the CoG, or
its velocity pose under the slip-aware loop), so on a circle with the vehicle on it the law returns
κ = 1/R exactly (up to the polyline's sagitta).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from tsmpc.config import MPCSettings, PurePursuitSettings
from tsmpc.control.geometric import (
    lookahead_point,
    nearest_point,
    reference_heading,
    speed_command,
    vehicle_pose,
    yaw_rate_command,
)
from tsmpc.control.law import law_result
from tsmpc.control.ts_mpc import MPCResult, shifted_plan

__all__ = ["PurePursuit"]


class PurePursuit:
    """Pure pursuit on the reference window; the outer MPC's step protocol.

    Args:
        settings: look-ahead time and bounds.
        mpc: the MPC settings (input box Π, horizon N for the result's shape, the reference
            heading switches).
        Tc: outer sample time [s].
        along_track_gain: gain of the speed channel's along-track feedback [1/s].
    """

    def __init__(self, settings: PurePursuitSettings, mpc: MPCSettings, Tc: float, *,
                 along_track_gain: float) -> None:
        self.settings = settings
        self.N = mpc.N
        self.Tc = float(Tc)
        self.tangent_heading = mpc.tangent_heading
        self.step_average = mpc.step_average_reference
        self.gain = float(along_track_gain)
        self._umin = np.asarray(mpc.u_min, dtype=float)
        self._umax = np.asarray(mpc.u_max, dtype=float)
        self.reset()

    @property
    def dt(self) -> float:
        """Sample time T_c [s] (the runtime protocol's name)."""
        return self.Tc

    def reset(self) -> None:
        """Forget the previous result (used only by the fallback)."""
        self._prev: MPCResult | None = None

    def lookahead(self, v: float) -> float:
        """L_d [m] at speed v [m/s]."""
        s = self.settings
        return min(max(s.lookahead_time_s * v, s.lookahead_min_m), s.lookahead_max_m)

    def curvature(self, errors: Any, window: Any, v: float) -> float:
        """κ [1/m] of the arc from the pose to the look-ahead point at speed v."""
        heading = reference_heading(window, self.tangent_heading, self.step_average)
        X, Y, th = vehicle_pose(np.asarray(errors, dtype=float), window, heading)
        xs, ys = np.asarray(window.x, dtype=float), np.asarray(window.y, dtype=float)
        near = nearest_point(X, Y, xs, ys)
        gx, gy = lookahead_point(X, Y, xs, ys, near, self.lookahead(v))
        dx, dy = gx - X, gy - Y
        d2 = dx * dx + dy * dy
        if d2 <= 1e-12:
            return 0.0
        y_g = -math.sin(th) * dx + math.cos(th) * dy
        return 2.0 * y_g / d2

    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One step: ``errors`` [e_x, e_y, e_θ], ``u_prev`` [v, ω] (u_{k−1}), ``reference`` the
        window from sample k (``.x, .y, .theta, .v, .omega``, ≥ 2 samples)."""
        t0 = time.perf_counter()
        x0 = np.asarray(errors, dtype=float).reshape(3)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        xs, ys = np.asarray(reference.x, dtype=float), np.asarray(reference.y, dtype=float)
        v_d = np.asarray(reference.v, dtype=float)
        if not (xs.size >= 2 and np.isfinite(x0.sum() + up.sum() + xs.sum() + ys.sum() + v_d[0])
                and np.isfinite(np.asarray(reference.theta, dtype=float)[:2].sum())):
            self._prev = shifted_plan(self._prev, x0, up, self.N, t0, 0, 0, 0)
            return self._prev
        v = min(max(speed_command(x0, float(v_d[0]), self.gain), self._umin[0]), self._umax[0])
        w = yaw_rate_command(v, self.curvature(x0, reference, v))
        u = np.array([v, min(max(w, self._umin[1]), self._umax[1])])
        self._prev = law_result(x0, u, up, self.N, t0)
        return self._prev
