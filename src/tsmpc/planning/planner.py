"""Trajectory planner (the paper's "trajectory planning" block; the paper's scenario).

From waypoints (or a track centre line) to a :class:`~tsmpc.planning.reference.Reference`:

1. *Path*: a C² cubic spline through the waypoints (periodic for closed laps, natural otherwise),
   parametrised by chord length and resampled at uniform arc length; heading and curvature κ(s)
   from its derivatives (both continuous).
2. *Speed profile* on s, as a linear programme in b = v² (so that dv/dt = ½ db/ds is linear):
   maximise Σ b subject to ``v ≤ v_max``, ``v²|κ| ≤ a_lat``, ``v|κ| ≤ ω_max`` (optional),
   ``−a_brake ≤ ½ db/ds ≤ a_lon`` and a jerk bound on the second difference of b. Without the jerk
   bound the answer is the classic forward/backward-pass profile (used here as the upper bound
   that scales the jerk rows); with it the acceleration is continuous, so v_d is continuous *and*
   differentiable while every limit holds by construction (not by smoothing and re-clipping).
3. *Timing*: between grid nodes b is linear in s, i.e. the acceleration is constant, so t(s) and
   s(t) are exact. The output is sampled at ``dt`` and the pose is *integrated* with the paper's
   convention θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T: the arc length advances by
   v(k)T, θ(k) is the path heading at the middle of that step (second-order accurate, so the pose
   stays within centimetres of the geometric path) and ω(k) = (θ(k) − θ(k−1))/T, κ(k) = ω(k)/v(k).
   Thus every planner output reproduces itself exactly under the paper's integration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from tsmpc.config import PlannerSettings
from tsmpc.errors import DataFormatError, SolverError
from tsmpc.planning.reference import MAX_HEADING_STEP_RAD, Reference, check_coordinates

__all__ = [
    "JERK_MAX",
    "MAX_PATH_LENGTH_M",
    "MAX_SAMPLES",
    "PathGeometry",
    "SpeedProfile",
    "check_waypoints",
    "integrate_pose",
    "path_geometry",
    "plan_path",
    "speed_profile",
]

#: Arc-length resolution of the geometry [m].
DS = 0.25
#: Arc-length resolution of the speed profile (LP variables) [m].
DS_SPEED = 1.0
#: Default longitudinal jerk bound [m/s³] (comfort level); makes dv_d/dt continuous.
JERK_MAX = 2.0
#: Longest path planned [m] (the geometry grid and the speed LP grow with the length).
MAX_PATH_LENGTH_M = 200_000.0
#: Most output samples planned (≈ 2.3 days at 0.1 s; each sample is 7 doubles).
MAX_SAMPLES = 2_000_000
#: A turn sharper than this between consecutive waypoint chords is a direction reversal [deg].
MAX_WAYPOINT_TURN_DEG = 160.0


def check_waypoints(wp: NDArray[np.float64], closed: bool) -> None:
    """Refuse paths the planner cannot drive forward: direction reversals (consecutive chords
    turning back by more than :data:`MAX_WAYPOINT_TURN_DEG`), a closing chord much longer than
    the path's segments (a half lap "closed" by a straight line) and paths longer than
    :data:`MAX_PATH_LENGTH_M`. Waypoints are numbered from 1 in file order."""
    check_coordinates(wp[:, 0], wp[:, 1], "planner: waypoints")
    seg_vec = np.diff(wp, axis=0)
    seg = np.hypot(seg_vec[:, 0], seg_vec[:, 1])
    keep = seg > 1e-9
    idx = np.flatnonzero(keep)  # chord i goes from waypoint i to i + 1
    vec = seg_vec[keep]
    length = float(seg.sum())
    if closed and wp.shape[0] >= 3:
        closing = float(np.hypot(*(wp[0] - wp[-1])))
        med = float(np.median(seg[keep])) if keep.any() else 0.0
        if closing > 5.0 * med and closing > 0.15 * length and closing > 1.0:
            raise DataFormatError(
                f"planner: the closing chord from the last waypoint to the first is {closing:.0f} m "
                f"while the median segment is {med:.3g} m: the waypoints do not form a lap "
                "(add waypoints along the closing stretch, or plan an open path with --open)")
        length += closing
        if closing > 1e-9:
            vec = np.vstack([vec, wp[0] - wp[-1], vec[:1]])
            idx = np.concatenate([idx, [wp.shape[0] - 1, idx[0]]])
    if vec.shape[0] >= 2:
        cross = vec[:-1, 0] * vec[1:, 1] - vec[:-1, 1] * vec[1:, 0]
        dot = np.sum(vec[:-1] * vec[1:], axis=1)
        turn = np.degrees(np.abs(np.arctan2(cross, dot)))
        bad = np.flatnonzero(turn > MAX_WAYPOINT_TURN_DEG)
        if bad.size:
            i = int(bad[0])
            at = (int(idx[i]) + 1) % wp.shape[0] + 1
            raise DataFormatError(
                f"planner: waypoint {at}: the path turns back by {turn[i]:.0f} deg (direction "
                f"reversal; at most {MAX_WAYPOINT_TURN_DEG:.0f} deg between consecutive chords): "
                "the planner plans forward driving only")
    if length > MAX_PATH_LENGTH_M:
        raise DataFormatError(f"planner: the path is {length:.3g} m long; at most "
                              f"{MAX_PATH_LENGTH_M:.0f} m (check the units: metres expected)")


def _check_samples(n: float, what: str) -> None:
    if not n <= MAX_SAMPLES:
        raise DataFormatError(
            f"planner: {what} gives {n:.3g} samples, more than the limit of {MAX_SAMPLES:,}: "
            "raise --dt or --v-max, or shorten the path")


@dataclass(frozen=True)
class PathGeometry:
    """A path on a uniform arc-length grid (the paper's scenario).

    Attributes:
        s: (m,) arc length [m], from 0 to ``length``.
        x: (m,) position X [m].
        y: (m,) position Y [m].
        heading: (m,) tangent direction [rad], unwrapped.
        kappa: (m,) curvature [1/m] (positive turning left).
        closed: the path is a closed loop (s = length is s = 0).
        v_cap: (m,) speed cap along the path [m/s], or None.
    """

    s: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    heading: NDArray[np.float64]
    kappa: NDArray[np.float64]
    closed: bool
    v_cap: NDArray[np.float64] | None = None

    @property
    def length(self) -> float:
        """Path length [m]."""
        return float(self.s[-1])

    @property
    def turn(self) -> float:
        """Heading gain over one closed lap [rad] (a whole number of turns; 0 when open)."""
        if not self.closed:
            return 0.0
        return 2 * np.pi * np.round((self.heading[-1] - self.heading[0]) / (2 * np.pi))

    def heading_at(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Heading at arc lengths s; closed paths wrap (adding whole turns), open paths hold the
        end headings (straight continuation)."""
        if self.closed:
            lap = np.floor(s / self.length)
            return np.interp(s - lap * self.length, self.s, self.heading) + lap * self.turn
        return np.interp(s, self.s, self.heading)

    def kappa_at(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Curvature at arc lengths s (wrapped for closed paths, 0 past the ends of open ones)."""
        if self.closed:
            return np.interp(np.mod(s, self.length), self.s, self.kappa)
        return np.interp(s, self.s, self.kappa, left=0.0, right=0.0)

    def point_at(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, 2) positions at arc lengths s (wrapped when closed; extrapolated straight when open)."""
        if self.closed:
            ss = np.mod(s, self.length)
            return np.stack([np.interp(ss, self.s, self.x), np.interp(ss, self.s, self.y)], axis=1)
        p = np.stack([np.interp(s, self.s, self.x), np.interp(s, self.s, self.y)], axis=1)
        for mask, i in ((s < 0, 0), (s > self.length, -1)):
            if np.any(mask):
                d = s[mask] - self.s[i]
                h = self.heading[i]
                p[mask] = np.stack([self.x[i] + d * np.cos(h), self.y[i] + d * np.sin(h)], axis=1)
        return p


def _spline(waypoints: NDArray[np.float64], closed: bool) -> tuple[CubicSpline, float]:
    pts = waypoints
    if closed and np.hypot(*(pts[0] - pts[-1])) > 1e-9:
        pts = np.vstack([pts, pts[:1]])
    elif closed:
        pts = pts.copy()
        pts[-1] = pts[0]  # exact closure for the periodic spline
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-9])
    pts = pts[keep]
    u = np.concatenate([[0.0], np.cumsum(seg[seg > 1e-9])])
    if pts.shape[0] < (4 if closed else 2):
        raise DataFormatError("planner: need at least 2 distinct waypoints (3 for a closed lap)")
    return CubicSpline(u, pts, bc_type="periodic" if closed else "natural"), float(u[-1])


def path_geometry(
    waypoints: ArrayLike, *, closed: bool = False, ds: float = DS, v_cap: ArrayLike | None = None,
) -> PathGeometry:
    """Cubic spline through ``waypoints`` (n, 2) [m] on a uniform arc-length grid of step ≈ ds.

    ``v_cap`` (n,) [m/s], optional: a speed cap on the stretch from each waypoint to the next.
    """
    wp = np.asarray(waypoints, dtype=float)
    if wp.ndim != 2 or wp.shape[1] != 2 or not np.all(np.isfinite(wp)):
        raise DataFormatError("planner: waypoints must be a finite (n, 2) array of x, y [m]")
    caps = None
    if v_cap is not None:
        caps = np.asarray(v_cap, dtype=float).reshape(-1)
        if caps.size != wp.shape[0] or np.any(~(caps > 0)):
            raise DataFormatError("planner: v_cap needs one positive speed [m/s] per waypoint")
        if np.any(np.hypot(*np.diff(wp, axis=0).T) <= 1e-9):
            raise DataFormatError("planner: v_cap needs distinct consecutive waypoints")
    sp, L = _spline(wp, closed)
    u = np.linspace(0.0, L, max(int(L / (ds / 4)), 50))
    d1 = sp(u, 1)
    speed = np.hypot(d1[:, 0], d1[:, 1])
    s_u = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))])
    n = max(int(np.ceil(s_u[-1] / ds)), 8)
    s = np.linspace(0.0, s_u[-1], n + 1)
    uu = np.interp(s, s_u, u)
    p, d1, d2 = sp(uu), sp(uu, 1), sp(uu, 2)
    norm = np.maximum(np.hypot(d1[:, 0], d1[:, 1]), 1e-12)
    kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / norm**3
    heading = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
    cap_s = None
    if caps is not None:
        # The spline knots are the waypoints (chord parameter u): cap i holds on [u_i, u_{i+1}).
        knots = sp.x
        cap_s = caps[np.clip(np.searchsorted(knots, uu, side="right") - 1, 0, caps.size - 1)]
    return PathGeometry(s=s, x=p[:, 0], y=p[:, 1], heading=heading, kappa=kappa, closed=closed,
                        v_cap=cap_s)


@dataclass(frozen=True)
class SpeedProfile:
    """Speed along the path (the paper's scenario).

    Attributes:
        s: (m,) arc length [m], uniform, from 0 to the path length.
        v: (m,) speed [m/s]; v² is linear between samples (constant acceleration per interval).
    """

    s: NDArray[np.float64]
    v: NDArray[np.float64]


def _passes(ub: NDArray[np.float64], h: float, a_lon: float, a_brk: float, closed: bool,
            b0: float | None) -> NDArray[np.float64]:
    """Forward/backward passes: the pointwise-largest sequence with bounded differences."""
    b = ub.copy()
    n = b.size
    for _ in range(3 if closed else 1):  # closed: a few sweeps settle the wrap-around
        if b0 is not None:
            b[0] = min(b[0], b0)
        elif closed:
            b[0] = min(b[0], b[-1] + 2 * a_lon * h)
        for i in range(n - 1):
            b[i + 1] = min(b[i + 1], b[i] + 2 * a_lon * h)
        if closed:
            b[-1] = min(b[-1], b[0] + 2 * a_brk * h)
        for i in range(n - 2, -1, -1):
            b[i] = min(b[i], b[i + 1] + 2 * a_brk * h)
    return b


def _window_max(s: NDArray[np.float64], f: NDArray[np.float64], centres: NDArray[np.float64],
                half: float, closed: bool) -> NDArray[np.float64]:
    """max f over [c − half, c + half] for each centre (wrapped when closed)."""
    ds = float(s[1] - s[0])
    w = int(np.ceil(half / ds)) + 1
    i = np.rint(centres / ds).astype(int)
    offs = np.arange(-w, w + 1)
    j = i[:, None] + offs[None, :]
    j = np.mod(j, s.size - 1) if closed else np.clip(j, 0, s.size - 1)
    return f[j].max(axis=1)


def speed_profile(
    geo: PathGeometry, settings: PlannerSettings, *, omega_max: float | None = None,
    jerk_max: float = JERK_MAX, h: float = DS_SPEED, oversample: int = 8,
) -> SpeedProfile:
    """Speed profile within every limit of ``settings`` on the path ``geo`` (the paper's scenario).

    v²(s) is a uniform quadratic B-spline of knot step ≈ h whose control points c are the
    variables of a linear programme (maximise Σc). The spline's convex-hull property makes the
    bounds exact everywhere, not only at nodes: v² ≤ c ≤ the v_max / a_lat / ω_max limit over the
    control point's support; ½ d(v²)/ds = a is piecewise linear in s (continuous) and is a convex
    combination of control-point differences, which are bounded by a_lon and a_brake; da/ds is
    their second difference, bounded by jerk_max / v (soft: a curvature spike sharper than the
    jerk bound allows would otherwise force the speed to 0). Open paths start at
    ``settings.v_start`` (or slower if a curve demands it) and end with zero acceleration.
    """
    from scipy.optimize import linprog
    from scipy.sparse import diags, eye, hstack, vstack

    L = geo.length
    m = max(int(np.ceil(L / h)), 4)
    h = L / m
    closed = geo.closed
    nc = m if closed else m + 2
    # Control point i acts on [s_{i−2}, s_{i+1}]: centre (i − ½)h, half-width 1.5h.
    centres = (np.arange(nc, dtype=np.float64) - 0.5) * h
    k = np.maximum(_window_max(geo.s, np.abs(geo.kappa), np.mod(centres, L) if closed
                               else np.clip(centres, 0, L), 1.5 * h, closed), 1e-9)
    ub = np.minimum(settings.v_max**2, settings.a_lat_max / k)
    if geo.v_cap is not None:
        cap = -_window_max(geo.s, -geo.v_cap, np.mod(centres, L) if closed else np.clip(centres, 0, L),
                           1.5 * h, closed)
        ub = np.minimum(ub, cap**2)
    if omega_max is not None:
        ub = np.minimum(ub, (omega_max / k) ** 2)
    a_lon, a_brk = settings.a_lon_max, settings.a_brake_max
    b0 = None if closed else min(settings.v_start**2, ub[0], ub[1])
    upper = _passes(ub, h, a_lon, a_brk, closed, b0)
    # (pyright: scipy annotates diags' offsets as an int; its documented API takes a sequence)
    if closed:
        d1 = diags([-np.ones(nc), np.ones(nc - 1), [1.0]], [0, 1, -(nc - 1)], shape=(nc, nc))  # pyright: ignore[reportArgumentType]
        d2 = diags([np.ones(nc), -2 * np.ones(nc - 1), [-2.0], np.ones(nc - 2), [1.0, 1.0]],
                   [0, 1, -(nc - 1), 2, -(nc - 2)], shape=(nc, nc))  # pyright: ignore[reportArgumentType]
        vseg = np.sqrt(np.maximum.reduce([upper, np.roll(upper, -1), np.roll(upper, -2)]))
    else:
        d1 = diags([-np.ones(nc - 1), np.ones(nc - 1)], [0, 1], shape=(nc - 1, nc))  # pyright: ignore[reportArgumentType]
        d2 = diags([np.ones(nc - 2), -2 * np.ones(nc - 2), np.ones(nc - 2)], [0, 1, 2], shape=(nc - 2, nc))  # pyright: ignore[reportArgumentType]
        vseg = np.sqrt(np.maximum.reduce([upper[:-2], upper[1:-1], upper[2:]]))
    m1, m2 = d1.shape[0], d2.shape[0]  # pyright: ignore[reportOptionalSubscript]  # (scipy: shape Optional)
    # The pass profile bounds v from above, so jerk/upper is a conservative bound on da/ds.
    jrow = 2 * h * h * jerk_max / np.maximum(vseg, 1e-3)
    z1 = np.zeros((m1, m2))
    A = vstack([hstack([d1, z1]), hstack([-d1, z1]),
                hstack([d2, -eye(m2)]), hstack([-d2, -eye(m2)])]).tocsr()
    rhs = np.concatenate([np.full(m1, 2 * a_lon * h), np.full(m1, 2 * a_brk * h), jrow, jrow])
    # A crawl floor (0.5 m/s unless the limits demand less) keeps the lap time finite.
    bounds = np.concatenate([np.stack([np.minimum(upper, 0.25), upper], axis=1),
                             np.tile([0.0, np.inf], (m2, 1))])
    A_eq = b_eq = None
    if b0 is not None:
        # v²(0) = (c0 + c1)/2 = v_start²; zero acceleration at the end (c_{m+1} = c_m).
        A_eq = np.zeros((2, nc + m2))
        A_eq[0, :2] = 0.5
        A_eq[1, nc - 2], A_eq[1, nc - 1] = 1.0, -1.0
        b_eq = np.array([b0, 0.0])
    cost = np.concatenate([-np.ones(nc), np.full(m2, 1e4)])
    res = linprog(cost, A_ub=A, b_ub=rhs, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if res.status != 0:
        raise SolverError(f"planner: speed-profile LP failed ({res.message}); "
                          "check that the limits allow the start speed")
    c = np.clip(res.x[:nc], 0.0, upper)
    # Evaluate the spline: on segment j with u ∈ [0, 1), b = ½(1−u)² c_j + (½ + u − u²) c_{j+1} + ½u² c_{j+2}.
    q = m * oversample
    u_all = np.arange(q + 1) / oversample
    j = np.minimum(np.floor(u_all).astype(int), m - 1)
    u = u_all - j
    cj = (lambda i: c[np.mod(i, nc)]) if closed else (lambda i: c[i])
    b = 0.5 * (1 - u) ** 2 * cj(j) + (0.5 + u - u * u) * cj(j + 1) + 0.5 * u * u * cj(j + 2)
    return SpeedProfile(s=u_all * h, v=np.sqrt(np.maximum(b, 0.0)))


def integrate_pose(
    x0: float, y0: float, th0: float, v: NDArray[np.float64], omega: NDArray[np.float64], dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The paper's convention: θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T."""
    th = th0 + np.concatenate([[0.0], np.cumsum(omega[1:] * dt)])
    x = x0 + np.concatenate([[0.0], np.cumsum(v[1:] * np.cos(th[1:]) * dt)])
    y = y0 + np.concatenate([[0.0], np.cumsum(v[1:] * np.sin(th[1:]) * dt)])
    return x, y, th


def _speed_at_times(s_n: NDArray[np.float64], b_n: NDArray[np.float64],
                    t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Exact v(t) when v² is linear in s between nodes (constant acceleration per segment)."""
    v_n = np.sqrt(b_n)
    dt_seg = 2 * np.diff(s_n) / np.maximum(v_n[1:] + v_n[:-1], 1e-12)
    t_n = np.concatenate([[0.0], np.cumsum(dt_seg)])
    i = np.clip(np.searchsorted(t_n, t, side="right") - 1, 0, s_n.size - 2)
    a = (b_n[i + 1] - b_n[i]) / (2 * np.diff(s_n)[i])
    tau = t - t_n[i]
    v = v_n[i] + a * tau
    past = t > t_n[-1]
    v[past] = v_n[-1]
    return np.maximum(v, 0.0)


def plan_path(
    waypoints: ArrayLike, settings: PlannerSettings, *, closed: bool = False, dt: float = 0.1,
    laps: int = 1, tail_s: float = 0.0, omega_max: float | None = None, jerk_max: float = JERK_MAX,
    v_cap: ArrayLike | None = None,
) -> Reference:
    """Plan a reference through ``waypoints`` (n, 2) [m] (the paper's scenario).

    Args:
        waypoints: points of the path, in driving order (a closed lap need not repeat the first).
        settings: speed and acceleration limits.
        closed: a closed lap (periodic spline and speed profile, flying start); the lap time is
            rounded up to a whole number of samples (speeds scaled down by < dt/T_lap) so that the
            reference repeats every ``len/laps`` samples.
        dt: sample time of the output [s].
        laps: number of laps (closed paths only).
        tail_s: extra time at the end [s] so an MPC has its look-ahead: closed paths continue
            along the lap, open paths drive straight on at the final speed.
        omega_max: optional yaw-rate limit |ω_d| ≤ omega_max [rad/s].
        jerk_max: bound on |dv_d/dt| rate of change [m/s³] (keeps the acceleration continuous).
        v_cap: optional (n,) speed cap [m/s] on the stretch from each waypoint to the next.

    Returns:
        A :class:`Reference` with ``closed`` set for a closed path without tail.
    """
    if laps < 1 or (laps > 1 and not closed):
        raise DataFormatError("planner: laps must be ≥ 1, and > 1 only for closed paths")
    if not (np.isfinite(dt) and dt > 0) or not (np.isfinite(tail_s) and tail_s >= 0):
        raise DataFormatError(f"planner: dt must be positive and finite (got {dt}) and tail_s "
                              f"finite and >= 0 (got {tail_s})")
    wp = np.asarray(waypoints, dtype=float)
    if wp.ndim != 2 or wp.shape[1] != 2 or not np.all(np.isfinite(wp)):
        raise DataFormatError("planner: waypoints must be a finite (n, 2) array of x, y [m]")
    check_waypoints(wp, closed)
    chord = float(np.sum(np.hypot(*np.diff(wp, axis=0).T)))
    # The car is never faster than v_max: a lower bound on the samples, checked before any work.
    _check_samples(laps * chord / (settings.v_max * dt) + tail_s / dt,
                   f"a {chord:.0f} m path at <= {settings.v_max:g} m/s every dt = {dt:g} s")
    geo = path_geometry(wp, closed=closed, v_cap=v_cap)
    L = geo.length
    prof = speed_profile(geo, settings, omega_max=omega_max, jerk_max=jerk_max)
    s_n, v_n = prof.s, prof.v
    T_lap = float(np.sum(2 * np.diff(s_n) / np.maximum(v_n[1:] + v_n[:-1], 1e-12)))
    b = v_n**2
    n_lap = 0  # (closed paths: samples per lap)
    if closed:
        n_lap = int(np.ceil(T_lap / dt - 1e-9))
        b = b * (T_lap / (n_lap * dt)) ** 2  # slower by < one sample per lap: limits still hold
        n_main = laps * n_lap
    else:
        n_main = int(np.floor(T_lap / dt)) + 1
    _check_samples(n_main + tail_s / dt, f"a lap time of {T_lap:.4g} s every dt = {dt:g} s")
    n = n_main + int(np.ceil(tail_s / dt - 1e-9))
    t = np.arange(n, dtype=np.float64) * dt
    if closed:
        reps = int(np.ceil(t[-1] / (n_lap * dt))) + 1
        s_ext = np.concatenate([s_n[:-1] + r * L for r in range(reps)] + [[reps * L]])
        b_ext = np.concatenate([b[:-1]] * reps + [b[:1]])
    else:
        s_ext, b_ext = s_n, b
    v = _speed_at_times(s_ext, b_ext, t)
    # The pose by the paper's own recursion; the arc length advances by v(k)·dt.
    s_k = np.concatenate([[0.0], np.cumsum(v[1:] * dt)])
    mid = np.concatenate([[-0.5 * v[0] * dt], 0.5 * (s_k[1:] + s_k[:-1])])
    theta = geo.heading_at(mid)
    omega = np.concatenate([[v[0] * float(geo.kappa_at(np.zeros(1))[0])], np.diff(theta) / dt])
    turn = np.abs(np.diff(theta))
    if turn.size and turn.max() > MAX_HEADING_STEP_RAD:  # a polygon, not a path (issue 24)
        fine = dt * MAX_HEADING_STEP_RAD / float(turn.max())
        unit = 10.0 ** (np.floor(np.log10(fine)) - 1)  # two significant digits, rounded down
        raise DataFormatError(
            f"planner: dt = {dt:g} s is too coarse for this path: the heading turns "
            f"{turn.max():.3g} rad between two samples (at most {MAX_HEADING_STEP_RAD:g}); "
            f"use --dt <= {np.floor(fine / unit) * unit:.2g}")
    kappa = np.where(v > 1e-6, omega / np.maximum(v, 1e-6), geo.kappa_at(s_k))
    x, y, _ = integrate_pose(float(geo.x[0]), float(geo.y[0]), float(theta[0]), v, omega, dt)
    return Reference(t=t, x=x, y=y, theta=theta, v=v, omega=omega, kappa=kappa,
                     closed=closed and n == n_main)
