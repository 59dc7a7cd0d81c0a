"""Can the vehicle drive this plan? Checked before any design or compile work (issue 36).

A reference planned for another car, or with limits the tyres do not have (a track planned at
8 m/s² lateral for a car whose tyres give μ_tyre g = 8.8 m/s²), is accepted by the closed loop and
leaves the road minutes later. :func:`check_plan` compares the reference's demands with the
vehicle's limits, sample by sample:

* lateral acceleration ``v²|κ|`` against ``GRIP_MARGIN × μ g``, the tyre's peak μ_tyre, scaled
  by μ(road)/μ_dry where the plant's grip follows the road: sample by sample, μ(road) where (path
  distance) and when (the plan's own time) the sample is driven, its dips shorter than
  :data:`SUSTAINED_S` filled. A plan capped for a time-based drop arrives later than its own
  timing says: the online speed governor covers what the plan cannot;
* the lateral and longitudinal acceleration together, ``sqrt(a_lat² + a_long²)``, against the same
  ``GRIP_MARGIN × μ g`` (the friction circle of a speed planner's g-g diagram: a tyre that brakes
  has less left for the corner; named "combined grip" only where the lateral acceleration alone is
  within its margin). Without it, the TUMFTM tracks capped at 30 m/s braked at the planner's
  3 m/s² into corners already at the lateral margin, 6.1 m/s² together, and the car's yaw rate
  overshot at the turn-in: of 20 further tracks (not tuned on), Suzuka, Brands Hatch and
  Catalunya left the 0.5 m bound (0.90, 0.77, 0.55 m);
* acceleration against the force budget ``(η F_max − μ M g − drag)/M`` and braking against
  ``(η |F_min| + μ M g + drag)/M`` (:mod:`tsmpc.planning.retime`, headroom
  η = :data:`~tsmpc.planning.retime.FORCE_HEADROOM`; the highest μ(road) of the run for the
  resistance the drive must overcome, the lowest sustained one for the resistance that helps
  braking; the
  driven tyre's grip too when it has a friction ellipse).

The margins, and why: the lateral margin 0.6 keeps the tyres out of the last 40 % of their
grip. The controllers' models are linear in the tyre slip (constant C_x); the plant's Pacejka
curve (C 1.3, E −0.5) still has 69 % of that local stiffness at 60 % of its peak force, under half
(49 %) at 75 %, so beyond 60 % the feedback works on a plant that answers a slip correction with
half the force its model expects — room the feedback needs for the errors it has to correct, on
tracks nobody measured. The force headroom (90 %) is the one :mod:`~tsmpc.planning.retime` uses:
the inner loop keeps 10 % of its force for its feedback. The re-timing also accelerates and brakes
no harder than the plan itself does (:func:`_in_style`): the force budgets alone (the paper's road
resistance brakes at up to 9 m/s²) made the capped TUMFTM tracks at 30 m/s alternate full drive and
full braking between close corners, and three of five left the road; no harder than the planner's
own limits, all five stay well within 0.5 m (docs/planning.md, generated).

:func:`feasible_plan` acts on the result: a plan within the limits is returned unchanged; one
beyond them is re-timed along the same path (:func:`tsmpc.planning.retime.retime`: the lateral cap
``v ≤ sqrt(GRIP_MARGIN μ g / |κ|)``, then the forward acceleration and backward braking passes
within the friction circle, no harder than the budgets nor than the plan itself accelerates and
brakes) and one line says by how
much and which limit; ``strict`` refuses it instead (:class:`ConfigError`,
exit 2 on the command line), naming the limit.

The published reference (the paper's run window of its planner file) is exempt: it is the
benchmark the paper's Table 5 was measured on and that our rows are compared with, so it is tracked
as published. It is not within the limits everywhere — its v row jumps by 0.8 m/s in one 0.1 s
sample at 2.5 s (8 m/s², above the 4.3 m/s² the force budget gives) — and the check says so in its
line instead of capping it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, LQRSettings, TyreModel, TyreParams, VehicleParams
from tsmpc.errors import ConfigError
from tsmpc.planning.reference import Reference
from tsmpc.planning.retime import (
    FORCE_HEADROOM,
    braking_budget_deceleration,
    force_budget_acceleration,
    lateral_speed_cap,
    path_curvature,
    retime,
)
from tsmpc.scenarios import FrictionProfile, mu_array

__all__ = ["GRIP_MARGIN", "STYLE_FLOOR", "SUSTAINED_S", "PlanCheck", "check_plan", "feasible_plan",
           "feasible_plan_for"]

#: Share of the tyre's peak grip μ g the plan's lateral acceleration may use (see the module text).
GRIP_MARGIN = 0.6
#: A μ(road) patch shorter than this [s] does not lower the grip the plan is checked against: the
#: paper's profile has 0.1 s of ice (μ 0.1) at 70 s, crossed on momentum; capping the corners
#: around it to 10 % of the grip for it would make them a crawl.
SUSTAINED_S = 1.0
#: A plan that accelerates (brakes) at least this much [m/s²] somewhere is re-timed no harder than
#: that; below it (a constant-speed plan) the force budget alone bounds the re-timing.
STYLE_FLOOR = 0.5
#: A demand counts as beyond a limit only past this relative tolerance: a capped plan resampled at
#: its period (linear interpolation of v and κ) keeps peaks a few per mille above the cap.
_TOL = 0.01
#: The re-timing's friction circle, as a share of the lateral margin's: inside it by enough that the
#: resampled plan passes :func:`check_plan` within :data:`_TOL`.
_CIRCLE_AIM = 0.98


@dataclass(frozen=True)
class PlanCheck:
    """The result of :func:`check_plan`.

    Attributes:
        limit: the limit exceeded most (by the ratio demand / allowed): "lateral grip",
            "combined grip" (lateral and longitudinal together, the friction circle), "force
            budget" (acceleration) or "braking budget"; "" when none is.
        ratio: that largest demand / allowed (> 1: beyond the limit).
        demand: the demand there [m/s²].
        allowed: the limit there [m/s²].
        t: its time from the reference's start [s].
        mu_grip: the tyre's grip coefficient at the lateral check's worst sample.
        a_lat_max: GRIP_MARGIN μ_grip g there [m/s²].
    """

    limit: str
    ratio: float
    demand: float
    allowed: float
    t: float
    mu_grip: float
    a_lat_max: float

    @property
    def ok(self) -> bool:
        """The plan is within every limit."""
        return not self.limit

    def describe(self) -> str:
        """The exceeded limit and by how much, for one line."""
        what = {"lateral grip": f"lateral acceleration {self.demand:.2f} m/s² > {self.allowed:.2f} m/s² "
                                f"({GRIP_MARGIN:g} x mu {self.mu_grip:.3g} x g)",
                "combined grip": f"lateral and longitudinal acceleration together {self.demand:.2f} m/s² > "
                                 f"{self.allowed:.2f} m/s² ({GRIP_MARGIN:g} x mu {self.mu_grip:.3g} x g)",
                "force budget": f"acceleration {self.demand:.2f} m/s² > {self.allowed:.2f} m/s² (the "
                                f"force budget, {FORCE_HEADROOM:.0%} of the force limit)",
                "braking budget": f"deceleration {self.demand:.2f} m/s² > {self.allowed:.2f} m/s² (the "
                                  f"braking budget, {FORCE_HEADROOM:.0%} of the force limit)"}
        return f"{self.limit}: {what.get(self.limit, '')} at t = {self.t:.1f} s"


def _run_mu(friction: FrictionProfile, ref: Reference) -> NDArray[np.float64]:
    """μ(road) at each sample's time (from the start) and path distance, as the run meets it."""
    t = np.asarray(ref.t, dtype=float) - float(ref.t[0])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(ref.x), np.diff(ref.y)))])
    return mu_array(friction, t, s)


def _closed(mu: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
    """μ per sample with the dips shorter than :data:`SUSTAINED_S` filled (a morphological closing:
    the sliding max, then the sliding min, over windows of that length)."""
    n = max(1, round(SUSTAINED_S / dt))
    if n <= 1 or mu.size <= n:
        return mu.copy() if mu.size > n else np.full(mu.size, float(mu.max()) if mu.size else 0.0)
    half = n // 2
    pad = np.pad(mu, (half, n - 1 - half), mode="edge")
    up = np.lib.stride_tricks.sliding_window_view(pad, n).max(axis=1)
    pad = np.pad(up, (n - 1 - half, half), mode="edge")
    return np.lib.stride_tricks.sliding_window_view(pad, n).min(axis=1)


@dataclass(frozen=True)
class _Limits:
    mu_grip: NDArray[np.float64]  # the tyre's peak μ at each sample
    a_lat: NDArray[np.float64]  # allowed lateral acceleration [m/s²] per sample (inf: linear tyre)
    acc: Callable[[float], float]  # a(v): allowed acceleration
    dec: Callable[[float], float]  # d(v): allowed deceleration


def _limits(ref: Reference, vehicle: VehicleParams, tyre: TyreParams, lqr: LQRSettings,
            friction: FrictionProfile, limits_vehicle: VehicleParams | None) -> _Limits:
    mu = _closed(_run_mu(friction, ref), ref.dt)
    mu_low, mu_high = float(mu.min()), float(mu.max())
    # the tyre's grip at each sample: μ_tyre, scaled where the plant's grip follows the road
    mu_grip = tyre.mu_tyre * mu / tyre.mu_dry if tyre.scale_grip_with_road else np.full(mu.size, tyre.mu_tyre)
    # the linear tyre (the control model's, a verification plant) has no grip limit
    a_lat = GRIP_MARGIN * mu_grip * vehicle.g if tyre.model == TyreModel.PACEJKA else np.full(mu.size, np.inf)
    acc = force_budget_acceleration(vehicle, lqr, mu_high, tyre=tyre, limits_vehicle=limits_vehicle)
    dec = braking_budget_deceleration(vehicle, lqr, mu_low, tyre=tyre, limits_vehicle=limits_vehicle)
    return _Limits(mu_grip, a_lat, acc, dec)


def _in_style(ref: Reference, lim: _Limits) -> tuple[Callable[[float], float], Callable[[float], float]]:
    """The acceleration and braking limits of the re-timing: the budgets, and no harder than the
    plan itself accelerates and brakes anywhere (its planner's limits: a capped plan keeps its
    style; the physical budgets — the paper's road resistance brakes at up to 9 m/s² — would make
    it alternate full drive and full braking between close corners, which the car follows badly).
    A plan that never brakes (or accelerates) by :data:`STYLE_FLOOR` leaves the budget alone."""
    dv = np.diff(np.asarray(ref.v, dtype=float)) / ref.dt
    a_plan = float(dv.max()) if dv.size else 0.0
    d_plan = float(-dv.min()) if dv.size else 0.0
    a_budget, d_budget = lim.acc, lim.dec

    def acc(v: float) -> float:
        return min(a_budget(v), a_plan) if a_plan >= STYLE_FLOOR else a_budget(v)

    def dec(v: float) -> float:
        return min(d_budget(v), d_plan) if d_plan >= STYLE_FLOOR else d_budget(v)

    return acc, dec


def check_plan(ref: Reference, vehicle: VehicleParams, tyre: TyreParams, lqr: LQRSettings,
               friction: FrictionProfile, *, limits_vehicle: VehicleParams | None = None) -> PlanCheck:
    """Compare ``ref``'s lateral acceleration, acceleration and braking with the limits of
    ``vehicle`` (the plant's) on ``tyre`` over the run's μ(road) (``friction``); the force limits
    are ``lqr``'s for ``limits_vehicle`` (the controllers' vehicle; default ``vehicle``).
    Raises :class:`ConfigError` when the force limit cannot even hold the speed against the road."""
    lim = _limits(ref, vehicle, tyre, lqr, friction, limits_vehicle)
    return _measure(ref, lim)


def _measure(ref: Reference, lim: _Limits) -> PlanCheck:
    v = np.maximum(np.asarray(ref.v, dtype=float), 0.0)
    t = np.asarray(ref.t, dtype=float) - float(ref.t[0])
    lat = v * v * np.abs(path_curvature(ref))
    dv = np.diff(v) / ref.dt  # the change into sample k+1, at the speed it starts from
    acc_allowed = np.array([lim.acc(float(x)) for x in v[:-1]])
    dec_allowed = np.array([lim.dec(float(x)) for x in v[1:]])
    worst = ("", 0.0, 0.0, 0.0, 0.0)
    kl = 0  # the lateral check's worst sample: its grip goes into the line
    # the friction circle: the change into sample k+1 with sample k's lateral acceleration (named
    # only when the lateral acceleration alone is within its margin: that is the plain message)
    combined = np.hypot(lat[:-1], dv)
    cases = (("lateral grip", lat, lim.a_lat, t),
             ("combined grip", combined, lim.a_lat[:-1], t[:-1]),
             ("force budget", dv, acc_allowed, t[1:]),
             ("braking budget", -dv, dec_allowed, t[1:]))
    for name, demand, allowed, tt in cases:
        if demand.size == 0:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(allowed > 0, demand / np.where(allowed > 0, allowed, 1.0),
                         np.where(demand > 0, np.inf, 0.0))
        k = int(np.argmax(r))
        if name == "combined grip" and worst[0] == "lateral grip":
            continue
        if name == "lateral grip" or (name == "combined grip" and r[k] > 1.0 + _TOL):
            kl = k
        if r[k] > 1.0 + _TOL and r[k] > worst[1]:
            worst = (name, float(r[k]), float(demand[k]), float(allowed[k]), float(tt[k]))
    return PlanCheck(worst[0], worst[1], worst[2], worst[3], worst[4], float(lim.mu_grip[kl]),
                     float(lim.a_lat[kl]))


def feasible_plan(ref: Reference, vehicle: VehicleParams, tyre: TyreParams, lqr: LQRSettings,
                  friction: FrictionProfile, *, limits_vehicle: VehicleParams | None = None,
                  strict: bool = False, exempt: str = "") -> tuple[Reference, PlanCheck, str]:
    """(reference, check, line): ``ref`` unchanged with an empty line when it is within the
    limits (:func:`check_plan`); else re-timed along its path to them (the lateral cap, then the
    acceleration and braking passes) with one line saying how much and which limit — or, with
    ``strict``, :class:`ConfigError` naming the limit; ``exempt`` (a reason) keeps it as it is
    and the line says it exceeds them."""
    try:
        lim = _limits(ref, vehicle, tyre, lqr, friction, limits_vehicle)
    except ConfigError as err:  # the force limit cannot even hold the speed: no plan is drivable
        if strict:
            raise ConfigError(f"plan check (--strict-plan): {err}") from None
        nothing = PlanCheck("force budget", float("inf"), 0.0, 0.0, 0.0, tyre.mu_tyre, float("nan"))
        return ref, nothing, f"plan check: {err}; the plan is tracked as it is (expect saturation)"
    check = _measure(ref, lim)
    if check.ok:
        return ref, check, ""
    if exempt:
        return ref, check, (f"plan check: the reference exceeds the vehicle's limits ({check.describe()}); "
                            f"tracked as it is: {exempt}")
    if strict:
        raise ConfigError(f"plan check (--strict-plan): the reference exceeds the vehicle's "
                          f"{check.describe()}; re-plan it within the limits, or drop --strict-plan "
                          "to cap its speed profile")
    acc, dec = _in_style(ref, lim)
    # each sample's cap from the grip where (and when, along the plan's own timing) it is driven
    # the friction circle aimed _CIRCLE_AIM inside: the resampled plan's samples (linear in time)
    # land between the re-timing's, a per cent or two beyond its corners (measured on the TUMFTM
    # tracks); re-checked, a capped plan must pass (`tsmpc plan` then `tsmpc run`: capped once)
    capped = retime(ref, acc, v_cap=lateral_speed_cap(ref, lim.a_lat), d_max=dec,
                    a_grip=lim.a_lat * _CIRCLE_AIM)
    v0, v1 = float(np.max(ref.v)), float(np.max(capped.v))
    return capped, check, (f"plan capped to the vehicle's limits: {check.describe()}; speed profile "
                           f"re-timed along the same path (max v {v0:.1f} -> {v1:.1f} m/s, duration "
                           f"{ref.duration:.1f} -> {capped.duration:.1f} s); --strict-plan refuses instead")


def feasible_plan_for(cfg: Config, ref: Reference, *,
                      strict: bool = False) -> tuple[Reference, PlanCheck, str]:
    """:func:`feasible_plan` for ``cfg``'s vehicle, tyre and force limits on the μ(road) every run
    meets (the paper's profile by time, :func:`tsmpc.sim.compare.load_scenario`): what
    ``tsmpc plan`` checks before it writes a reference."""
    from tsmpc.scenarios import paper_friction_profile

    return feasible_plan(ref, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile(), strict=strict)
