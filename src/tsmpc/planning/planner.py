"""Trajectory planner (the paper's "trajectory planning" block; SPEC §10).

From waypoints (or a track centre line) to a :class:`~tsmpc.planning.reference.Reference`:

1. *Path*: a C² cubic spline through the waypoints (periodic for closed laps, natural otherwise),
   parametrised by chord length and resampled at uniform arc length; curvature κ(s) from its
   derivatives (continuous, so ω_d = v_d κ is continuous).
2. *Speed profile* on s: ``v ≤ v_max``, ``v ≤ √(a_lat/|κ|)``, a forward pass with ``a_lon`` and a
   backward pass with ``a_brake`` (run on a margin of the limits), then Gaussian smoothing in s so
   v_d and its derivative are continuous, then the pointwise limit again.
3. *Timing*: t(s) = ∫ ds / v, sampled at ``dt``. The pose is then *integrated* from (v_d, ω_d) with
   the paper's convention θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T, so every planner
   output is exactly consistent with its own speeds and yaw rates (it stays within centimetres of
   the geometric path on tracks of a few kilometres).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d

from tsmpc.config import PlannerSettings
from tsmpc.errors import DataFormatError
from tsmpc.planning.reference import Reference

__all__ = ["integrate_pose", "plan_path", "speed_profile"]

#: Arc-length resolution of the profile [m].
DS = 0.25
#: The passes use this fraction of the limits; smoothing then stays inside the true limits.
MARGIN = 0.9
#: Gaussian smoothing of the speed profile along s [m].
SMOOTH_M = 6.0


def _spline(waypoints: NDArray[np.float64], closed: bool) -> tuple[CubicSpline, float]:
    pts = waypoints
    if closed and np.hypot(*(pts[0] - pts[-1])) > 1e-9:
        pts = np.vstack([pts, pts[:1]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-9])
    pts = pts[keep]
    u = np.concatenate([[0.0], np.cumsum(seg[seg > 1e-9])])
    if pts.shape[0] < (4 if closed else 2):
        raise DataFormatError("planner: need at least 2 distinct waypoints (3 for a closed lap)")
    return CubicSpline(u, pts, bc_type="periodic" if closed else "natural"), float(u[-1])


def _geometry(waypoints: NDArray[np.float64], closed: bool) -> tuple[NDArray[np.float64], ...]:
    """(s, x, y, heading, κ) on a uniform arc-length grid."""
    sp, L = _spline(waypoints, closed)
    u = np.linspace(0.0, L, max(int(L / (DS / 4)), 50))
    d1 = sp(u, 1)
    ds = np.hypot(d1[:, 0], d1[:, 1])
    s_u = np.concatenate([[0.0], np.cumsum(0.5 * (ds[1:] + ds[:-1]) * np.diff(u))])
    n = max(int(s_u[-1] / DS), 8)
    s = np.linspace(0.0, s_u[-1], n + 1)
    uu = np.interp(s, s_u, u)
    p, d1, d2 = sp(uu), sp(uu, 1), sp(uu, 2)
    kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(np.hypot(d1[:, 0], d1[:, 1]) ** 3, 1e-12)
    heading = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
    return s, p[:, 0], p[:, 1], heading, kappa


def speed_profile(
    s: NDArray[np.float64], kappa: NDArray[np.float64], settings: PlannerSettings, *, closed: bool,
    v_start: float | None = None,
) -> NDArray[np.float64]:
    """Speed on the arc-length grid s within every limit of ``settings`` (SPEC §10)."""
    ds = np.diff(s)
    v_lim = np.minimum(settings.v_max, np.sqrt(settings.a_lat_max / np.maximum(np.abs(kappa), 1e-9)))
    vm = np.minimum(settings.v_max, np.sqrt(MARGIN * settings.a_lat_max / np.maximum(np.abs(kappa), 1e-9)))
    a_lon, a_brk = MARGIN * settings.a_lon_max, MARGIN * settings.a_brake_max
    v = vm.copy()
    n = v.size
    passes = 3 if closed else 1
    v0 = settings.v_start if v_start is None else v_start
    for p in range(passes):
        if not closed:
            v[0] = min(v[0], v0)
        elif p > 0:
            v[0] = min(v[0], v[-1])
        for i in range(n - 1):  # forward: acceleration
            v[i + 1] = min(v[i + 1], np.sqrt(v[i] ** 2 + 2.0 * a_lon * ds[i]))
        if closed:
            v[-1] = min(v[-1], v[0])
        for i in range(n - 2, -1, -1):  # backward: braking
            v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2.0 * a_brk * ds[i]))
    sigma = SMOOTH_M / max(float(np.mean(ds)), 1e-9)
    vs = gaussian_filter1d(v, sigma, mode="wrap" if closed else "nearest")
    if not closed:
        vs[0] = v[0]
        # Keep the start speed: blend the first smoothing length back to the raw profile.
        w = np.clip(s / (3 * SMOOTH_M), 0, 1)
        vs = w * vs + (1 - w) * v
    return np.minimum(vs, v_lim)


def integrate_pose(
    x0: float, y0: float, th0: float, v: NDArray[np.float64], omega: NDArray[np.float64], dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The paper's convention: θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T."""
    th = th0 + np.concatenate([[0.0], np.cumsum(omega[1:] * dt)])
    x = x0 + np.concatenate([[0.0], np.cumsum(v[1:] * np.cos(th[1:]) * dt)])
    y = y0 + np.concatenate([[0.0], np.cumsum(v[1:] * np.sin(th[1:]) * dt)])
    return x, y, th


def plan_path(
    waypoints: ArrayLike, settings: PlannerSettings, *, closed: bool = False, dt: float = 0.1,
    laps: int = 1, tail_s: float = 0.0,
) -> Reference:
    """Plan a reference through ``waypoints`` (n, 2) [m].

    Args:
        waypoints: points of the path, in driving order.
        settings: speed and acceleration limits.
        closed: a closed lap (periodic spline, periodic speed profile, flying start).
        dt: sample time of the output [s].
        laps: number of laps (closed paths only).
        tail_s: extra time at the end, driving straight at the final speed (MPC look-ahead).
    """
    wp = np.asarray(waypoints, dtype=float)
    if wp.ndim != 2 or wp.shape[1] != 2 or not np.all(np.isfinite(wp)):
        raise DataFormatError("planner: waypoints must be a finite (n, 2) array of x, y [m]")
    if laps < 1 or (laps > 1 and not closed):
        raise DataFormatError("planner: laps must be ≥ 1, and > 1 only for closed paths")
    if dt <= 0:
        raise DataFormatError("planner: dt must be positive")
    s, x, y, heading, kappa = _geometry(wp, closed)
    L = float(s[-1])
    v = speed_profile(s, kappa, settings, closed=closed)
    if closed and laps > 1:
        s = np.concatenate([s[:-1] + k * L for k in range(laps)] + [[laps * L]])
        v = np.concatenate([v[:-1]] * laps + [v[-1:]])
        kappa = np.concatenate([kappa[:-1]] * laps + [kappa[-1:]])
    v_floor = 0.05  # a planned speed never reaches 0 inside the path (t(s) stays finite)
    vv = np.maximum(v, v_floor)
    t_s = np.concatenate([[0.0], np.cumsum(2.0 * np.diff(s) / (vv[1:] + vv[:-1]))])
    T = float(t_s[-1])
    n = int(np.floor(T / dt)) + 1
    t = np.arange(n) * dt
    s_t = np.interp(t, t_s, s)
    v_t = np.interp(s_t, s, v)
    k_t = np.interp(s_t, s, kappa)
    n_tail = int(np.ceil(tail_s / dt))
    if n_tail:
        t = np.arange(n + n_tail) * dt
        v_t = np.concatenate([v_t, np.full(n_tail, v_t[-1])])
        k_t = np.concatenate([k_t, np.zeros(n_tail)])
    w_t = v_t * k_t
    px, py, th = integrate_pose(float(x[0]), float(y[0]), float(heading[0]), v_t, w_t, dt)
    return Reference(t=t, x=px, y=py, theta=th, v=v_t, omega=w_t, kappa=k_t,
                     closed=closed and n_tail == 0)
