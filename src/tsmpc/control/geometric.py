"""What the geometric path-tracking baselines share (pure pursuit, Stanley; issue 26): the vehicle's
pose recovered from the outer loop's errors, the reference window as a polyline (nearest point,
look-ahead point), the one conversion from a path curvature to the yaw-rate command, and the
speed channel.

**Pose.** The outer loop hands every method the same errors ``[e_x, e_y, e_θ]`` of the
pose it tracks against reference sample k (the velocity pose under the slip-aware outer loop,
whose heading is the direction of travel; see :mod:`tsmpc.control.slip_aware`). With the
reference heading θ_d' the errors were taken against, the pose is
θ = θ_d' − e_θ, (X, Y) = (x_d, y_d) − R(θ) [e_x, e_y]. θ_d' is what the cascade used
(:func:`reference_heading`): the path's tangent at the sample under ``mpc.tangent_heading``, else
the sample's θ_d. The window the MPC receives carries exactly that heading in the default
configuration (``mpc.step_average_reference``: its θ are the tangents) and in the paper preset
(neither switch: the raw θ_d); with the tangent heading but raw windows, the tangent is measured
on the window (:meth:`tsmpc.planning.reference.Reference.tangent_heading`). A heading off by
ω_d T_c / 2 (0.01 rad) would bias a pure pursuit's curvature by 2 · 0.01 / L_d.

**Curvature to yaw rate (the one conversion).** A geometric law yields a path curvature κ (pure
pursuit directly; Stanley through the kinematic bicycle κ = tan δ / L, :func:`curvature_of_steering`).
The inner loop takes a yaw rate: ω_ref = v_ref κ (:func:`yaw_rate_command`) — the yaw rate at which
a point moving at v_ref along its heading turns with curvature κ; no other place converts.

**Speed channel.** Geometric laws steer only. Their speed command is
v_ref = v_d(k) cos e_θ + k_s e_x (:func:`speed_command`): a *feed-forward* of the reference speed
(the kinematic error model's equilibrium input) plus proportional *feedback* on the
along-track error e_x, gain ``baselines.along_track_gain``. The inner loop's own speed-error
feedback then tracks v_ref, exactly as it tracks the MPC's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "PathPoint",
    "curvature_of_steering",
    "lookahead_point",
    "nearest_point",
    "reference_heading",
    "speed_command",
    "vehicle_pose",
    "yaw_rate_command",
]


def reference_heading(window: Any, tangent_heading: bool, step_average: bool) -> float:
    """θ_d' [rad] the outer loop's errors were taken against at the window's first sample, for the
    switches ``mpc.tangent_heading`` and ``mpc.step_average_reference`` (module docstring)."""
    th = float(window.theta[0])
    if tangent_heading and not step_average and hasattr(window, "tangent_heading"):
        th = float(window.tangent_heading()[0])
    return th


def vehicle_pose(errors: NDArray[np.float64], window: Any, heading: float) -> tuple[float, float, float]:
    """(X, Y, θ) of the pose whose errors against the window's first sample (x_d, y_d) with
    reference heading ``heading`` (:func:`reference_heading`) are ``errors``."""
    e_x, e_y, e_th = (float(v) for v in errors)
    th = float(heading) - e_th
    c, s = math.cos(th), math.sin(th)
    return float(window.x[0]) - (c * e_x - s * e_y), float(window.y[0]) - (s * e_x + c * e_y), th


@dataclass(frozen=True)
class PathPoint:
    """The point of the reference polyline nearest to a query point.

    Attributes:
        x: the point's x [m].
        y: the point's y [m].
        heading: the path's tangent there [rad] (vertex tangents interpolated along the segment).
        kappa: the reference curvature there [1/m] (interpolated along the segment).
        offset: signed distance of the query point from the path [m], positive to the left of it.
        segment: index i of the segment (samples i, i+1).
        t: position along the segment in [0, 1] (beyond on the first and last segments: the path
            extended along them).
    """

    x: float
    y: float
    heading: float
    kappa: float
    offset: float
    segment: int
    t: float


def _vertex_tangents(xs: NDArray[np.float64], ys: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tangent angle at each vertex: the mean direction of the chords meeting there (ends: their chord)."""
    ch = np.arctan2(np.diff(ys), np.diff(xs))
    ch = np.unwrap(ch)
    tan = np.empty(xs.size)
    tan[0], tan[-1] = ch[0], ch[-1]
    tan[1:-1] = 0.5 * (ch[:-1] + ch[1:])
    return tan


def nearest_point(
    px: float, py: float, xs: NDArray[np.float64], ys: NDArray[np.float64],
    kappa: NDArray[np.float64] | None = None,
) -> PathPoint:
    """Nearest point of the polyline (xs, ys) (n ≥ 2 samples) to (px, py). The first and last
    segments extend beyond their ends, so a point behind the window's start (or past its end)
    projects onto the path's continuation, not onto an end vertex."""
    xs = np.asarray(xs, dtype=float)
    ys = np.asarray(ys, dtype=float)
    dx, dy = np.diff(xs), np.diff(ys)
    L2 = dx * dx + dy * dy
    ok = L2 > 1e-18
    L2s = np.where(ok, L2, 1.0)
    t = np.where(ok, ((px - xs[:-1]) * dx + (py - ys[:-1]) * dy) / L2s, 0.0)
    lo = np.zeros_like(t)
    hi = np.ones_like(t)
    lo[0], hi[-1] = -np.inf, np.inf
    t = np.clip(t, lo, hi)
    qx, qy = xs[:-1] + t * dx, ys[:-1] + t * dy
    d2 = (qx - px) ** 2 + (qy - py) ** 2
    d2 = np.where(ok | (np.arange(t.size) == 0), d2, np.inf)
    i = int(np.argmin(d2))
    ti = float(t[i])
    tangents = _vertex_tangents(xs, ys)
    w = min(max(ti, 0.0), 1.0)
    heading = float((1.0 - w) * tangents[i] + w * tangents[i + 1])
    k = 0.0 if kappa is None else float((1.0 - w) * kappa[i] + w * kappa[i + 1])
    seg = math.atan2(float(dy[i]), float(dx[i]))
    # Signed offset: the query point's side of the segment (+ = left of the direction of travel).
    offset = -math.sin(seg) * (px - float(qx[i])) + math.cos(seg) * (py - float(qy[i]))
    return PathPoint(float(qx[i]), float(qy[i]), heading, k, offset, i, ti)


def lookahead_point(
    px: float, py: float, xs: NDArray[np.float64], ys: NDArray[np.float64], start: PathPoint,
    distance: float,
) -> tuple[float, float]:
    """The first point of the polyline after ``start`` at Euclidean distance ``distance`` from
    (px, py); if the vehicle is farther than that from the path, the distance grows to the nearest
    point's (the goal then lies just ahead on the path); past the window's end, the last sample."""
    xs = np.asarray(xs, dtype=float)
    ys = np.asarray(ys, dtype=float)
    L = max(float(distance), math.hypot(start.x - px, start.y - py))
    # Candidate segments: from the nearest point's segment on; the crossing is where the distance
    # from (px, py) first exceeds L.
    i0 = start.segment
    vx, vy = xs[i0 + 1:] - px, ys[i0 + 1:] - py
    far = np.flatnonzero(vx * vx + vy * vy >= L * L)
    if far.size == 0:
        return float(xs[-1]), float(ys[-1])
    j = i0 + 1 + int(far[0])  # first vertex at distance ≥ L; the crossing is on segment (j−1, j)
    ax, ay = (start.x, start.y) if j - 1 == i0 else (float(xs[j - 1]), float(ys[j - 1]))
    bx, by = float(xs[j]), float(ys[j])
    # |a + τ(b − a) − p|² = L², the larger root in [0, 1] (a is inside the circle, b outside).
    ux, uy = bx - ax, by - ay
    wx, wy = ax - px, ay - py
    A = ux * ux + uy * uy
    if A <= 1e-18:
        return bx, by
    B = 2.0 * (ux * wx + uy * wy)
    C = wx * wx + wy * wy - L * L
    disc = max(B * B - 4.0 * A * C, 0.0)
    tau = min(max((-B + math.sqrt(disc)) / (2.0 * A), 0.0), 1.0)
    return ax + tau * ux, ay + tau * uy


def curvature_of_steering(delta: float, wheelbase: float) -> float:
    """Path curvature of a kinematic bicycle with front steering angle δ: κ = tan δ / L [1/m]."""
    return math.tan(delta) / wheelbase


def yaw_rate_command(v: float, kappa: float) -> float:
    """The one conversion of a geometric law's output into the inner loop's input: ω_ref = v κ
    [rad/s] (a point moving at speed v along a path of curvature κ turns at v κ)."""
    return v * kappa


def speed_command(errors: NDArray[np.float64], v_d: float, gain: float) -> float:
    """v_ref = v_d cos e_θ + gain · e_x: reference-speed feed-forward plus proportional feedback on
    the along-track error (not clipped here)."""
    return v_d * math.cos(float(errors[2])) + gain * float(errors[0])
