"""Plant block: the T_d/h RK4 steps of :class:`tsmpc.vehicle.plant.Plant` between two inner steps in
one compiled call (linear and Pacejka tyres). Same right-hand side, same operation order as the
float closure of ``Plant._make_rhs`` (the plant model), so the two agree to rounding (tested ≤ 1e-10)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["pack", "rk4_block", "warm"]

# Layout of the constants vector (see pack()).
_M, _I, _A, _B, _CF, _KD, _VF, _VE, _MG, _FZF, _FZR, _CC, _EE, _MUT0, _SCALE, _LIN, _CR, _COMB = range(18)


def pack(plant) -> np.ndarray:
    """The constants of a :class:`~tsmpc.vehicle.plant.Plant` as the kernel's vector."""
    p, t, k = plant.vehicle, plant.tyre, plant.constants
    fzf, fzr = p.static_loads
    scale = t.mu_tyre / t.mu_dry if t.scale_grip_with_road else 0.0
    # Per-axle cornering stiffness where the parameters have it (C_f, C_r), else the paper's one C.
    cf = getattr(p, "C_f", p.cornering_stiffness)
    cr = getattr(p, "C_r", p.cornering_stiffness)
    return np.array([p.mass, p.inertia, p.a, p.b, cf, p.drag_factor, k.v_floor,
                     k.v_eps, p.mass * p.g, fzf, fzr, t.shape_c, t.curvature_e, t.mu_tyre, scale,
                     1.0 if plant._linear else 0.0, cr,
                     1.0 if (getattr(t, "combined_slip", False) and not plant._linear) else 0.0])


@njit(cache=True, fastmath=False, inline="always")
def _rhs(cst, th, v, al, om, F, d, mu, cosd):
    M, I, a, b, Cf, Cr = cst[_M], cst[_I], cst[_A], cst[_B], cst[_CF], cst[_CR]
    v_floor = cst[_VF]
    ve = v if v > v_floor else v_floor
    sa, ca = math.sin(al), math.cos(al)
    f_res = mu * cst[_MG] * math.tanh(v / cst[_VE])
    if cst[_LIN] != 0.0:
        fyf = Cf * (d - al - a * om / ve)
        fyr = Cr * (b * om / ve - al)
    else:
        vx, vy = ve * ca, ve * sa
        scale = cst[_SCALE]
        mu_t = mu * scale if scale else cst[_MUT0]
        Df, Dr = mu_t * cst[_FZF], mu_t * cst[_FZR]
        cc, ee = cst[_CC], cst[_EE]
        if Df > 0.0:
            bs = Cf / (cc * Df) * (math.atan2(vy + a * om, vx) - d)
            fyf = -Df * math.sin(cc * math.atan(bs - ee * (bs - math.atan(bs))))
            bs = Cr / (cc * Dr) * math.atan2(vy - b * om, vx)
            fyr = -Dr * math.sin(cc * math.atan(bs - ee * (bs - math.atan(bs))))
        else:
            fyf = 0.0
            fyr = 0.0
        if cst[_COMB] != 0.0:  # friction ellipse of the rear tyre (as Plant._make_rhs)
            ft = F - f_res
            if Dr > 0.0:
                ft = -Dr if ft < -Dr else (Dr if ft > Dr else ft)
                rr = ft / Dr
                fyr *= math.sqrt(1.0 - rr * rr)
            else:
                ft = 0.0
            F = ft
            f_res = 0.0
    sda, cda = math.sin(d - al), math.cos(d - al)
    vdot = (F * ca - fyf * sda + fyr * sa - cst[_KD] * v * v - f_res) / M
    adot = (-F * sa + fyf * cda + fyr * ca) / (M * ve) - om
    wdot = (a * fyf * cosd - b * fyr) / I
    return v * math.cos(th + al), v * math.sin(th + al), om, vdot, adot, wdot


@njit(cache=True, fastmath=False)
def rk4_block(x, F, d, mu, n, h, cst):
    """``n`` RK4 steps of length h from x (6,) with u = (F, δ) and μ held; returns (x⁺ (6,), ok) —
    ok False if the input, the state or the result is not finite."""
    out = np.empty(6)
    X, Y, th, v, al, om = x[0], x[1], x[2], x[3], x[4], x[5]
    if not (math.isfinite(X) and math.isfinite(Y) and math.isfinite(th) and math.isfinite(v)
            and math.isfinite(al) and math.isfinite(om) and math.isfinite(F) and math.isfinite(d)
            and math.isfinite(mu)):
        out[:] = x
        return out, False
    h2 = 0.5 * h
    h6 = h / 6.0
    cosd = math.cos(d)
    for _ in range(n):
        a1, b1, c1, d1, e1, g1 = _rhs(cst, th, v, al, om, F, d, mu, cosd)
        a2, b2, c2, d2, e2, g2 = _rhs(cst, th + h2 * c1, v + h2 * d1, al + h2 * e1, om + h2 * g1, F, d, mu,
                                      cosd)
        a3, b3, c3, d3, e3, g3 = _rhs(cst, th + h2 * c2, v + h2 * d2, al + h2 * e2, om + h2 * g2, F, d, mu,
                                      cosd)
        a4, b4, c4, d4, e4, g4 = _rhs(cst, th + h * c3, v + h * d3, al + h * e3, om + h * g3, F, d, mu,
                                      cosd)
        X += h6 * (a1 + 2.0 * (a2 + a3) + a4)
        Y += h6 * (b1 + 2.0 * (b2 + b3) + b4)
        th += h6 * (c1 + 2.0 * (c2 + c3) + c4)
        v += h6 * (d1 + 2.0 * (d2 + d3) + d4)
        al += h6 * (e1 + 2.0 * (e2 + e3) + e4)
        om += h6 * (g1 + 2.0 * (g2 + g3) + g4)
    out[0], out[1], out[2], out[3], out[4], out[5] = X, Y, th, v, al, om
    ok = (math.isfinite(X) and math.isfinite(Y) and math.isfinite(th) and math.isfinite(v)
          and math.isfinite(al) and math.isfinite(om))
    return out, ok


def warm() -> None:
    """Compile (or load from the cache) the signature the plant uses."""
    cst = np.array([683.0, 560.0, 0.7, 1.0, 25000.0, 0.4, 0.5, 0.05, 6700.0, 3800.0, 2900.0, 1.3, -1.0,
                    0.9, 0.0, 0.0, 25000.0, 0.0])
    rk4_block(np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]), 100.0, 0.01, 0.9, 2, 0.001, cst)
