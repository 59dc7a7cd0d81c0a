"""The single-track model's arithmetic, written once (issue 34): the right-hand side of the plant
(:func:`plant_rhs`; the equations are in :mod:`tsmpc.vehicle.plant`'s docstring), its RK4 steps
(:func:`rk4_steps`) and the friction force the models see (:func:`friction_force`), ``@jitable``
blocks over the record :class:`PlantParams`.

:class:`~tsmpc.vehicle.plant.Plant` and :class:`~tsmpc.vehicle.plant.VehiclePlant` call them as
Python (no compiled kernels); :func:`tsmpc.kernels.plant.rk4_block` compiles them (the Python loop
with the kernels on, the run engine, the batch's exact path), and the engine logs the friction
force by the same function. The batch's lane-vectorised RK4 (``tsmpc.kernels.batch.rk4_lanes``) is
the only second form, pure arithmetic, compared with this one on random inputs
(tests/test_plant_block.py). A module of its own: the blocks import numba (compiled callers), which
``import tsmpc.vehicle.plant`` does not.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from tsmpc.config import TyreModel, TyreParams, VehicleParams
from tsmpc.kernels.jit import jitable

__all__ = ["PlantParams", "friction_force", "plant_params", "plant_rhs", "rk4_steps"]


class PlantParams(NamedTuple):
    """The plant's constants, read by :func:`plant_rhs` (:func:`plant_params` builds them; the
    compiled kernels carry them as a float vector in this order, ``tsmpc.kernels.plant.pack``).

    Attributes:
        mass: M [kg].
        inertia: I [kg m²].
        a: CoG to front axle [m].
        b: CoG to rear axle [m].
        C_f: front cornering stiffness [N/rad].
        drag: ½ρC_dA_r [kg/m].
        v_floor: speed floor of every 1/v [m/s].
        v_eps: speed scale of the resistance's tanh [m/s].
        mg: M g [N].
        fz_f: static front axle load [N].
        fz_r: static rear axle load [N].
        shape_c: Pacejka shape factor C.
        curvature_e: Pacejka curvature factor E.
        mu_tyre: the tyre's friction coefficient μ_tyre.
        grip_scale: μ_tyre / μ_dry when the grip follows the road (μ_t = μ(road) grip_scale), else 0.
        linear: linear tyres (else Pacejka).
        C_r: rear cornering stiffness [N/rad].
        combined: the rear tyre's friction ellipse (Pacejka tyres only).
    """

    mass: float
    inertia: float
    a: float
    b: float
    C_f: float
    drag: float
    v_floor: float
    v_eps: float
    mg: float
    fz_f: float
    fz_r: float
    shape_c: float
    curvature_e: float
    mu_tyre: float
    grip_scale: float
    linear: bool
    C_r: float
    combined: bool


def plant_params(vehicle: VehicleParams, tyre: TyreParams, v_floor: float = 0.5, v_eps: float = 0.05
                 ) -> PlantParams:
    """The record of a plant with these parameters (``v_floor``, ``v_eps``: the low-speed
    regularisation, :class:`~tsmpc.vehicle.plant.PlantConstants`)."""
    fzf, fzr = vehicle.static_loads
    linear = tyre.model == TyreModel.LINEAR
    return PlantParams(
        vehicle.mass, vehicle.inertia, vehicle.a, vehicle.b, vehicle.C_f, vehicle.drag_factor,
        v_floor, v_eps, vehicle.mass * vehicle.g, fzf, fzr, tyre.shape_c,
        tyre.curvature_e, tyre.mu_tyre, tyre.mu_tyre / tyre.mu_dry if tyre.scale_grip_with_road else 0.0,
        linear, vehicle.C_r, bool(tyre.combined_slip) and not linear)


@jitable
def plant_rhs(p: PlantParams, th: float, v: float, al: float, om: float, F: float, d: float, mu: float,
              cosd: float) -> tuple[float, float, float, float, float, float]:
    """ẋ = f(x, u, μ) (the module docstring's equations) at heading θ, speed v, slip α, yaw rate
    ω (X, Y do not enter), input (F_xR, δ), μ(road); ``cosd`` = cos δ (constant over a step)."""
    M, I, a, b, Cf, kd, v_floor, v_eps, Mg, fzf, fzr, cc, ee, mu_t0, scale, linear, Cr, combined = p
    ve = v if v > v_floor else v_floor
    sa, ca = math.sin(al), math.cos(al)
    f_res = mu * Mg * math.tanh(v / v_eps)
    if linear:
        fyf = Cf * (d - al - a * om / ve)
        fyr = Cr * (b * om / ve - al)
    else:
        vx, vy = ve * ca, ve * sa
        mu_t = mu * scale if scale else mu_t0
        Df, Dr = mu_t * fzf, mu_t * fzr
        if Df > 0.0:
            bs = Cf / (cc * Df) * (math.atan2(vy + a * om, vx) - d)
            fyf = -Df * math.sin(cc * math.atan(bs - ee * (bs - math.atan(bs))))
            bs = Cr / (cc * Dr) * math.atan2(vy - b * om, vx)
            fyr = -Dr * math.sin(cc * math.atan(bs - ee * (bs - math.atan(bs))))
        else:
            fyf = 0.0
            fyr = 0.0
        if combined:  # friction ellipse of the driven (rear) tyre; see the module docstring
            ft = F - f_res
            if Dr > 0.0:
                ft = -Dr if ft < -Dr else (Dr if ft > Dr else ft)
                rr = ft / Dr
                fyr *= math.sqrt(1.0 - rr * rr)
            else:
                ft = 0.0
            F = ft  # the body sees the traction; the resistance is inside it
            f_res = 0.0
    sda, cda = math.sin(d - al), math.cos(d - al)
    vdot = (F * ca - fyf * sda + fyr * sa - kd * v * v - f_res) / M
    adot = (-F * sa + fyf * cda + fyr * ca) / (M * ve) - om
    wdot = (a * fyf * cosd - b * fyr) / I
    return v * math.cos(th + al), v * math.sin(th + al), om, vdot, adot, wdot


@jitable
def rk4_steps(p: PlantParams, X: float, Y: float, th: float, v: float, al: float, om: float, F: float,
              d: float, mu: float, n: int, h: float) -> tuple[float, float, float, float, float, float]:
    """``n`` classical RK4 steps of length h from [X, Y, θ, v, α, ω] with (F_xR, δ) and μ(road)
    held (no finiteness test: the callers make it)."""
    h2 = 0.5 * h
    h6 = h / 6.0
    cosd = math.cos(d)
    for _ in range(n):
        a1, b1, c1, d1, e1, g1 = plant_rhs(p, th, v, al, om, F, d, mu, cosd)
        a2, b2, c2, d2, e2, g2 = plant_rhs(p, th + h2 * c1, v + h2 * d1, al + h2 * e1, om + h2 * g1, F, d, mu,
                                           cosd)
        a3, b3, c3, d3, e3, g3 = plant_rhs(p, th + h2 * c2, v + h2 * d2, al + h2 * e2, om + h2 * g2, F, d, mu,
                                           cosd)
        a4, b4, c4, d4, e4, g4 = plant_rhs(p, th + h * c3, v + h * d3, al + h * e3, om + h * g3, F, d, mu,
                                           cosd)
        X += h6 * (a1 + 2.0 * (a2 + a3) + a4)
        Y += h6 * (b1 + 2.0 * (b2 + b3) + b4)
        th += h6 * (c1 + 2.0 * (c2 + c3) + c4)
        v += h6 * (d1 + 2.0 * (d2 + d3) + d4)
        al += h6 * (e1 + 2.0 * (e2 + e3) + e4)
        om += h6 * (g1 + 2.0 * (g2 + g3) + g4)
    return X, Y, th, v, al, om


@jitable
def friction_force(mu_nominal: float, mg: float, mu_road: float) -> float:
    """The friction disturbance the models see, F_fr = (μ(road) − μ_o) M g [N] (``mg`` = M g)."""
    return (mu_road - mu_nominal) * mg
