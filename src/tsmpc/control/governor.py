"""Speed governor (beyond the paper; issue 36): re-time the reference online to the grip the road
has now.

The planner times the reference for the grip it was told (``tyre.mu_tyre``); a road that loses its
grip mid-run (μ 0.9 → 0.5) leaves a plan whose corners and accelerations ask for more than the
tyres can give, and nothing in the paper's cascade slows down. The governor samples the reference
at a *governed* time τ instead of the run's time t, with rate r = dτ/dt ∈ [r_min, 1]: the path is
unchanged, the car drives it at r times the planned speed (v_d(τ) r, ω_d(τ) r), so its lateral
acceleration v_d ω_d and its acceleration along the path both scale with r². The cascade keeps τ
as its reference-time offset (``t − τ``, the recovery's offset, :mod:`tsmpc.control.cascade`).

Grip. Its model is the road the run declares — whether the tyres' grip follows μ(road): the
config's tyre (``tyre.scale_grip_with_road``) or the scenario's
(``scenario.plant.grip_scales_with_road``), the reading the plan check makes of the same road
(:func:`tsmpc.sim.experiment.check_plan_limits`) — read each MPC step by :func:`governor_inputs`:

- *The tyres' grip follows the road* (either flag). The friction force the MHE-UIO estimates (its
  unknown input, :mod:`tsmpc.estimation.mhe_uio`) is F̂_fr = (μ(road) − μ_o) M g, so
  μ̂(road) = (μ_o M g + F̂_fr) / (M̂ g) — the whole resistance over the estimated weight (M̂: the mass
  estimate of ``fusion.mass_estimate`` when on, M the model's), and
  the grip is μ̂_t = μ̂(road) μ_tyre / μ_dry.
- *Tyre-only* (neither, the default). The grip holds its prior μ_tyre and is lowered only by what
  the tyre itself shows: a spin (below). Why not read it from the resistance: before the wheel
  first spins, a μ drop 0.9 → 0.5 and the default run's μ program look the same to the controller
  — the road's resistance drops and the tyres' utilisation stays ≤ 0.43 — so the grip is not
  observable in time (the study of 2026-11-27, notes/governor-grip-study); only the resistance
  change, read through the coupling "the tyres' grip follows the road", warns early enough. Whether
  that coupling holds is a property of the tyres on that road, which the run declares, not
  something the governor can estimate. Read through a coupling nobody declared — the conservative
  belief μ̂_t = μ_tyre min(μ̂(road)/μ_dry, 1) on every run, measured (REF, Python loop) — the
  default run's μ program slows the built-in circuit for grip it never lost (1 action, max |e_y|
  0.0076 → 0.0082 m, RMSE v 0.049 → 0.051 m/s), and a μ 0.9 → 0.5 drop at 30 s that leaves the
  grip alone is slowed throughout: 7 actions on the built-in circuit (max |e_y| 0.0083 → 0.0169 m,
  RMSE v +14 %), 8 on Monza (RMSE v +12 %). The plan's own demand is above ``margin`` of the
  governor's grip even at μ_tyre there (the deadband holds it), so any grip belief lowered on a
  resistance drop acts. Tyres that follow the road without the run saying so (a real car configured
  tyre-only) stay a model mismatch the governor learns of at the first spin only: on the paper
  reference's μ 0.9 → 0.5 at 30 s too late (the car left the road at ≈ 64.4 s when this model
  read ``tyre.scale_grip_with_road`` alone and the drop was declared in ``scenario.plant``).

A wheel that spins (either model) shows in the estimate: the acceleration the drive force does not
produce looks like more resistance (μ 0.9 → 0.3 under full throttle: μ̂(road) 1.36). A μ̂(road) at
the model's mass above every road the tyre knows, (1 + deadband) μ_dry, while the inner loop
saturates is read as such (a mass error alone also raises μ̂(road), without the saturation): the
grip is then the traction the rear tyre delivers, |F_xR − μ̂(road) M g| over its load
(:func:`spin_grip`; 0.30 there), and the governor is engaged for ``SPIN_HOLD_S`` whatever the grip:
a plan that asks more traction than the dry tyre has (the paper reference's start on the
friction-ellipse tyre) spins the wheel too. The estimate is low-passed (time constant
``grip_time_constant_s``) but a lower value is taken at once: grip lost is believed at once, grip
regained (back to the prior, tyre-only) slowly. The oracle row (``grip_source = "oracle"``) reads
the true μ(road) through the same declared coupling.

Demand of a reference sample (v_d, ω_d, a_d = dv_d/dτ) at rate 1, as an acceleration [m/s²]::

    d = sqrt((v_d ω_d)² + (k a_t)²),   a_t = a_d + c_d v_d² / M,   k = (a + b) / (a η)

a_t is the force per kg the driven rear tyre must transmit (acceleration plus the drag c_d v²;
:mod:`tsmpc.vehicle.plant`), driving or braking: F_xR is the car's one longitudinal force, a rear
one, and on the friction-ellipse tyre the road's resistance passes through the rear tyre too. The
rear axle carries a/(a+b) of the weight, so it reaches its grip (a+b)/a times sooner than the
whole car, and the reference may use a share η (``traction_margin``, 0.5) of it: the speed loop's
transients ask about twice the reference's own acceleration (the μ drop on the paper reference: at
0.8 of the axle's grip the car spun as the governed speed rose again). Braking counted for the
whole car (k = 1, before) let the built-in circuit's braking at 45 s (1.9 m/s², within the whole
car's grip on μ 0.5 but 92 % of the rear tyre's) through unslowed: the rear wheel locked and the
car left the road at 49.3 s, the μ-knowing oracle row too. In the preview a_d is the central
difference of the plan's speeds (the forward one at the first sample): a single-sample jump of the
plan's speed (the published reference has them) would read as twice the plan's acceleration for
one sample, and the governor slowed down — itself a braking — for a demand the car never follows.
At rate r the demand is r² d; the sample can be carried when r² d ≤ margin μ̂_t g, and its
traction needs at most the force budget, r² (a_t) ≤ (F_max − μ̂(road) M̂ g) / M̂: the largest
such rate r_j of each preview sample j.

A slow-down is itself a braking: a falling r decelerates the car by v_d dr/dt on top of r² a_t,
and the rear tyre carries both. So r_j is reachable from a sample before it only by the falls the
tyre has room for on the way, a speed planner's backward pass over the preview (the MPC's horizon
N and the samples a braking from 1 to r_min at ρ_down needs)::

    r*_j = min(r_j, r*_{j+1} + T_c min(ρ_down, room_j / max(v_j, 1))),   r = r*_{j+1},
    room_j = max(sqrt((margin μ̂_t g)² − (r² v_j ω_j)²) / k − max(−r² a_t,j, 0), 0)

and the target is r*_0. Inside a braking zone that already uses the tyre's share (room 0) the
governor cannot slow down, so it slows before it: the old credit, ρ_down T_c for every sample
ahead, assumed a fall the tyre cannot make there. The pass credits the tyre's share only, never a
sample's acceleration (which the governed car, at another rate and a few samples of the speed
loop later, need not have); :func:`rate_limit`, at the current sample, counts the plan's
acceleration both ways. r follows r* within −ρ_down T_c and +ρ_up T_c per MPC step, and within the
room :func:`rate_limit` leaves. So it slows before a stretch the grip cannot carry and returns to
the plan smoothly (rate-limited) when the grip returns. A wheel that locks the moment μ drops
inside a braking zone is beyond it: the inner loop's speed transient after the drop asks more than
the tyre has before any rate change counts (a μ 0.3 patch from 45 s on the built-in circuit, a μ
0.4 drop at 60 s inside Monza's first braking zone: both leave the road, the oracle row too). There
the car would have to brake less than the plan, r > 1, which the governor never asks.

While μ̂_t ≥ (1 − deadband) μ_tyre (with the default tyre it holds μ_tyre until a wheel spins) the
grip is not its business, but the force budget still is: a plan whose traction ahead needs more
than the drive force leaves, r*² < 1 − deadband with the budget alone (:func:`preview_rate` without
a grip limit), is slowed to it. Without that, a car heavier than the plan's — configured with its
true mass, so that no mass error shows as a spin — saturated its drive force through the paper
reference's launch (up to about 5 m/s²), fell 4 m behind, and the MPC's catch-up drove it to its
18 m/s bound: 4.4 m/s above the plan's speed at 25 % more mass (measured; the oracle-tuned rows of
the mismatch and generalisation benchmarks did exactly that). A plan checked for the vehicle's
grip and force budget before the run (:mod:`tsmpc.planning.retime`, 90 % of the budget) needs
nothing from it, and on those the run is the cascade's without the governor, bit for bit — the
built-in circuit's and the race tracks'. The published paper reference, exempt from the check
(its speeds jump in single samples), asks for more at its launch: there the nominal run is
governed for about 3 s (it saturated 30 inner steps ungoverned, 9 governed). The governor is on by
default, off in the ``paper`` presets.

:func:`governor_inputs` and :func:`governor_update` are the block's one definition
(:mod:`tsmpc.kernels.jit`): the outer block (:func:`tsmpc.control.outer_block.outer_after`) runs
them for the cascade, the run engine and the batch. :class:`Governor` is a standalone online
wrapper of :func:`governor_update`; :func:`governed_window` the reference at a governed time as a
:class:`~tsmpc.planning.reference.Reference` (the baselines' window; the outer block reads the same
samples through :func:`governed_index` and :func:`governed_fill`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.kernels.jit import jitable
from tsmpc.planning.reference import Reference

__all__ = [
    "Governor",
    "GovernorParams",
    "GovernorState",
    "GripParams",
    "governed_fill",
    "governed_index",
    "governed_window",
    "governor_inputs",
    "governor_update",
    "grip_estimate",
    "interp_unit",
    "preview_rate",
    "rate_limit",
    "sample_demand",
    "spin_grip",
]


#: After a spin of the rear wheel the governor stays engaged this long [s] (the plan asked for more
#: traction than the tyre has, whatever the grip estimate says once the wheel grips again).
SPIN_HOLD_S = 3.0


class GovernorParams(NamedTuple):
    """Parameters of the governor (from ``[governor]`` and the vehicle).

    Attributes:
        margin: share of μ̂ g the reference ahead may use [-].
        rate_down: fastest decrease of r [1/s].
        rate_up: fastest increase of r [1/s].
        rate_min: lowest r [-].
        mu_plan: the grip the plan was made for (tyre.mu_tyre) [-].
        deadband: the governor acts only below (1 − deadband) mu_plan [-].
        traction_factor: k = (a + b)/(a · traction_margin): the driven (rear) axle carries a/(a+b)
            of the weight, and the reference may use ``traction_margin`` of its grip [-].
        drag_per_kg: ½ρC_dA_r / M [1/m].
        g: gravity [m/s²].
        Tc: MPC step [s] (the governor's step, and the reference's sample period).
        grip_alpha: low-pass gain per step of a rising grip estimate, T_c / τ clipped to 1 [-].
    """

    margin: float
    rate_down: float
    rate_up: float
    rate_min: float
    mu_plan: float
    deadband: float
    traction_factor: float
    drag_per_kg: float
    g: float
    Tc: float
    grip_alpha: float


class GripParams(NamedTuple):
    """What :func:`governor_inputs` reads the grip with (from the config's vehicle and tyre).

    Attributes:
        oracle: the grip comes from the true μ(road) given each step (``grip_source = "oracle"``).
        mu_nominal: μ_o, the control model's nominal friction coefficient [-].
        mu_dry: the road μ at which the tyre has ``mu_tyre`` [-].
        mu_tyre: the tyre's grip, the plan's (the prior of the tyre-only model) [-].
        grip_per_road: μ_tyre / μ_dry when the tyres' grip follows the road
            (``tyre.scale_grip_with_road``), 0 for the tyre-only model [-].
        deadband: a resistance above (1 + deadband) μ_dry under saturation is a spin [-].
        g: gravity [m/s²].
        mass: the control model's mass M (the spin's reading) [kg].
        rear_share: a / (a + b), the share of the weight on the driven rear axle [-].
        force_max: the inner loop's largest drive force [N].
    """

    oracle: bool
    mu_nominal: float
    mu_dry: float
    mu_tyre: float
    grip_per_road: float
    deadband: float
    g: float
    mass: float
    rear_share: float
    force_max: float


class GovernorState(NamedTuple):
    """State of the governor.

    Attributes:
        rate: the governed rate r = dτ/dt [-].
        grip: the filtered grip estimate μ̂_t (NaN before the first) [-].
        spin_hold: time the governor stays engaged after the last spin [s].
    """

    rate: float = 1.0
    grip: float = math.nan
    spin_hold: float = 0.0


@jitable
def grip_estimate(F_fr: float, mass: float, mu_nominal: float, g: float, grip_per_road: float,
                  model_mass: float = math.nan) -> float:
    """μ̂_t from the friction force estimate: the road's whole resistance, the model's μ_o M g plus
    the unknown input F̂_fr, over the estimated weight M̂ g — μ̂(road) = (μ_o M g + F̂_fr) / (M̂ g) =
    μ_o + F̂_fr / (M̂ g) + μ_o (M − M̂) / M̂ — times μ_tyre / μ_dry (``grip_per_road``). ``mass``:
    M̂; ``model_mass``: the model's M (NaN: M̂, the term vanishes). Read as μ_o + F̂_fr / (M̂ g), a
    mass error the mass estimate has found still counted μ_o ΔM g as road: 7 % too much grip on
    dry asphalt with 15 % more mass (the estimate right to 0.3 %). NaN for a non-finite estimate."""
    if not (math.isfinite(F_fr) and mass > 0.0):
        return math.nan
    mu = mu_nominal + F_fr / (mass * g)
    if math.isfinite(model_mass) and model_mass != mass:
        mu += mu_nominal * (model_mass - mass) / mass
    return max(mu, 0.0) * grip_per_road


@jitable
def spin_grip(F_applied: float, mu_road: float, mass: float, g: float, rear_share: float) -> float:
    """μ̂_t of a rear wheel that spins: the traction it delivers, F_xR − μ̂(road) M g (the force
    the MHE's model sees accelerate the car), over its load ``rear_share`` M g."""
    return abs(F_applied - mu_road * mass * g) / (rear_share * mass * g)


@jitable
def governor_inputs(p: GripParams, F_fr: float, usable: bool, mass: float, saturated: bool,
                    F_applied: float, road_mu: float) -> tuple[float, bool, float]:
    """This MPC step's (grip sample μ̂_t, spinning, force budget per kg) for :func:`governor_update`.

    ``F_fr``: the inner loop's last friction estimate (NaN before the first); ``usable``: that
    estimate may be read as the road's resistance (accepted, at a speed of the dynamic box);
    ``mass``: M̂, the mass the resistance is read with; ``saturated``: the inner loop's last step
    saturated; ``F_applied``: the drive force applied [N]; ``road_mu``: the true μ(road) (oracle).

    μ̂(road) = (μ_o M g + F̂_fr) / (M̂ g) (:func:`grip_estimate`; the oracle: the true μ). The grip:
    μ̂(road) ``grip_per_road`` when the tyres follow the road, else the prior μ_tyre while a reading
    is usable (tyre-only: the resistance says nothing about the tyre). A resistance at the model's
    mass above every road, (1 + deadband) μ_dry, while the inner loop saturates is a spin: the grip
    is then the traction the rear tyre delivers (:func:`spin_grip`; the oracle knows the grip and
    ignores it). The force budget: (F_max − μ̂(road) M̂ g) / M̂ (μ_o without a reading)."""
    if p.oracle:
        mu_road = road_mu
    else:
        mu_road = grip_estimate(F_fr if usable else math.nan, mass, p.mu_nominal, p.g, 1.0, p.mass)
    grip = math.nan
    if math.isfinite(mu_road):
        grip = mu_road * p.grip_per_road if p.grip_per_road > 0.0 else p.mu_tyre
    mu_model = grip_estimate(F_fr, p.mass, p.mu_nominal, p.g, 1.0)
    spinning = saturated and mu_model > (1.0 + p.deadband) * p.mu_dry
    if spinning and not p.oracle:
        grip = spin_grip(F_applied, mu_model, p.mass, p.g, p.rear_share)
    mu_res = mu_road if math.isfinite(mu_road) else p.mu_nominal
    force_per_kg = (p.force_max - mu_res * mass * p.g) / mass
    return grip, spinning, force_per_kg


@jitable
def sample_demand(p: GovernorParams, v: float, omega: float, a_d: float) -> tuple[float, float]:
    """(grip demand [m/s²], traction per kg [m/s²]) of a reference sample at rate 1: driving and
    braking both at the rear tyre (k = ``traction_factor``)."""
    a_t = a_d + p.drag_per_kg * v * v
    a_lat = v * omega
    kt = p.traction_factor * a_t
    return math.sqrt(a_lat * a_lat + kt * kt), a_t


@jitable
def preview_rate(p: GovernorParams, grip: float, force_per_kg: float, v: NDArray[np.float64],
                 omega: NDArray[np.float64]) -> float:
    """The target rate r*: the backward pass r*_j = min(r_j, r*_{j+1} + T_c min(ρ_down,
    room_j / v_j)) over the preview, r_j the largest rate at which sample j needs at most
    margin·grip·g and its traction at most ``force_per_kg`` (the force budget left after the road
    resistance, per kg), room_j what the rear tyre has left at sample j, beside its lateral demand
    and the plan's braking, for the braking a falling r adds (module docstring); r*_0 within
    [rate_min, 1]. ``v``, ``omega``: the reference's samples
    from the governed time on; the plan's acceleration at a sample is the central difference."""
    allowed = p.margin * grip * p.g
    target = 1.0
    n = v.size - 1
    for j in range(n - 1, -1, -1):
        i = max(j - 1, 0)
        d, a_t = sample_demand(p, v[j], omega[j], (v[j + 1] - v[i]) / ((j + 1 - i) * p.Tc))
        r2 = 1.0
        if d > allowed:
            r2 = allowed / d if allowed > 0.0 else 0.0
        if a_t > force_per_kg and a_t > 0.0:
            r2 = min(r2, max(force_per_kg, 0.0) / a_t)
        # how far r can fall over sample j on the way to the rate sample j + 1 needs: the braking
        # a falling r adds, v_j dr/dt, and the sample's own braking share the rear tyre's grip
        r = min(target, 1.0)
        a_lat = r * r * v[j] * omega[j]
        room = math.sqrt(max(allowed * allowed - a_lat * a_lat, 0.0)) / p.traction_factor
        fall = min(p.rate_down, max(room - max(-r * r * a_t, 0.0), 0.0) / max(v[j], 1.0)) * p.Tc
        target = min(math.sqrt(r2), target + fall)
    return min(max(target, p.rate_min), 1.0)


@jitable
def governor_update(p: GovernorParams, s: GovernorState, grip_sample: float, force_per_kg: float,
                    v: NDArray[np.float64], omega: NDArray[np.float64],
                    spinning: bool = False) -> GovernorState:
    """One MPC step: the new state (rate and filtered grip). ``grip_sample``: this step's μ̂_t
    (NaN: the last one stands); ``v``, ``omega``: the preview (see :func:`preview_rate`);
    ``spinning``: the rear wheel spins now (engaged for ``SPIN_HOLD_S`` whatever the grip)."""
    hold = SPIN_HOLD_S if spinning else max(s.spin_hold - p.Tc, 0.0)
    grip = s.grip
    if math.isfinite(grip_sample):
        if not math.isfinite(grip) or grip_sample < grip:
            grip = grip_sample  # grip lost: believed at once
        else:
            grip += p.grip_alpha * (grip_sample - grip)  # regained: slowly
    target = 1.0
    if math.isfinite(grip) and (grip < (1.0 - p.deadband) * p.mu_plan or hold > 0.0):
        target = preview_rate(p, grip, force_per_kg, v, omega)
    elif math.isfinite(force_per_kg):
        # the grip holds, but the plan ahead may ask more than the drive force has (a heavier car
        # than planned): its traction alone, engaged beyond the deadband (within it the plan's own
        # margin and the speed loop's feedback carry it, and the nominal run stays the ungoverned one)
        budget = preview_rate(p, math.inf, force_per_kg, v, omega)
        if budget < 1.0 - p.deadband:
            target = budget
    r = s.rate
    if target < r:
        r = max(target, r - rate_limit(p, grip, r, v, omega, -1.0) * p.Tc)
    elif target > r:
        r = min(target, r + rate_limit(p, grip, r, v, omega, 1.0) * p.Tc)
    return GovernorState(min(max(r, p.rate_min), 1.0), grip, hold)


@jitable
def rate_limit(p: GovernorParams, grip: float, r: float, v: NDArray[np.float64],
               omega: NDArray[np.float64], sign: float) -> float:
    """How fast r may rise (``sign`` +1) or fall (−1) now [1/s]: at most ``rate_up`` /
    ``rate_down``, and no faster than the traction left at the current sample allows — a changing
    r accelerates the car by v_d dr/dt on top of r² a_t, and the rear tyre carries both:
    k |r² a_t + v_d dr/dt| ≤ sqrt((margin μ̂ g)² − (r² v_d ω_d)²). (Without grip estimate: the
    nominal limits.)"""
    top = p.rate_up if sign > 0.0 else p.rate_down
    if not math.isfinite(grip) or v.size < 2:
        return top
    _, a_t = sample_demand(p, v[0], omega[0], (v[1] - v[0]) / p.Tc)
    allowed = p.margin * grip * p.g
    a_lat = r * r * v[0] * omega[0]
    room = math.sqrt(max(allowed * allowed - a_lat * a_lat, 0.0)) / p.traction_factor - sign * r * r * a_t
    return min(top, max(room, 0.0) / max(v[0], 1.0))


@jitable
def interp_unit(a: NDArray[np.float64], s: float) -> float:
    """``np.interp(s, arange(a.size), a)`` for one ``s``, numpy's formula bit for bit (slope of
    the bracketing samples times the distance from the lower one, the other end's form when that
    is NaN; the end values outside): the one definition the Python window and the run engine use."""
    n = a.size
    if s != s:
        return s
    if s < 0.0:
        return a[0]
    if s >= n - 1:
        return a[n - 1]
    j = math.floor(s)
    if s == j:
        return a[j]
    slope = a[j + 1] - a[j]
    out = slope * (s - j) + a[j]
    if out != out:
        out = slope * (s - (j + 1)) + a[j + 1]
        if out != out and a[j] == a[j + 1]:
            out = a[j]
    return out


@jitable
def governed_index(tau: float, T: float) -> tuple[int, float]:
    """(k₀, s₀): the reference sample at or before governed time ``tau`` (sample period ``T``) and
    the fraction of a sample past it."""
    x = tau / T
    k0 = max(math.floor(x + 1e-9), 0)
    return k0, x - k0


@jitable
def governed_fill(a: NDArray[np.float64], s0: float, rate: float, scale: float,
                  out: NDArray[np.float64]) -> None:
    """``out[i]`` = the samples ``a`` (from k₀ on) at s₀ + i·rate samples, times ``scale``."""
    for i in range(out.size):
        out[i] = interp_unit(a, s0 + i * rate) * scale


def governed_window(ref: Reference, tau: float, rate: float, n: int) -> Reference:
    """``n`` samples of ``ref`` (period T) for the MPC's steps from governed time ``tau`` (in
    reference time since its first sample) at rate ``rate``: positions and headings at
    τ + i·rate·T, linearly interpolated, speeds and yaw rates times ``rate`` (curvature unchanged);
    time t₀ + i T (the steps the car drives them in)."""
    T = ref.dt
    k0, s0 = governed_index(tau, T)
    w = ref.window(k0, n + 2)

    def at(a: NDArray[np.float64], scale: float = 1.0) -> NDArray[np.float64]:
        out = np.empty(n)
        governed_fill(np.ascontiguousarray(a, dtype=float), s0, rate, scale, out)
        return out

    t = ref.t[0] + tau + np.arange(n) * T
    return Reference._trusted({"t": t, "x": at(w.x), "y": at(w.y), "theta": at(w.theta),
                               "v": at(w.v, rate), "omega": at(w.omega, rate), "kappa": at(w.kappa)})


class Governor:
    """The online wrapper of :func:`governor_update`: one call per MPC step.

    Args:
        params: the block's parameters.
        preview: samples of the reference the governor looks ahead (≥ the MPC horizon).
        grip: how the grip is read (:func:`governor_inputs`).
    """

    def __init__(self, params: GovernorParams, preview: int, grip: GripParams) -> None:
        self.params = params
        self.preview = int(preview)
        self.grip = grip  #: how the grip is read (:func:`governor_inputs`)
        self.reset()

    def reset(self) -> None:
        """Back to the plan (r = 1), the grip forgotten, the counters zeroed."""
        self.state = GovernorState()
        self.actions = 0  #: slow-downs begun (r left 1)
        self.steps = 0  #: MPC steps with r < 1

    @property
    def rate(self) -> float:
        """The governed rate r = dτ/dt now."""
        return self.state.rate

    def step(self, grip_sample: float, force_per_kg: float, v: NDArray[np.float64],
             omega: NDArray[np.float64], spinning: bool = False) -> float:
        """The rate for the next MPC step (counted: an action when r leaves 1)."""
        before = self.state.rate
        self.state = governor_update(self.params, self.state, float(grip_sample), float(force_per_kg),
                                     np.ascontiguousarray(v, dtype=float),
                                     np.ascontiguousarray(omega, dtype=float), bool(spinning))
        r = self.state.rate
        self.actions += before >= 1.0 and r < 1.0
        self.steps += r < 1.0
        return r
