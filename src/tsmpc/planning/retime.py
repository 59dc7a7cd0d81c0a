"""Re-timing a reference along its own path (issue 21): the same (x, y) samples, a speed profile
that never asks for more acceleration than a vehicle can give.

A reference planned for one car can be infeasible for another: the paper's run accelerates at up to
4.4 m/s², while a car 20 % heavier has (10 kN − μ M g − drag)/M ≈ 3.4 m/s² left on dry asphalt
(the paper's road resistance μ M g is 7.2 kN there). Tracking such a reference measures the force
limit, not the controller. :func:`retime` keeps the path and lowers the speed profile where the
acceleration limit binds (a forward pass ``w_k = min(v_k, sqrt(w_{k−1}² + 2 a(w_{k−1}) Δs_k))``;
braking is never harder than the original's, since ``w ≤ v`` and w only meets v from below), then
resamples it in time. :func:`retime_for_force_budget` takes the limit from the force budget:
``a(v) = (η F_max − μ M g − ½ρC_dA_r v²)/M`` with the headroom η (90 %: the inner loop keeps room
for its feedback) and, for a plant whose rear tyre has a friction ellipse, a traction of at most
η μ_t F_zR (the grip of the driven axle).

Capping a plan the vehicle cannot drive (issue 36, :mod:`tsmpc.planning.feasibility`): ``retime``
also takes a speed cap per sample (the lateral cap ``v ≤ sqrt(a_lat/|κ|)`` of
:func:`lateral_speed_cap`) and a deceleration limit (:func:`braking_budget_deceleration`): the cap
first, then the forward pass, then a backward pass ``w_k = min(w_k, sqrt(w_{k+1}² + 2 d(w_{k+1})
Δs_{k+1}))`` that brakes before a capped corner instead of arriving too fast.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from tsmpc.config import LQRSettings, TyreParams, VehicleParams
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference

__all__ = ["FORCE_HEADROOM", "braking_budget_deceleration", "force_budget_acceleration",
           "lateral_speed_cap", "path_curvature", "retime", "retime_for_force_budget"]

#: Share of the upper force limit a re-timed reference may use for acceleration and resistance.
FORCE_HEADROOM = 0.9


def _rear_grip_mu(tyre: TyreParams, mu_road: float) -> float:
    """The driven (rear) tyre's peak μ on a road of ``mu_road`` (scaled when grip follows the road)."""
    return mu_road * tyre.mu_tyre / tyre.mu_dry if tyre.scale_grip_with_road else tyre.mu_tyre


def force_budget_acceleration(vehicle: VehicleParams, lqr: LQRSettings, mu_road: float,
                              headroom: float = FORCE_HEADROOM, tyre: TyreParams | None = None,
                              limits_vehicle: VehicleParams | None = None) -> Callable[[float], float]:
    """a(v) [m/s²]: what ``headroom`` × the upper force limit leaves for acceleration at speed v
    against the road resistance μ(road) M g and the drag; with a ``tyre`` that has
    ``combined_slip``, also at most ``headroom`` × the rear tyre's grip μ_t F_zR as traction.
    ``limits_vehicle``: the vehicle whose mass per-kg force limits follow (the controllers' one,
    which applies the saturation; default ``vehicle``).
    Raises :class:`ConfigError` when nothing is left at standstill."""
    f_max = headroom * lqr.force_limits(limits_vehicle or vehicle)[1]
    res = mu_road * vehicle.mass * vehicle.g
    if f_max <= res:
        raise ConfigError(f"scenario: a {vehicle.mass:g} kg vehicle needs {res:.0f} N against "
                          f"mu(road) = {mu_road:g}, more than {headroom:g} x its force limit")
    traction = f_max - res
    if tyre is not None and tyre.combined_slip:
        traction = min(traction, headroom * _rear_grip_mu(tyre, mu_road) * vehicle.static_loads[1])
    d, m = vehicle.drag_factor, vehicle.mass

    def a(v: float) -> float:
        return max((traction - d * v * v) / m, 0.0)

    return a


def braking_budget_deceleration(vehicle: VehicleParams, lqr: LQRSettings, mu_road: float,
                                headroom: float = FORCE_HEADROOM, tyre: TyreParams | None = None,
                                limits_vehicle: VehicleParams | None = None) -> Callable[[float], float]:
    """d(v) > 0 [m/s²]: the deceleration ``headroom`` × the lower force limit gives at speed v with
    the road resistance μ(road) M g and the drag helping (pass the *lowest* μ(road) of the run:
    the least help); with a ``tyre`` that has ``combined_slip``, the rear tyre's braking is at most
    ``headroom`` × its grip μ_t F_zR. ``limits_vehicle`` as in :func:`force_budget_acceleration`."""
    brake = headroom * max(-lqr.force_limits(limits_vehicle or vehicle)[0], 0.0)
    res = mu_road * vehicle.mass * vehicle.g
    if tyre is not None and tyre.combined_slip:  # the tyre transmits F_xR − F_res: brake + res
        grip = headroom * _rear_grip_mu(tyre, mu_road) * vehicle.static_loads[1]
        brake, res = min(brake + res, grip), 0.0
    d, m = vehicle.drag_factor, vehicle.mass

    def dec(v: float) -> float:
        return (brake + res + d * v * v) / m

    return dec


def path_curvature(ref: Reference) -> np.ndarray:
    """κ [1/m] of each sample: ω/v where the reference moves (v > 0.1 m/s), else its own κ."""
    v = np.asarray(ref.v, dtype=float)
    return np.where(v > 0.1, np.asarray(ref.omega) / np.maximum(v, 0.1), np.asarray(ref.kappa))


def lateral_speed_cap(ref: Reference, a_lat: float | np.ndarray) -> np.ndarray:
    """The speed [m/s] at which each sample's curvature κ gives the lateral acceleration ``a_lat``
    (one value, or one per sample):
    ``sqrt(a_lat / |κ|)`` (inf on a straight)."""
    k = np.abs(path_curvature(ref))
    with np.errstate(divide="ignore"):
        return np.where(k > 1e-9, np.sqrt(a_lat / np.maximum(k, 1e-12)), np.inf)


def _grip_left(a_grip: np.ndarray | None, kappa: np.ndarray, k: int, v: float) -> float:
    """What the friction circle of sample k leaves along the path at speed v [m/s²]:
    sqrt(a_grip² − (v² κ)²), 0 beyond it; inf without ``a_grip``."""
    if a_grip is None:
        return math.inf
    lat = v * v * abs(float(kappa[k]))
    return math.sqrt(max(float(a_grip[k]) ** 2 - lat * lat, 0.0))


def _braked_from(nxt: float, ds: float, dec: float, a_grip: np.ndarray | None, kappa: np.ndarray,
                 k: int) -> float:
    """The highest speed at sample k from which the car reaches ``nxt`` at sample k+1, ``ds`` on,
    braking at most ``dec`` and, with ``a_grip``, within sample k's friction circle at that speed:
    (w² − nxt²) / (2 ds) ≤ sqrt(a_grip² − (w² κ_k)²), solved for u = w² — the quadratic
    (1 + c) u² − 2 nxt² u + nxt⁴ − 4 ds² a_grip² = 0, c = 4 ds² κ_k², its larger root."""
    u = nxt * nxt + 2.0 * dec * ds
    if a_grip is not None:
        A, c, n2 = float(a_grip[k]), 4.0 * ds * ds * float(kappa[k]) ** 2, nxt * nxt
        if math.isfinite(A):
            disc = n2 * n2 - (1.0 + c) * (n2 * n2 - 4.0 * ds * ds * A * A)
            u = min(u, (n2 + math.sqrt(max(disc, 0.0))) / (1.0 + c))
    return math.sqrt(max(u, nxt * nxt))


def retime(ref: Reference, a_max: Callable[[float], float], v_cap: np.ndarray | None = None,
           d_max: Callable[[float], float] | None = None, a_grip: np.ndarray | None = None) -> Reference:
    """``ref``'s path with its speed profile lowered where accelerating from sample k−1 to k would
    need more than ``a_max(speed)``; resampled at ``ref.dt`` (the result is longer in time). A
    reference that already complies is returned unchanged. Closed laps are re-timed cyclically.

    ``v_cap`` (n,): a speed cap per sample applied first (:func:`lateral_speed_cap`); ``d_max``:
    a deceleration limit for a backward pass after the forward one, so the speed comes down to a
    cap before it (without it, the original's braking is kept: w only meets v from below).
    ``a_grip`` (n,): the friction circle per sample [m/s²]: the acceleration from sample k−1 and
    the braking from sample k use at most what that sample's lateral acceleration leaves of it,
    sqrt(a_grip² − (v² κ)²) (the g-g diagram of a speed planner; at the lateral cap nothing is
    left, so the braking ends before the corner and the acceleration waits for its exit)."""
    x, y = np.asarray(ref.x), np.asarray(ref.y)
    v = np.maximum(np.asarray(ref.v, dtype=float), 0.0)
    n = v.size
    kappa = path_curvature(ref)  # (the friction circle reads it; the resampled output too)
    # ds[k]: the step into sample k (ds[0]: from the last sample, a closed lap's wrap)
    ds = np.hypot(np.diff(x, prepend=x[-1]), np.diff(y, prepend=y[-1]))
    top = v if v_cap is None else np.minimum(v, np.maximum(np.asarray(v_cap, dtype=float), 0.0))
    w = top.copy()
    order = [k % n for k in range(1, 2 * n)] if ref.closed else list(range(1, n))
    for k in order:  # a closed lap twice round, so its start sees the end of the lap
        prev = w[k - 1]
        acc = min(a_max(prev), _grip_left(a_grip, kappa, k - 1, prev))
        w[k] = min(top[k], float(np.sqrt(prev * prev + 2.0 * acc * ds[k])))
    if d_max is not None:  # backward: w_k may exceed w_{k+1} by what braking over Δs_{k+1} takes off
        back = [k % n for k in range(2 * n - 2, -1, -1)] if ref.closed else list(range(n - 2, -1, -1))
        for k in back:
            nxt = w[(k + 1) % n]
            w[k] = min(w[k], _braked_from(nxt, float(ds[(k + 1) % n]), d_max(nxt), a_grip, kappa, k))
    if np.all(w >= v - 1e-9):
        return ref
    # Time of each step: the original T where neither end changed (so the unchanged stretches keep
    # their time base exactly), else the step at the mean of its end speeds, 2 Δs / (w_{k−1} + w_k),
    # which makes the acceleration along the changed stretches exactly a_max.
    dt = ref.dt
    same = (w[1:] >= v[1:] - 1e-9) & (w[:-1] >= v[:-1] - 1e-9)
    step = np.where(same, dt, 2.0 * ds[1:] / np.maximum(w[:-1] + w[1:], 1e-6))
    tau = np.concatenate([[0.0], np.cumsum(step)])
    m = int(np.floor(tau[-1] / dt + 1e-9)) + 1
    t_new = np.arange(m) * dt
    vv = np.interp(t_new, tau, w)
    out = Reference(ref.t[0] + t_new, np.interp(t_new, tau, x), np.interp(t_new, tau, y),
                    np.interp(t_new, tau, np.asarray(ref.theta)), vv, np.interp(t_new, tau, kappa) * vv,
                    np.interp(t_new, tau, kappa), closed=ref.closed)
    return out


def retime_for_force_budget(ref: Reference, vehicle: VehicleParams, lqr: LQRSettings,
                            mu_road: float, tyre: TyreParams | None = None,
                            limits_vehicle: VehicleParams | None = None) -> Reference:
    """:func:`retime` with :func:`force_budget_acceleration` of ``vehicle`` (and ``tyre``) at
    ``mu_road``, the force limits those of ``limits_vehicle`` (default ``vehicle``)."""
    return retime(ref, force_budget_acceleration(vehicle, lqr, mu_road, tyre=tyre,
                                                 limits_vehicle=limits_vehicle))
