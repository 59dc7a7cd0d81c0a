"""Reference windows with closed-form geometry for the geometric baselines' tests (not a test module)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np


def circle_window(R: float, v: float, Tc: float, n: int, *, left: bool = True,
                  tangent_convention: bool = True) -> SimpleNamespace:
    """n samples of a circle of radius R driven at speed v from the origin heading east (centre
    (0, ±R)). ``tangent_convention``: θ_d is the heading of the step *into* each sample (the paper
    planner's convention, SPEC §10; the path tangent is θ_d + ω_d T_c / 2), else the tangent itself."""
    sgn = 1.0 if left else -1.0
    ds = v * Tc
    phi = np.arange(n) * ds / R
    x, y = R * np.sin(phi), sgn * R * (1.0 - np.cos(phi))
    tangent = sgn * phi
    dphi = sgn * ds / R
    theta = tangent - 0.5 * dphi if tangent_convention else tangent
    return SimpleNamespace(x=x, y=y, theta=theta, v=np.full(n, v), omega=np.full(n, sgn * v / R),
                           kappa=np.full(n, sgn / R))


def straight_window(v: float, Tc: float, n: int) -> SimpleNamespace:
    """n samples of the x-axis driven eastwards at speed v."""
    x = np.arange(n) * v * Tc
    z = np.zeros(n)
    return SimpleNamespace(x=x, y=z.copy(), theta=z.copy(), v=np.full(n, v), omega=z.copy(), kappa=z.copy())
