"""Stanley's path-tracking law (issue 26 baseline; Hoffmann, Tomlin, Montemerlo & Thrun 2007, as in
PythonRobotics and most autonomous-driving courses).

Each T_c: from the pose the outer loop tracks (:func:`tsmpc.control.geometric.vehicle_pose`), the
front axle lies at distance a ahead along the heading θ; with the reference path's point nearest
to it (tangent θ_p, curvature κ_p) and its cross-track error e (positive when the path lies to the
left of the axle)::

    δ = k_ψ ψ_e + atan(k e / (k_soft + v_ref)) [+ atan(L κ_p) − k_ψ atan(a κ_p)],   ψ_e = wrap(θ_p − θ),

saturated to the steering limit ``lqr.delta_max`` (``baselines.stanley``: k, k_soft, k_ψ, the
feed-forward switch).

* k_ψ = 1 is the classic law. Run every T_c, its heading term alone gives ω = v tan(ψ_e) / L, i.e.
  e_θ⁺ ≈ (1 − k_ψ v T_c / L) e_θ per step: at T_c = 0.1 s and L = 1.79 m the classic law
  overshoots the heading every step above 18 m/s, and the inner loop's yaw-rate lag turns that into
  a growing oscillation. k_ψ < 1 is the usual remedy when the law cannot run faster.
* The bracket is the *curvature feed-forward* (off = the classic law): the reference is the CoG's
  path, and on a circle of curvature κ a kinematic bicycle whose CoG follows it sees
  ψ_e = atan(a κ) at its front axle while it needs δ = atan(L κ); without the bracket the
  cross-track term must make up the difference, i.e. a steady offset ≈ (k_soft + v) tan(b κ) / k
  (for k_ψ = 1) to the outside of every corner.

δ becomes a curvature through the kinematic bicycle, κ = tan δ / L, and then the yaw-rate command
ω_ref = v_ref κ (:mod:`tsmpc.control.geometric`, the one conversion). The speed channel is
:func:`tsmpc.control.geometric.speed_command`; both commands are saturated to the MPC's input box.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from tsmpc.config import MPCSettings, StanleySettings, VehicleParams
from tsmpc.control.geometric import (
    curvature_of_steering,
    nearest_point,
    reference_heading,
    speed_command,
    vehicle_pose,
    yaw_rate_command,
)
from tsmpc.control.law import law_result
from tsmpc.control.ts_mpc import MPCResult, shifted_plan

__all__ = ["Stanley"]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Stanley:
    """Stanley's law on the reference window; the outer MPC's step protocol.

    Args:
        settings: gain k, softening speed, heading gain k_ψ, curvature feed-forward switch.
        mpc: the MPC settings (input box Π, horizon N for the result's shape, the reference
            heading switches).
        Tc: outer sample time [s].
        vehicle: axle distances a, b (wheelbase L = a + b).
        delta_max: steering limit [rad].
        along_track_gain: gain of the speed channel's along-track feedback [1/s].
    """

    def __init__(self, settings: StanleySettings, mpc: MPCSettings, Tc: float, vehicle: VehicleParams,
                 *, delta_max: float, along_track_gain: float) -> None:
        self.settings = settings
        self.N = mpc.N
        self.Tc = float(Tc)
        self.tangent_heading = mpc.tangent_heading
        self.step_average = mpc.step_average_reference
        self.a = float(vehicle.a)
        self.wheelbase = float(vehicle.wheelbase)
        self.delta_max = float(delta_max)
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

    def steering(self, errors: Any, window: Any, v: float) -> float:
        """δ [rad] of the law at speed v (saturated to ±delta_max)."""
        heading = reference_heading(window, self.tangent_heading, self.step_average)
        X, Y, th = vehicle_pose(np.asarray(errors, dtype=float), window, heading)
        fx, fy = X + self.a * math.cos(th), Y + self.a * math.sin(th)
        kap = getattr(window, "kappa", None)
        near = nearest_point(fx, fy, np.asarray(window.x, dtype=float), np.asarray(window.y, dtype=float),
                             None if kap is None else np.asarray(kap, dtype=float))
        st = self.settings
        delta = (st.heading_gain * _wrap(near.heading - th)
                 + math.atan2(st.gain * -near.offset, st.softening_speed + v))
        if st.curvature_feedforward:
            delta += (math.atan(self.wheelbase * near.kappa)
                      - st.heading_gain * math.atan(self.a * near.kappa))
        return min(max(delta, -self.delta_max), self.delta_max)

    def step(self, errors: Any, u_prev: Any, reference: Any) -> MPCResult:
        """One step: ``errors`` [e_x, e_y, e_θ], ``u_prev`` [v, ω] (u_{k−1}), ``reference`` the
        window from sample k (``.x, .y, .theta, .v, .omega, .kappa``, ≥ 2 samples)."""
        t0 = time.perf_counter()
        x0 = np.asarray(errors, dtype=float).reshape(3)
        up = np.clip(np.asarray(u_prev, dtype=float).reshape(2), self._umin, self._umax)
        xs, ys = np.asarray(reference.x, dtype=float), np.asarray(reference.y, dtype=float)
        v_d = np.asarray(reference.v, dtype=float)
        kap = np.asarray(getattr(reference, "kappa", np.zeros(2)), dtype=float)
        if not (xs.size >= 2 and np.isfinite(x0.sum() + up.sum() + xs.sum() + ys.sum() + v_d[0]
                                             + kap.sum())
                and np.isfinite(np.asarray(reference.theta, dtype=float)[:2].sum())):
            self._prev = shifted_plan(self._prev, x0, up, self.N, t0, 0, 0, 0)
            return self._prev
        v = min(max(speed_command(x0, float(v_d[0]), self.gain), self._umin[0]), self._umax[0])
        kappa = curvature_of_steering(self.steering(x0, reference, v), self.wheelbase)
        w = yaw_rate_command(v, kappa)
        u = np.array([v, min(max(w, self._umin[1]), self._umax[1])])
        self._prev = law_result(x0, u, up, self.N, t0)
        return self._prev
