"""Exact planar motion for the course-fusion tests: the velocity's heading θ + α turns at ω over a
step (α constant), so the positions are what a real car at that slip would measure."""

from __future__ import annotations

import math


def arc_step(X: float, Y: float, th: float, v: float, w: float, alpha: float,
             dt: float) -> tuple[float, float, float]:
    """(X, Y, θ) after ``dt`` at speed v, yaw rate ω and constant slip α."""
    chi0 = th + alpha
    th += w * dt
    chi1 = th + alpha
    if abs(w) > 1e-12:
        X += v / w * (math.sin(chi1) - math.sin(chi0))
        Y += -v / w * (math.cos(chi1) - math.cos(chi0))
    else:
        X += v * math.cos(chi0) * dt
        Y += v * math.sin(chi0) * dt
    return X, Y, th
