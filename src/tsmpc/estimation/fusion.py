"""Measurement fusion and online adaptation beyond the paper (issue 21; the switches of
:class:`~tsmpc.config.FusionSettings`): what keeps the cascade accurate on a vehicle that is not
the one its models describe, with sensors that are not ideal.

Every signal here comes from the sensor samples the cascade is given (pose, v, ω) and from the
MHE's estimate; nothing reads the plant (docs/mismatch.md lists the sources).

* :class:`RepeatGuard` (``reject_repeated_samples``) — a sample bit-identical to the previous one
  (its five numbers and its stamp, when the platform stamps samples: a new stamp is a new sample)
  is a stalled sensor bus re-delivering it: with any sensor noise, or a moving car, two real
  samples never agree in all five numbers. It is treated as missing (like NaN), so the MHE
  predicts instead of fitting a frozen speed (which it would explain as a friction jump).
* ``predict_pose`` — a missing pose is replaced by the last good pose dead-reckoned with the
  estimate (v̂, α̂, ω̂) over each T_d (the cascade's own dead reckoning, which its pose-jump gate
  uses in any case). The paper-faithful alternative (hold the last pose) makes the reference run
  ahead of a frozen car: one lost MPC sample at 13 m/s is a 1.3 m jump of e_x, which the MPC
  answers with a full-throttle v_ref (issue 21: 795 saturated inner steps at 5 % random dropouts).
* :class:`CourseFusion` (``course_slip``, ``course_speed``) — the measured positions give the
  course and the speed over ground without any model: over a chord of the last ``BASELINE`` MPC
  poses the chord's direction is the (speed-weighted) mean of the velocity heading θ + α, and its
  length over the time is the mean speed (arc/chord corrected for the turn). Two least-squares fits
  with forgetting use them:

  - the slip: ᾱ_course − ᾱ̂ = κ ā_y + β (ā_y = v̂ ω̂ the lateral acceleration). A stiffness or mass
    error biases the MHE's α̂ in proportion to the lateral force (steady state of the single-track
    model: α depends on C_r and M through M a_y / C_r), so κ carries the model error and β a
    heading-sensor offset.
    The outer loop uses α̂ + κ̂ a_y,d + β̂ with a_y,d = v_d ω_d the *reference's* lateral
    acceleration (issue 21: 5 mrad of α̂ bias cost 0.08 m of RMSE y). The measured a_y would close
    a loop ω → a_y → slip → e_θ → ω without the tyres' lag, fast enough to destabilise a car
    whose rear grip is 30 % below the model's (it did, in a trial); the reference's is exogenous.
    κ explains the error of the model the MHE runs *now*: when the stiffness fit below gives
    the MHE new stiffnesses, κ restarts from its prior (β stays). Kept, it went on correcting
    the old model's bias for its memory on top of the new model's correct α̂ (issue 21: with
    C_f 30 % below the model's, RMSE y 0.0095 → 0.0062 m, the oracle-tuned controller's 0.0043);
  - the speed sensor's offset: v̄_measured − v_ground, removed from v before the MHE and the inner
    loop.

  - the axle cornering stiffnesses (``stiffness_estimate``): with the chord's slip ᾱ from the
    course, the axle forces from the measured lateral and yaw accelerations and the slips of the
    single-track model, F_yF = C_f (δ − α − a ω/v) and F_yR = C_r (b ω/v − α) are
    fitted per axle (least squares through the origin on the compliance 1/C, Bayesian: the
    model's C as prior with a relative σ of ``STIFF_PRIOR_REL``, each chord weighted by its slip
    noise, forgetting over ``STIFF_MEMORY_S``), from chords where the reference turns
    (``CORNER_ACCEL``) and the car neither accelerates nor brakes (``STIFF_MAX_ACCEL``), per axle
    only where the chord's own F / slip is a plausible stiffness (``STIFF_RANGE``). The
    fitted C_f, C_r replace the model's in the MHE and in the inner loop's reference gain N̄ (the
    LMI gains stay): with them α̂ and the steering feed-forward are right (issue 21: the stiffness
    error was worth 0.08 m of RMSE y; with the true C in both blocks the loss disappears, in the
    LMI gains alone it does not).

  The fits compare like with like (means over the same chord), so the chord's lag in a transient
  does not bias them; only chords of measured (not predicted) poses count. Each chord is weighted
  by its slip noise: the configured position σ over the chord's length, scaled up by the noise
  level the slip fit measures where the reference runs straight (there the slip and the model's
  error in it are ≈ 0, so its innovation is noise: ``noise_scale``) — positions noisier than the
  config says then count for less instead of driving the fits.
* :class:`MassEstimator` (``mass_estimate``) — the MHE's window-constant friction force F̂ takes up
  whatever force the model does not explain; with a mass error that includes ΔM ā, the inertia of
  the extra mass (ā = the window's mean acceleration). Compensating it feeds the acceleration back
  with the window's delay, and the speed feedback M (v_ref − v̂)/τ runs with the wrong mass: the
  two fight (issue 21: 946 saturated steps at +20 % mass, 700 with the true mass in the
  controllers). ΔM is fitted by least squares to the *high-passed* F̂ and ā (the road's resistance
  changes slowly and drops out; forgetting over ``MASS_MEMORY_S``), above ``MASS_MIN_SPEED``
  (below, the model's low-speed clipping makes F̂ meaningless). The compensation then gets
  F̂ − ΔM̂ ā and the speed feedback (M + ΔM̂)(v_ref − v̂)/τ.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, FusionSettings, VehicleParams

__all__ = ["BASELINE", "CourseFusion", "Fusion", "MassEstimator", "RepeatGuard"]

#: MPC steps spanned by the chord of the course fusion.
BASELINE = 5
#: Shortest chord [m] the course and the speed over ground are measured on.
MIN_CHORD_M = 2.0
#: Memory of the slip fit [s] (forgetting factor 1 − T_c / memory per MPC step).
SLIP_MEMORY_S = 30.0
#: Memory of the speed-offset fit [s].
SPEED_MEMORY_S = 10.0
#: Prior standard deviations of the slip fit: κ [rad per m/s²] and β [rad].
SLIP_PRIOR = (0.005, 0.02)
#: Largest slip correction applied [rad] (a fit beyond it is a broken sensor, not a model error).
SLIP_CORRECTION_MAX = 0.05
#: Largest speed offset removed [m/s].
SPEED_OFFSET_MAX = 2.0
#: Speed above which the mass is learnt [m/s] (the dynamic box's floor is 2 m/s).
MASS_MIN_SPEED = 3.0
#: High-pass time constant of F̂ and ā in the mass fit [s].
MASS_HIGHPASS_S = 2.0
#: Memory of the mass fit [s].
MASS_MEMORY_S = 100.0
#: Excitation Σ ā_hp² [m²/s⁴ · samples] needed before the mass estimate is used.
MASS_EXCITATION = 50.0
#: Bounds of the mass correction, as fractions of the model mass.
MASS_RANGE = (-0.4, 0.6)
#: Prior standard deviation of the axle cornering stiffnesses, as a fraction of the model's: a
#: car's tyres differ from the model's by tens of per cent (tyre make, pressure, load, wear,
#: temperature). The compliance fits are Bayesian: the model's 1/C with this relative σ against
#: chords weighted by their own slip noise, so how fast data outweigh the model follows the
#: measurement's noise instead of a fixed weight.
STIFF_PRIOR_REL = 0.3
#: Smallest slip error [rad] of one chord in the compliance fits: the quasi-steady single-track
#: fit's own error, which no better sensor removes (residual rms of the chords' slip against F / C
#: with a plant equal to the model, paper reference: 0.44 mrad rear, 0.54 mrad front).
STIFF_SLIP_FLOOR = 5e-4
#: Chords per independent slip measurement in the compliance fits: consecutive chords' errors are
#: correlated (same model error through a corner); 1 + 2 Σ ρ_k of that residual over 15 chords is
#: 4.0 (rear) to 5.0 (front), so each chord counts as 1/5 of one.
STIFF_CORRELATION = 5.0
#: Memory [s of chords on straights] of the positions' measured noise level.
NOISE_MEMORY_S = 30.0
#: Prior of the measured noise level, in chords at the configured σ.
NOISE_PRIOR_CHORDS = 10.0
#: Memory of the stiffness fits [s].
STIFF_MEMORY_S = 100.0
#: Bounds of the fitted stiffnesses, as multiples of the model's.
STIFF_RANGE = (0.5, 2.0)
#: Smallest lateral acceleration of the *reference* v_d ω_d [m/s²] all along a chord for it to count
#: in the stiffness fit (the reference, not the car: a car weaving on a straight is no corner).
CORNER_ACCEL = 0.2
#: Largest longitudinal acceleration of the car over a chord [g] for it to count in the stiffness
#: fit. The fit is a pure-slip, constant-speed single-track fit; under traction or braking the
#: tyres' lateral stiffness drops (combined slip) and load moves between the axles (ΔF_z / F_z ≈
#: a h / (g L/2): ≈ 4 % per axle at 0.1 g for a CoG height of 0.5 m on a 2.5 m wheelbase), neither
#: of which the fit's model has. CommonRoad's multi-body van (vehicle 3), accelerating hard through
#: fast corners, drove the fit's front/rear balance 10 % off, and the MHE with that balance left
#: the road at 74 s; with the gate it tracks to 0.03 m.
STIFF_MAX_ACCEL = 0.1


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class RepeatGuard:
    """Is a sample [X, Y, θ, v, ω] bit-identical to the previous finite one?"""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the previous sample."""
        self._last: tuple[float, ...] | None = None
        self.n_repeated = 0

    def repeated(self, sample: tuple[float, ...]) -> bool:
        """True (counted) when ``sample`` equals the previous finite sample in every number (an
        infinite entry, e.g. a missing stamp as −inf, counts as finite here)."""
        if any(math.isnan(c) for c in sample):
            return False
        same = self._last is not None and sample == self._last
        self._last = sample
        self.n_repeated += same
        return same


@dataclass
class _Interval:
    """Sums of one MPC interval (speed-weighted where the course needs it)."""

    start: tuple[float, float, float]  #: measured pose at the interval's start
    ok: bool = True  #: every sample measured and finite
    n: int = 0
    sv: float = 0.0  #: Σ v
    sv_dth: float = 0.0  #: Σ v (θ − θ_start), trapezoid (the closing sample counts half)
    sv_alpha: float = 0.0  #: Σ v α̂
    sv_ay: float = 0.0  #: Σ v â_y
    sv_full: float = 0.0  #: Σ v, every sample in full (the weights of α̂ and â_y)
    s_delta: float = 0.0  #: Σ δ (applied steering)
    s_w_v: float = 0.0  #: Σ ω / v
    s_vw: float = 0.0  #: Σ v ω (measured lateral acceleration, α̇ aside)
    s_F: float = 0.0  #: Σ F_xR (applied force)
    w_first: float = 0.0  #: ω of the opening sample
    ay_ref: float = 0.0  #: smallest |v_d ω_d| of the reference at the interval's ends
    v_first: float = math.nan  #: measured speed at the interval's first sample [m/s]


class CourseFusion:
    """Course and speed over ground from the measured positions, fitted against the model
    (see the module docstring). Call :meth:`sample` every T_d and :meth:`close` at every MPC
    step, before the MPC runs."""

    def __init__(self, Tc: float, position_sigma: float, vehicle: VehicleParams | None = None) -> None:
        self.Tc = float(Tc)
        self.sigma = max(float(position_sigma), 1e-4)
        self.vehicle = vehicle
        self.reset()

    def reset(self) -> None:
        """Forget everything: corrections back to zero."""
        self._iv: deque[_Interval] = deque(maxlen=BASELINE)
        self._cur: _Interval | None = None
        self._omega_now = 0.0
        self._v_now = math.nan
        self._theta = np.zeros(2)  # [κ, β]
        self._P = np.diag(np.square(SLIP_PRIOR))
        self._sv = 0.0  # speed-offset fit: Σ w b, Σ w
        self._sw = 0.0
        self.n_chords = 0
        # measured noise level: Σ (innovation / σ_chord)² and Σ 1 of the slip fit on straights
        self._n2 = NOISE_PRIOR_CHORDS
        self._n1 = NOISE_PRIOR_CHORDS
        # compliance fits α = F / C per axle: Σ w F α, Σ w F² with the prior 1/C_model of
        # standard deviation STIFF_PRIOR_REL / C_model, i.e. information (C_model / REL)²
        p = self.vehicle
        c0 = np.array((p.C_f, p.C_r) if p is not None else (1.0, 1.0))
        self._prior_den = np.square(c0 / STIFF_PRIOR_REL)
        self._prior_num = self._prior_den / c0
        self._c0 = c0  # the model's (C_f, C_r): the plausible range of a chord's own stiffness
        self._cnum = self._prior_num.copy()
        self._cden = self._prior_den.copy()
        self._alpha_hat_prev: float | None = None

    @property
    def slip_params(self) -> tuple[float, float]:
        """(κ̂ [rad per m/s²], β̂ [rad])."""
        return float(self._theta[0]), float(self._theta[1])

    def slip_correction(self, a_y: float) -> float:
        """κ̂ a_y + β̂ [rad], bounded by ``SLIP_CORRECTION_MAX``."""
        if not math.isfinite(a_y):
            a_y = 0.0
        c = float(self._theta[0] * a_y + self._theta[1])
        return min(max(c, -SLIP_CORRECTION_MAX), SLIP_CORRECTION_MAX)

    @property
    def noise_scale(self) -> float:
        """The chords' slip noise as measured on straights, over the configured σ's (≥ 1: the
        configured σ is a floor)."""
        return math.sqrt(max(1.0, self._n2 / self._n1))

    @property
    def speed_offset(self) -> float:
        """Estimated speed-sensor offset [m/s] (measured − true)."""
        if self._sw <= 0.0:
            return 0.0
        return min(max(self._sv / self._sw, -SPEED_OFFSET_MAX), SPEED_OFFSET_MAX)

    @property
    def stiffness(self) -> tuple[float, float] | None:
        """(Ĉ_f, Ĉ_r) [N/rad]: the inverse of the fitted compliances (the model's until data
        outweigh the prior), within ``STIFF_RANGE`` × the model's; None without a vehicle."""
        p = self.vehicle
        if p is None:
            return None
        lo, hi = STIFF_RANGE
        comp = self._cnum / self._cden
        c = np.where(comp > 0.0, 1.0 / np.maximum(comp, 1e-12), np.inf)
        return (min(max(float(c[0]), lo * p.C_f), hi * p.C_f),
                min(max(float(c[1]), lo * p.C_r), hi * p.C_r))

    def model_changed(self) -> None:
        """The MHE's model got new stiffnesses: the slip fit's κ restarts from its prior (it was
        the a_y-proportional error of the previous model, which the new one no longer makes;
        kept, it corrects a bias that has gone, for its memory). β, a heading-sensor offset that
        no model change explains, is kept."""
        self._theta[0] = 0.0
        self._P[0, :] = 0.0
        self._P[:, 0] = 0.0
        self._P[0, 0] = SLIP_PRIOR[0] * SLIP_PRIOR[0]

    def sample(self, ok: bool, theta: float, v: float, alpha_hat: float, a_y: float,
               omega: float = 0.0, delta: float = 0.0, force: float = 0.0) -> None:
        """One T_d sample: measured heading θ, speed v (raw) and yaw rate ω, the estimate's α̂
        and â_y = v̂ ω̂, the applied steering δ and force F_xR; ``ok`` False for a missing or
        rejected sample (spoils the interval)."""
        cur = self._cur
        if cur is None:
            return
        if not (ok and math.isfinite(theta) and math.isfinite(v) and math.isfinite(alpha_hat)
                and math.isfinite(a_y) and math.isfinite(omega) and math.isfinite(delta)
                and math.isfinite(force)):
            cur.ok = False
            return
        dth = _wrap(theta - cur.start[2])
        w = 0.5 if cur.n == 0 else 1.0  # trapezoid: the opening sample counts half
        if cur.n == 0:
            cur.w_first = omega
            cur.v_first = v
        cur.n += 1
        cur.sv_full += v
        cur.s_delta += delta
        cur.s_w_v += omega / max(v, 1.0)
        cur.s_vw += v * omega
        cur.s_F += force
        cur.sv += w * v
        cur.sv_dth += w * v * dth
        cur.sv_alpha += v * alpha_hat
        cur.sv_ay += v * a_y

    def close(self, pose: NDArray[np.float64] | None, v: float, omega: float = 0.0,
              ay_ref: float = 0.0) -> None:
        """An MPC step: ``pose`` the measured pose now (None if missing: no chord ends here),
        ``v`` and ``omega`` the measured speed and yaw rate now (the closing sample), ``ay_ref``
        the reference's lateral acceleration v_d ω_d now."""
        self._omega_now = omega
        self._v_now = v
        ay = abs(ay_ref) if math.isfinite(ay_ref) else 0.0
        cur = self._cur
        good = pose is not None and bool(np.all(np.isfinite(pose))) and math.isfinite(v)
        if cur is not None:
            cur.ay_ref = min(cur.ay_ref, ay)
            if good and cur.n > 0 and cur.ok:
                assert pose is not None
                dth = _wrap(float(pose[2]) - cur.start[2])
                cur.sv += 0.5 * v
                cur.sv_dth += 0.5 * v * dth
            else:
                cur.ok = False
            self._iv.append(cur)
            if good and len(self._iv) == BASELINE and all(i.ok for i in self._iv):
                assert pose is not None
                self._chord(np.asarray(pose, dtype=float))
        self._cur = _Interval(start=tuple(float(c) for c in pose), ay_ref=ay) if good else None  # type: ignore[arg-type, union-attr]

    def _chord(self, end: NDArray[np.float64]) -> None:
        first = self._iv[0].start
        dx, dy = float(end[0] - first[0]), float(end[1] - first[1])
        chord = math.hypot(dx, dy)
        if chord < MIN_CHORD_M:
            return
        # speed-weighted means over the chord (θ relative to the chord's first pose)
        sv = sum(i.sv for i in self._iv)
        if sv <= 0.0:
            return
        sv_th = sum(i.sv_dth + _wrap(i.start[2] - first[2]) * i.sv for i in self._iv)
        th_mean = first[2] + sv_th / sv
        n = sum(i.n for i in self._iv)
        sv_full = sum(i.sv_full for i in self._iv)
        a_course = _wrap(math.atan2(dy, dx) - th_mean)
        alpha_hat = sum(i.sv_alpha for i in self._iv) / sv_full
        a_y = sum(i.sv_ay for i in self._iv) / sv_full
        self.n_chords += 1
        # slip: z = ᾱ_course − ᾱ̂ = κ ā_y + β, weighted by the chord's noise (positions at both ends)
        z = a_course - alpha_hat
        sig0 = 2.0 * math.sqrt(2.0) * self.sigma / chord + 2e-4
        # where the reference turns (its turn, not the car's, so that weaving is no corner): the
        # stiffness fit below takes only such chords; where it runs straight the slip and the
        # model's error in it are ≈ 0, so the fit's innovation there is the chord's noise, and its
        # level scales the configured σ up (positions noisier than the config says)
        cornering = min(i.ay_ref for i in self._iv) >= CORNER_ACCEL
        phi = np.array([a_y, 1.0])
        innov = z - phi @ self._theta
        if not cornering:
            g_n = 1.0 - self.Tc / NOISE_MEMORY_S
            r = innov / sig0  # (a scalar: 1-D @ 1-D, which numpy's stubs type as an array)
            self._n2 = g_n * self._n2 + r * r  # type: ignore[assignment]
            self._n1 = g_n * self._n1 + 1.0
        sig = sig0 * self.noise_scale
        lam = 1.0 - self.Tc / SLIP_MEMORY_S
        P = self._P / lam
        k = P @ phi / (sig * sig + phi @ P @ phi)
        self._theta = self._theta + k * innov
        self._P = P - np.outer(k, phi @ P)
        # speed over ground: the arc of the chord (turn Δχ ≈ Δθ) over its time span
        turn = abs(_wrap(float(end[2]) - first[2]))
        arc = chord * ((0.5 * turn) / math.sin(0.5 * turn) if turn > 1e-6 else 1.0)
        v_ground = arc / (BASELINE * self.Tc)
        v_meas = sv / n  # the trapezoid mean of the measured speed over the chord's time
        w = (chord / (2.0 * self.sigma)) ** 2
        g = 1.0 - self.Tc / SPEED_MEMORY_S
        self._sv = g * self._sv + w * (v_meas - v_ground)
        self._sw = g * self._sw + w
        # axle stiffnesses from the course's slip (quasi-steady single track):
        # lateral force S = M v (ω + α̇) + F_x α and yaw moment T = I ω̇ give F_yF = (b S + T)/L,
        # F_yR = (a S − T)/L; slips α_F = δ − α − a ω/v, α_R = b ω/v − α (chord means). The fit
        # is of the compliance 1/C with the force as regressor (slip = F / C): the forces come
        # from v, ω (precise), the slips carry the course's noise — as the response, noise does not
        # bias the fit (as a regressor it would pull C towards 0 on every straight).
        p = self.vehicle
        vw = sum(i.s_vw for i in self._iv) / n
        # and only where the reference turns (``cornering``): a straight carries no information on
        # C (slips and forces ≈ 0), only the traces of a lightly damped yaw motion (the same Monza
        # case drifted there)
        # and at nearly constant speed (pure slip: STIFF_MAX_ACCEL); a NaN speed fails the test
        a_x = (self._v_now - self._iv[0].v_first) / (BASELINE * self.Tc)
        steady = p is not None and abs(a_x) <= STIFF_MAX_ACCEL * p.g
        if p is not None and math.isfinite(self._omega_now) and cornering and steady:
            span = BASELINE * self.Tc
            # α̇ from the model's α̂ over consecutive chords (smooth; the course's own α would put
            # its noise through a 1/T_c difference into the force)
            ah_prev, self._alpha_hat_prev = self._alpha_hat_prev, alpha_hat
            al_dot = 0.0 if ah_prev is None else (alpha_hat - ah_prev) / self.Tc
            S = p.mass * (vw + v_meas * al_dot) + sum(i.s_F for i in self._iv) / n * a_course
            T = p.inertia * (self._omega_now - self._iv[0].w_first) / span
            L = p.a + p.b
            w_v = sum(i.s_w_v for i in self._iv) / n
            delta = sum(i.s_delta for i in self._iv) / n
            slips = np.array([delta - a_course - p.a * w_v, p.b * w_v - a_course])
            forces = np.array([(p.b * S + T) / L, (p.a * S - T) / L])
            # per axle, only a chord whose own stiffness F / slip is a plausible one (the sign and
            # STIFF_RANGE × the model's): anything else is no quasi-steady pure-slip chord (a
            # transient, a lag between forces and slips, a saturated tyre) and would drag the fit to
            # its bounds (on Spa at 22 m/s one corner took it to 2× and doubled the largest e_y)
            lo, hi = STIFF_RANGE
            fa, sa = np.abs(forces), np.abs(slips)
            ok = (forces * slips > 0.0) & (sa * hi * self._c0 >= fa) & (sa * lo * self._c0 <= fa)
            forces, slips = np.where(ok, forces, 0.0), np.where(ok, slips, 0.0)
            # the chord's weight: its slip noise (the course's, or the fit's own floor), shared
            # with the neighbouring chords (STIFF_CORRELATION)
            s_slip = max(sig, STIFF_SLIP_FLOOR)
            w_c = 1.0 / (STIFF_CORRELATION * s_slip * s_slip)
            g2 = 1.0 - self.Tc / STIFF_MEMORY_S
            # forgetting towards the prior (a fit without excitation returns to the model)
            self._cnum = g2 * self._cnum + (1.0 - g2) * self._prior_num + w_c * (forces * slips)
            self._cden = g2 * self._cden + (1.0 - g2) * self._prior_den + w_c * (forces * forces)


class MassEstimator:
    """ΔM from the friction estimate and the window's acceleration (see the module docstring).
    Call :meth:`update` every T_d with the MHE's v̂ and F̂."""

    def __init__(self, mass: float, Td: float, window: int) -> None:
        self.mass = float(mass)
        self.Td = float(Td)
        self.window = int(window)
        self.reset()

    def reset(self) -> None:
        """Forget everything: ΔM̂ = 0."""
        self._v: deque[float] = deque(maxlen=self.window + 1)
        self._lf = self._la = 0.0
        self._open = False
        self._sxy = self._sxx = 0.0
        self.accel = 0.0

    @property
    def delta_mass(self) -> float:
        """ΔM̂ [kg] (0 until the fit is excited), within ``MASS_RANGE`` × the model mass."""
        if self._sxx < MASS_EXCITATION:
            return 0.0
        lo, hi = MASS_RANGE
        return min(max(self._sxy / self._sxx, lo * self.mass), hi * self.mass)

    def update(self, v_hat: float, F_hat: float) -> float:
        """Add one sample; returns ā, the window's mean acceleration [m/s²]."""
        if not (math.isfinite(v_hat) and math.isfinite(F_hat)):
            self._open = False
            return self.accel
        self._v.append(v_hat)
        n = len(self._v) - 1
        self.accel = (self._v[-1] - self._v[0]) / (n * self.Td) if n > 0 else 0.0
        if n < self.window or min(self._v) <= MASS_MIN_SPEED:
            self._open = False  # the high-pass restarts when the fit opens again
            return self.accel
        a = self.accel
        if not self._open:
            self._lf, self._la, self._open = F_hat, a, True
        g = self.Td / MASS_HIGHPASS_S
        self._lf += g * (F_hat - self._lf)
        self._la += g * (a - self._la)
        y, x = F_hat - self._lf, a - self._la
        lam = 1.0 - self.Td / MASS_MEMORY_S
        self._sxy = lam * self._sxy + x * y
        self._sxx = lam * self._sxx + x * x
        return a


class Fusion:
    """The switches of ``cfg.fusion`` as one object the cascade calls (each part idle when its
    switch is off)."""

    def __init__(self, cfg: Config) -> None:
        self.settings: FusionSettings = cfg.fusion
        self.Td, self.Tc = cfg.rates.Td, cfg.rates.Tc
        self.guard = RepeatGuard()
        self.course = CourseFusion(self.Tc, cfg.noise.position * cfg.noise.scale, cfg.vehicle)
        self.mass = MassEstimator(cfg.vehicle.mass, self.Td, cfg.mhe.N)
        self.tau = cfg.lqr.speed_time_constant
        self.speed_feedback = cfg.lqr.speed_feedback

    def reset(self, pose: NDArray[np.float64] | None) -> None:
        """Start over from ``pose`` (None: the first measured one)."""
        self.guard.reset()
        self.course.reset()
        self.mass.reset()

    @property
    def any_course(self) -> bool:
        """The course fusion runs (for the slip, the speed or the stiffnesses)."""
        s = self.settings
        return s.course_slip or s.course_speed or s.stiffness_estimate

    def speed_offset(self) -> float:
        """The speed-sensor offset to remove (0 with ``course_speed`` off)."""
        return self.course.speed_offset if self.settings.course_speed else 0.0

    def slip_correction(self, a_y: float) -> float:
        """The correction added to α̂ for the outer loop (0 with ``course_slip`` off)."""
        return self.course.slip_correction(a_y) if self.settings.course_slip else 0.0

    def inertia_terms(self, v_hat: float, F_hat: float, v_ref: float) -> float:
        """The force to add to the compensated F̂ (0 with ``mass_estimate`` off):
        −ΔM̂ ā (the mass error's inertia is not friction) + ΔM̂ (v_ref − v̂)/τ (the speed
        feedback's missing mass)."""
        if not self.settings.mass_estimate:
            return 0.0
        a = self.mass.update(v_hat, F_hat)
        dm = self.mass.delta_mass
        if dm == 0.0 or not (math.isfinite(v_hat) and math.isfinite(v_ref)):
            return 0.0
        out = -dm * a
        if self.speed_feedback:
            out += dm * (v_ref - v_hat) / self.tau
        return out
