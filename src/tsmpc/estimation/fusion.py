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
  uses in any case; with ``course_slip`` along the slip fit's velocity heading θ + α̂ + κ̂ v̂ ω̂ + β̂,
  at the car's own lateral acceleration: between poses at 1–2 Hz an α̂ a few mrad off is the pose's
  drift, centimetres per pose). The paper-faithful alternative (hold the last pose) makes the reference run
  ahead of a frozen car: one lost MPC sample at 13 m/s is a 1.3 m jump of e_x, which the MPC
  answers with a full-throttle v_ref (issue 21: 795 saturated inner steps at 5 % random dropouts).
* :class:`CourseFusion` (``course_slip``, ``course_speed``) — the measured positions give the
  course and the speed over ground without any model: over a chord between two measured poses
  the chord's direction is the (speed-weighted) mean of the velocity heading θ + α, and its
  length over the time is the mean speed (arc/chord corrected for the turn). Two least-squares fits
  with forgetting use them:

  - **any pose rate** (issue 35: the pose at 1–10 Hz, speed and yaw rate at every T_d): an
    accepted pose ends the open interval at an MPC step, and between MPC steps once the interval
    has lasted a T_c; a chord is the shortest run of the latest intervals that lasts ``BASELINE``
    T_c (0.5 s), at most ``CHORD_MAX_S``, and its time span is the calls it counts, whatever the
    rate. Between poses the samples need only a speed and a yaw rate: the heading is the last
    accepted pose's plus the integral of the bias-free yaw rate (θ̇ = ω, exact kinematics; the
    gyro fit below removes the bias first), so a missing or rejected pose does not spoil the
    interval. Each chord adds the time of its last interval to the fits' memories (forgetting per
    second, not per chord), and the stiffness fit counts a chord as one independent slip
    measurement per ``STIFF_CORRELATION`` T_c of new data, its α̇ term's lag beyond T_c as noise
    (:func:`_stiffness_fit`). With a pose at every call the intervals are the MPC periods and the
    chords those of ``BASELINE`` of them, as before issue 35 (the results are the same to the
    bit); below 10 Hz no chord used to complete and every fit stayed at its prior;

  - the slip: ᾱ_course − ᾱ̂ = κ ā_y + β (ā_y = v̂ ω̂ the lateral acceleration). A stiffness or mass
    error biases the MHE's α̂ in proportion to the lateral force (steady state of the single-track
    model: α depends on C_r and M through M a_y / C_r), so κ carries the model error and β a
    heading-sensor offset. Both are steady errors: a chord along which α̂ changes (a transient,
    where the MHE's window and any actuator lag shift α̂ against the car's slip) counts the
    share ``SLIP_TRANSIENT_S`` |α̇| of its slip as error.
    The outer loop uses α̂ + κ̂ a_y,d + β̂ with a_y,d = v_d ω_d the *reference's* lateral
    acceleration (issue 21: 5 mrad of α̂ bias cost 0.08 m of RMSE y). The measured a_y would close
    a loop ω → a_y → slip → e_θ → ω without the tyres' lag, fast enough to destabilise a car
    whose rear grip is 30 % below the model's (it did, in a trial); the reference's is exogenous.
    κ explains the error of the model the MHE runs *now*: when the stiffness fit below gives
    the MHE new stiffnesses, κ restarts from its prior (β stays). Kept, it went on correcting
    the old model's bias for its memory on top of the new model's correct α̂ (issue 21: with
    C_f 30 % below the model's, RMSE y 0.0095 → 0.0062 m, the oracle-tuned controller's 0.0043);
  - the speed sensor's offset o and scale error e, v_measured = (1 + e) v + o: each interval's
    v̄_measured − v_ground = c + k v̄_measured, c = o / (1 + e), k = e / (1 + e) (least squares in
    information form, with a prior on each, σ = ``SPEED_PRIOR``, forgetting towards it over
    ``SPEED_MEMORY_S``, weighted by the intervals' measured noise level). Every interval between
    two poses is used, however short: its ground speed is its length over its time, whose error is
    the positions' √2 σ / D (and ``SPEED_MODEL_SIGMA``), whatever the speed.
    The offset is observable on any interval, at rest too (the car has not moved: the sensor reads
    o); the scale only while the speed varies (the launch, braking). At a constant speed the pair
    explains the one offset that speed shows, split by the priors, and the scale stays near its
    prior. The ground speed v − ĉ − k̂ v = (v − ô) / (1 + ê) goes to the MHE (and from its estimate
    to the inner loop).

  - the axle cornering stiffnesses (``stiffness_estimate``): with the chord's slip ᾱ from the
    course, the axle forces from the measured lateral and yaw accelerations and the slips of the
    single-track model, F_yF = C_f (δ − α − a ω/v) and F_yR = C_r (b ω/v − α) are
    fitted per axle (least squares through the origin on the compliance 1/C, Bayesian: the
    model's C as prior with a relative σ of ``STIFF_PRIOR_REL``, each chord weighted by its slip
    noise, forgetting over ``STIFF_MEMORY_S``), from chords where the reference turns
    (``CORNER_ACCEL``) and the car neither accelerates nor brakes (``STIFF_MAX_ACCEL``) over at most
    ``STIFF_MAX_SPAN_S``, per axle
    only where the chord's own F / slip is a plausible stiffness (``STIFF_RANGE``, widened by
    ``STIFF_BAND_SIGMAS`` of the chord's slip noise: the slip is the fit's noisy response, and a
    hard cut at the band's edges censored it — with an effective stiffness near the band's edge, a
    mass, CoG and stiffness error together, half the chords or all of them were cut and the fit
    stayed at the model's). The
    fitted C_f, C_r replace the model's in the MHE and in the inner loop's reference gain N̄ (the
    LMI gains stay): with them α̂ and the steering feed-forward are right (issue 21: the stiffness
    error was worth 0.08 m of RMSE y; with the true C in both blocks the loss disappears, in the
    LMI gains alone it does not).
  - the lateral model jointly (issue 35, :class:`LateralFit`, with ``stiffness_estimate``): the
    compliance fit above holds the model's CoG and yaw inertia, so a CoG or inertia error ends up
    in its stiffnesses. On the same chords an extended Kalman filter fits (a / L, I_z / I_z,0,
    C_f,0 / C_f, C_r,0 / C_r, δ_r) together (:func:`_lateral_fit`): both axles' slip equations with
    the forces split by the unknown CoG and the yaw moment I_z ω̇, the prior the model's values
    (``LATERAL_PRIOR``), each chord's slip noise inflated by the chords' correlation
    (``STIFF_CORRELATION``), by the error of its α̇ term (α̂'s rate along the chord, as large as
    the term: α̂ follows the model this fit hands over) and by the tyres' nonlinearity
    (``LATERAL_NONLINEAR``). **Observable**: the compliances
    and the CoG in any corner, the inertia only where ω̇ ≠ 0 (a corner's entry and exit); a
    parameter no chord informs holds its prior exactly (no process noise, no forgetting). M is the
    model's: a mass error scales the fitted C and I_z with it, which leaves the lateral dynamics of
    the MHE's model, run with the model's M, those of the car. Its model (C_f, C_r, I_z, a, b) is
    handed to the MHE, the TS-LQR's N̄ and the steering-offset fit's balance only where the
    reference runs straight (:func:`stiffness_update`); until its first hand-over the compliance
    fit gives its stiffnesses, in corners too.

  The fits compare like with like (means over the same chord), so the chord's lag in a transient
  does not bias them; only chords of measured (not predicted) poses count. Each chord is weighted
  by its slip noise: the configured position σ over the chord's length, scaled up by the noise
  level the slip fit measures where the reference runs straight (there the slip and the model's
  error in it are ≈ 0, so its innovation is noise: ``noise_scale``) — positions noisier than the
  config says then count for less instead of driving the fits.
* :class:`GyroFit` (``gyro_bias``) — the yaw-rate sensor's bias b (measured − true) as a slowly
  varying state. θ̇ = ω holds exactly (kinematics, no model, no tyre), so over a chord of D
  seconds between two *measured* headings (accepted poses with their θ; predicted poses never
  count) the bias is b = wrap(∫ω_measured dt − (θ_end − θ_start)) / D, observable at any speed,
  standing still included. The chord's noise is √(2 σ_θ² + D T_d σ_ω²) / D (the configured heading
  and yaw-rate σ's), its weight the inverse square; the estimate is the weighted mean of the chords
  with forgetting over ``GYRO_MEMORY_S`` (a drifting bias, a gyro's bias instability, is tracked
  with a lag of about the memory), the prior 0 with σ ``GYRO_PRIOR_SIGMA``. Chords last
  ``GYRO_CHORD_S``; a fresh fit closes them sooner, as soon as one chord weighs as much as the fit
  so far (one sample, then geometrically longer), so the bias is known within tenths of a second
  after the start (a 0.01 rad/s bias uncorrected for the first second cost 0.017 m of e_y on the
  built-in circuit). A missing yaw rate is held (trapezoid) for at most ``GYRO_MAX_GAP_S``, beyond
  that the chord is dropped. **Unobservable** — no pose, a pose without heading
  (``scenario.sensors.pose_heading`` false), rejected poses — no chord ends: the estimate holds
  where it was (the prior 0 if none came yet) and does not drift; nothing is extrapolated.
  The bias is removed from ω before everything that uses the measured yaw rate: the MHE's
  measurement (hence ω̂ for the TS-LQR and the dead reckoning) and the course fusion (its lateral
  acceleration v ω and slip terms ω / v model the true yaw rate; a biased ω there would bias the
  stiffness fit). The fit itself takes the *raw* ω: it estimates the sensor's whole bias directly,
  and no estimate feeds back into its own data. A heading sensor whose offset *drifts* is
  indistinguishable from a gyro bias here (both change ∫ω − Δθ); a constant heading offset cancels.
* :class:`MassEstimator` (``mass_estimate``) — the MHE's window-constant friction force F̂ takes up
  whatever force the model does not explain; with a mass error that includes ΔM ā, the inertia of
  the extra mass (ā = the window's mean acceleration). Compensating it feeds the acceleration back
  with the window's delay, and the speed feedback M (v_ref − v̂)/τ runs with the wrong mass: the
  two fight (issue 21: 946 saturated steps at +20 % mass, 700 with the true mass in the
  controllers). ΔM is fitted by least squares to the *high-passed* F̂ and ā (the road's resistance
  changes slowly and drops out; forgetting over ``MASS_MEMORY_S``), above ``MASS_MIN_SPEED``
  (below, the model's low-speed clipping makes F̂ meaningless). The compensation then gets
  F̂ − ΔM̂ ā and the speed feedback (M + ΔM̂)(v_ref − v̂)/τ.
* :func:`steer_sample` (``steering_offset``) — the wheels stand at δ_servo + δ₀ (a toe or steering
  sensor misalignment nothing else sees: the MHE explains its yaw moment as slip, the TS-LQR's
  integrator works against it, and the car tracks with a lateral offset). δ₀ is a slow state
  fitted from the steady yaw balance of the MHE's single-track model (α̇ = ω̇ = 0):
  δ_eq = g(v) ω (:func:`steer_gain`, g ≈ L / v + K_us v), so the residual
  r = g(v) ω_f − δ_f = δ₀ + ΔK v ω_f + e of the bias-free measured yaw rate and the steering sent
  (both filtered over ``STEER_FILTER_S``) is regressed on (1, a_y) — ΔK, an understeer-gradient
  error (C_f, C_r, CoG), is a nuisance regressor so a curve is not read as an offset — by
  information-form least squares with forgetting over ``STEER_MEMORY_S`` towards the prior
  (0 with σ ``STEER_PRIOR_SIGMA``, ``STEER_K_PRIOR_SIGMA``); a moving steering (a transient)
  weighs less. **Observable** whenever the car moves faster than ``STEER_V_MIN`` with the tyres
  in their linear range (|a_y| ≤ ``STEER_AY_MAX``), straights included (there r = −δ_f directly).
  **Frozen** — the state held, nothing forgotten — on a missing or rejected sample, a failed
  MHE, a saturated or blind inner loop, below ``STEER_V_MIN`` or above ``STEER_AY_MAX``. The
  estimate shrunk by ``STEER_DEADBAND`` is subtracted from the servo command (clipped to the servo's
  limits) and added to the steering the MHE's model gets: a bias correction without feedback
  into its own data (the fit reads the angle sent, whatever was subtracted). It holds during a
  blind stop (the wheels' offset does not go away). When the stiffness fit gives the MHE new
  C_f, C_r, g(v) uses them.

Each estimator's per-step logic is a block's one definition (:mod:`tsmpc.kernels.jit`): pure
``@jitable`` functions over ``NamedTuple`` records, the new state returned — :func:`repeat_check`;
:func:`course_sample`, :func:`course_close` (with :func:`course_chord`'s fits) and the outputs
:func:`slip_correction`, :func:`speed_update`, :func:`speed_offset`, :func:`noise_scale`, :func:`stiffness`,
:func:`stiffness_update`; :func:`gyro_sample` and :func:`gyro_bias`; :func:`mass_update`,
:func:`delta_mass`, :func:`inertia_force`; :func:`steer_sample`, :func:`steer_correction` and
:func:`steer_command`. The
classes below hold the records for :class:`~tsmpc.control.cascade.Cascade` and call them as
Python; the run engine (:mod:`tsmpc.kernels.engine`) and the batch compile the same functions. The
arithmetic is scalar (no numpy), so both run the same operations in the same order on any machine
(the slip fit's 2×2 products no longer depend on the BLAS).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, FusionSettings, VehicleParams
from tsmpc.kernels.jit import exact_hypot, jitable

__all__ = [
    "BASELINE", "MASS_START", "NO_INTERVAL", "N_CP", "REPEAT_START", "RING", "CourseFusion", "CourseParams",
    "CourseState", "Fusion", "GyroFit", "GyroParams", "GyroState", "Interval", "LateralFit", "MassEstimator",
    "MassParams", "MassState", "RepeatGuard", "RepeatState", "SlipFit", "SpeedFit", "SteerParams",
    "SteerState", "StiffFit", "course_chord", "course_close", "course_ends", "course_params", "course_sample",
    "course_start", "delta_mass", "ground_speed", "gyro_bias", "gyro_params", "gyro_sample", "gyro_start",
    "inertia_force", "interval_speed", "lateral_model", "lateral_start", "mass_update",
    "model_changed", "noise_scale", "pack_course", "repeat_check", "slip_correction", "speed_offset",
    "speed_sensor", "speed_update", "steer_command", "steer_correction", "steer_gain", "steer_offset",
    "steer_params", "steer_sample", "steer_sigma", "steer_start", "steer_stiffness", "stiffness",
    "stiffness_update", "unpack_course",
]

#: Shortest chord of the course fusion, in MPC periods T_c (0.5 s at the default rates): at the
#: nominal sensors exactly ``BASELINE`` MPC intervals between measured poses.
BASELINE = 5
#: Intervals held for the chords (a chord is the shortest run of the latest ones lasting
#: ``BASELINE`` T_c; more than ``BASELINE`` where missing poses made some shorter than T_c).
RING = 8
#: Longest chord [s]. The chord's direction is the speed-weighted mean of θ + α only to second
#: order in the course's spread over the chord: on a curve whose curvature changes, the residual
#: grows with the cube of the turn (≈ 0.3 mrad for the 0.15 rad of 0.5 s at 0.3 rad/s, ≈ 8 mrad
#: for 1.5 s), and between poses the heading is the gyro's integral, whose error grows with the
#: time. 1.5 s keeps every pose rate from 0.67 Hz up (a 1 Hz pose gives 1 s chords); a chord
#: longer than this (poses lost at a low rate) is not fitted.
CHORD_MAX_S = 1.5
#: Shortest chord [m] the course and the speed over ground are measured on.
MIN_CHORD_M = 2.0
#: Memory of the slip fit [s] (forgetting factor 1 − T_c / memory per MPC step).
SLIP_MEMORY_S = 30.0
#: Memory of the speed sensor's fit [s].
SPEED_MEMORY_S = 10.0
#: Prior standard deviations of the speed sensor's offset [m/s] and scale-factor error [-]. A
#: wheel-speed sensor's scale is the tyre's rolling radius, a few per cent over its pressure, load
#: and wear; the class the generalisation benchmark draws from is ±0.5 m/s and ±3 %.
SPEED_PRIOR = (0.5, 0.03)
#: The speed over ground's error beyond the positions' noise [m/s]: the chord's mean speed is the
#: CoG's path speed, the sensor's the longitudinal one (a β of 0.05 rad differs by 0.1 %), and the
#: arc's correction assumes a constant curvature along the chord.
SPEED_MODEL_SIGMA = 0.01
#: Prior standard deviations of the slip fit: κ [rad per m/s²] and β [rad].
SLIP_PRIOR = (0.005, 0.02)
#: Lag [s] between the model's α̂ and the car's slip the slip fit allows for, as error: a chord
#: along which α̂ changes at α̇ carries SLIP_TRANSIENT_S |α̇| of slip error beyond its noise. The
#: MHE's α̂ is a window estimate (30 T_d = 0.3 s at the defaults) and an actuator's lag, which no
#: model has, shifts the car's slip against it in the same way; κ and β are a steady model error,
#: and a transient's error, whose sign flips with the steering's direction, made κ swing between
#: −0.009 and +0.007 rad per m/s² within one chicane (the mismatch benchmark's Monza with a 50 ms
#: steering servo: max |e_y| 0.154 → 0.136 m, mean of seeds 2–3; no case of the benchmark worse
#: by over 7 %, within its seed-to-seed spread).
SLIP_TRANSIENT_S = 0.3
#: Seconds of chords after a reset before the fits of the model's lateral error (the slip fit's
#: κ, the stiffnesses) learn. A run starts from a state the car was not in (zero lateral slip at
#: speed, mid-corner on a closed track; the MHE at its prior): its first chords are the lateral
#: dynamics' start-up transient, not the model's steady error. The model car's single-track
#: lateral dynamics at 30 m/s have the eigenvalues −2.4 ± 3.5i 1/s, a time constant of 0.41 s
#: (0.27 s at 20 m/s): five of them, 2 s, leave under 1 % of the start. Meanwhile the slip offset β
#: (a heading or steering offset is there from the first chord: it is fitted alone, κ held at its
#: prior), the speed fit and the chords' noise level learn. Without it, held-back race tracks at
#: 30 m/s learnt κ = 0.011 (twice its prior σ) within the first two seconds and left the road.
FIT_SETTLE_S = 2.0
#: Largest slip correction applied [rad] (a fit beyond it is a broken sensor, not a model error).
SLIP_CORRECTION_MAX = 0.05
#: Largest speed offset removed [m/s].
SPEED_OFFSET_MAX = 2.0
#: Largest speed scale-factor error removed (the config's sensor scale range is 0.8–1.2).
SPEED_SCALE_MAX = 0.2
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
#: Noise σ's of a chord's slip by which the band of plausible stiffnesses is widened.
STIFF_BAND_SIGMAS = 1.0
#: Smallest lateral acceleration of the *reference* v_d ω_d [m/s²] all along a chord for it to count
#: in the stiffness fit (the reference, not the car: a car weaving on a straight is no corner).
CORNER_ACCEL = 0.2
#: Shortest chord [s] of the yaw-rate bias fit: the heading noise enters a chord's bias as
#: √2 σ_θ / D, the yaw rate's as σ_ω √(T_d / D); at the default σ's (1e-4 rad, 1e-4 rad/s) one
#: 1 s chord measures the bias to 1.4e-4 rad/s, and longer chords would only answer a drifting
#: bias later.
GYRO_CHORD_S = 1.0
#: Memory of the yaw-rate bias fit [s] (forgetting exp(−D / memory) per chord of D seconds): a
#: gyro's bias wanders (bias instability, temperature); at the default σ's the ≈ 40 chords it
#: averages hold the estimate's noise near 2e-5 rad/s. Tuned on the built-in circuit (REF, seed 1):
#: with a random-walk bias of 1e-3 rad/s/√s RMSE y 0.0355 m without the fit, 0.0260 m with 20 s,
#: 0.0170 m with 5 s, the calibrated gyro and a constant bias alike at both; but at 5 s the
#: estimate's noise cost the mismatch benchmark's nominal paper-reference run 5.5 % of max |e_y|
#: (at 20 s every column of the benchmark is within 2.1 % of the run without the fit).
GYRO_MEMORY_S = 20.0
#: Prior standard deviation of the yaw-rate sensor's bias [rad/s] (prior mean 0): 0.05 rad/s ≈
#: 2.9 °/s, the zero-rate offset of an uncalibrated consumer MEMS gyro; one chord outweighs it.
GYRO_PRIOR_SIGMA = 0.05
#: Largest yaw-rate bias removed [rad/s] (the sensor model's range of ``omega_bias``).
GYRO_BIAS_MAX = 0.2
#: Longest time [s] a missing yaw rate is held inside a chord (beyond it the chord is dropped).
GYRO_MAX_GAP_S = 0.5
#: Smallest heading σ [rad] the fit's weights assume (a noiseless configuration would give a
#: chord an infinite weight).
GYRO_HEADING_FLOOR = 1e-5
#: Longest chord [s] the stiffness fit takes. The fit is quasi-steady: α̇ comes from consecutive
#: chords and the forces from chord means, so a long chord through a corner's entry or exit mixes
#: the transient into the means (the slip fit is linear in its means and takes chords up to
#: ``CHORD_MAX_S``). 1.0 s admits the chords of a 1 Hz pose.
STIFF_MAX_SPAN_S = 1.0
#: Largest longitudinal acceleration of the car over a chord [g] for it to count in the stiffness
#: fit. The fit is a pure-slip, constant-speed single-track fit; under traction or braking the
#: tyres' lateral stiffness drops (combined slip) and load moves between the axles (ΔF_z / F_z ≈
#: a h / (g L/2): ≈ 4 % per axle at 0.1 g for a CoG height of 0.5 m on a 2.5 m wheelbase), neither
#: of which the fit's model has. CommonRoad's multi-body van (vehicle 3), accelerating hard through
#: fast corners, drove the fit's front/rear balance 10 % off, and the MHE with that balance left
#: the road at 74 s; with the gate it tracks to 0.03 m.
STIFF_MAX_ACCEL = 0.1
#: Prior standard deviations of the joint lateral fit's parameters (:class:`LateralFit`): the CoG's
#: distance to the front axle as a fraction of the wheelbase, the yaw inertia and the two axle
#: compliances as fractions of the model's, and the steering residual [rad] (what the steering-offset
#: fit has not yet removed). The class the generalisation benchmark draws from: CoG ±10 % of L, I_z
#: ±30 %, C ±40 %.
LATERAL_PRIOR = (0.05, 0.3, 0.3, 0.3, 0.01)
#: The joint fit's model is handed over only where it departs from the model in force by more than
#: this many of its own σ in one of a / L, I_z, C_f, C_r (a statistical tolerance, not a tuning
#: knob: at 2 σ the fit never handed over on the paper reference's 70 s; at 0, on noise alone, the
#: GNSS noise × 10 case lost 8 % of RMSE y).
LATERAL_SIGNIFICANCE = 1.0
#: A magic-formula tyre's secant compliance exceeds its small-slip one by ≈ c (F_y / (μ F_z))²
#: (c ≈ 0.3 at the plant's shape C 1.3, E −0.5, up to F_y = 0.3 μ F_z); the fit, linear in the
#: slip, takes that excess as the chord's noise, at the models' μ_o = 0.5: c / μ_o² = 1.2 per
#: (F_y / F_z)². Without it the high-a_y chords' extra slip pulled a / L and C_r along their ridge
#: (replayed chords of the paper reference, C_f −40 %: a / L 0.394 against 0.423, C_r −11 %).
LATERAL_NONLINEAR = 1.2
#: Bounds of the joint fit: a / L, I_z / I_z,0 (the compliances: ``STIFF_RANGE``).
LATERAL_A_RANGE = (0.2, 0.8)
LATERAL_I_RANGE = (0.5, 2.0)


@jitable
def _wrap(a: float) -> float:
    """Angle to [−π, π) (the expression of :func:`tsmpc.models.kinematic.wrap_angle`)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


# ============================================================================ repeat guard
class RepeatState(NamedTuple):
    """The previous finite sample (``has`` False: none yet), stamp included (−inf without one)."""

    has: bool
    X: float
    Y: float
    theta: float
    v: float
    omega: float
    stamp: float


#: No previous sample.
REPEAT_START = RepeatState(False, 0.0, 0.0, 0.0, 0.0, 0.0, -math.inf)


@jitable
def repeat_check(s: RepeatState, X: float, Y: float, theta: float, v: float, omega: float,
                 stamp: float) -> tuple[bool, RepeatState]:
    """(the sample equals the previous finite one in all six numbers, the new state). A sample
    with a NaN is never a repeat and is not remembered; an infinite entry (a missing stamp as
    −inf) counts as a number."""
    if (math.isnan(X) or math.isnan(Y) or math.isnan(theta) or math.isnan(v) or math.isnan(omega)
            or math.isnan(stamp)):
        return False, s
    same = (s.has and X == s.X and Y == s.Y and theta == s.theta and v == s.v and omega == s.omega
            and stamp == s.stamp)
    return same, RepeatState(True, X, Y, theta, v, omega, stamp)


class RepeatGuard:
    """Is a sample [X, Y, θ, v, ω] (optionally with its stamp) bit-identical to the previous
    finite one? (The online wrapper of :func:`repeat_check`.)"""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the previous sample."""
        self.state = REPEAT_START
        self.n_repeated = 0

    def repeated(self, sample: tuple[float, ...]) -> bool:
        """True (counted) when ``sample`` (X, Y, θ, v, ω[, stamp]) equals the previous finite
        sample in every number (no stamp: −inf)."""
        X, Y, th, v, om = sample[:5]
        return self.repeated_at(X, Y, th, v, om, sample[5] if len(sample) > 5 else -math.inf)

    def repeated_at(self, X: float, Y: float, theta: float, v: float, omega: float, stamp: float) -> bool:
        """:meth:`repeated` of the sample (X, Y, θ, v, ω) with its stamp (none: −inf)."""
        same, self.state = repeat_check(self.state, X, Y, theta, v, omega, stamp)
        self.n_repeated += same
        return same


# ============================================================================ course fusion
class Interval(NamedTuple):
    """Sums of one interval between two measured poses (speed-weighted where the course needs it):
    at the nominal sensors one MPC period (see :func:`course_close` for where intervals end)."""

    open: bool  #: an interval is open (a measured pose started it); False: no interval
    ok: bool  #: every sample's speed and yaw rate measured and finite
    sx: float  #: measured pose at the interval's start
    sy: float
    sth: float
    n: int  #: samples
    sv: float  #: Σ v, trapezoid (the opening and closing samples count half)
    sv_dth: float  #: Σ v (θ − θ_start), trapezoid
    sv_alpha: float  #: Σ v α̂
    sv_ay: float  #: Σ v â_y
    sv_full: float  #: Σ v, every sample in full (the weights of α̂ and â_y)
    s_delta: float  #: Σ δ (applied steering)
    s_w_v: float  #: Σ ω / v
    s_vw: float  #: Σ v ω (measured lateral acceleration, α̇ aside)
    s_F: float  #: Σ F_xR (applied force)
    w_first: float  #: ω of the opening sample
    ay_ref: float  #: smallest |v_d ω_d| of the reference at the interval's ends
    v_first: float  #: measured speed at the interval's first sample [m/s]
    th_last: float  #: heading of the last sample (measured, or the gyro's integral since) [rad]
    w_last: float  #: ω of the last sample [rad/s]


#: No interval open (before the first measured pose, after a measured pose without a speed).
NO_INTERVAL = Interval(False, False, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                       0.0, 0.0, 0.0, 0.0)


class CourseParams(NamedTuple):
    """Parameters of the course fusion (:func:`course_params` builds them).

    Attributes:
        Tc: MPC period T_c [s] (one interval at the nominal sensors).
        sigma: configured position noise σ [m] (at least 0.1 mm).
        has_vehicle: a model vehicle is given (without one: no stiffness fit).
        C_f: the model's front axle cornering stiffness [N/rad] (1 without a vehicle).
        C_r: the model's rear axle cornering stiffness [N/rad] (1 without a vehicle).
        mass: the model vehicle's M [kg].
        inertia: its yaw inertia I_z [kg m²].
        a: the distance from the centre of gravity to the front axle [m].
        b: the distance from the centre of gravity to the rear axle [m].
        g: gravity [m/s²].
        prior_num_f: the front compliance fit's prior Σ w F α of the model's 1/C with relative σ
            ``STIFF_PRIOR_REL``: (C / REL)² / C.
        prior_num_r: the same for the rear axle.
        prior_den_f: the front compliance fit's prior Σ w F²: (C / REL)².
        prior_den_r: the same for the rear axle.
        Td: call period T_d [s] (the gyro's integration step between poses).
        n_inner: calls per MPC period (the cascade's ``n_inner``): a chord of n calls lasts
            (n / n_inner) T_c.
        chord_min: calls of the shortest chord, ``BASELINE`` × ``n_inner``.
        chord_max: calls of the longest chord (``CHORD_MAX_S``).
        stiff_max: calls of the longest chord the stiffness fit takes (``STIFF_MAX_SPAN_S``).
        lateral: the joint lateral fit runs and hands its model over (``fusion.lateral_fit``).
    """

    Tc: float
    sigma: float
    has_vehicle: bool
    C_f: float
    C_r: float
    mass: float
    inertia: float
    a: float
    b: float
    g: float
    prior_num_f: float
    prior_num_r: float
    prior_den_f: float
    prior_den_r: float
    Td: float
    n_inner: int
    chord_min: int
    chord_max: int
    stiff_max: int
    lateral: bool


#: Length of :func:`pack_course`'s vector (CourseParams' 20 fields, in its order).
N_CP = 20


def pack_course(p: CourseParams) -> NDArray[np.float64]:
    """The record as the float vector :func:`unpack_course` reads (compiled callers rebuild it:
    the cascade's compiled calls, the run engine's parameter slots)."""
    return np.array(p, dtype=np.float64)


@jitable
def unpack_course(a: NDArray[np.float64]) -> CourseParams:
    """The record of :func:`pack_course`'s vector."""
    return CourseParams(a[0], a[1], a[2] != 0.0, a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11],
                        a[12], a[13], a[14], int(a[15]), int(a[16]), int(a[17]), int(a[18]), a[19] != 0.0)


class SlipFit(NamedTuple):
    """The slip fit z = κ a_y + β (recursive least squares with forgetting) and the chords' noise
    level measured on straights (Σ (innovation / σ_chord)², Σ 1)."""

    kappa: float
    beta: float
    P00: float
    P01: float
    P10: float
    P11: float
    n2: float
    n1: float


class SpeedFit(NamedTuple):
    """The speed sensor's fit of (c, k) (:func:`speed_update`) in information form:
    Λ = [[l00, l01], [l01, l11]] and η = (h0, h1), the prior's included (Λ θ̂ = η), and the
    measured noise level's sums (n2 / n1: the intervals' variance over the assumed one)."""

    l00: float
    l01: float
    l11: float
    h0: float
    h1: float
    n2: float
    n1: float


#: The speed fit at its prior (offset and scale error 0; :func:`speed_update`'s c and k).
SPEED_START = SpeedFit(1.0 / (SPEED_PRIOR[0] * SPEED_PRIOR[0]), 0.0, 1.0 / (SPEED_PRIOR[1] * SPEED_PRIOR[1]),
                       0.0, 0.0, NOISE_PRIOR_CHORDS, NOISE_PRIOR_CHORDS)


class StiffFit(NamedTuple):
    """The compliance fits α = F / C per axle: Σ w F α and Σ w F² (front, rear, prior included),
    and α̂ of the previous cornering chord (``has_prev`` False: none)."""

    num_f: float
    num_r: float
    den_f: float
    den_r: float
    alpha_prev: float
    has_prev: bool


class LateralFit(NamedTuple):
    """The joint fit of the lateral model (an extended Kalman filter over the cornering chords):
    x = (a / L, I_z / I_z,0, C_f,0 / C_f, C_r,0 / C_r, δ_r) — the model's values divided out, so
    every entry is of order one — and its covariance ``P`` (the upper triangle, row by row)."""

    x: tuple[float, float, float, float, float]
    P: tuple[float, float, float, float, float, float, float, float, float, float, float, float, float,
             float, float]
    fitted: bool  #: a chord was fitted since the reset
    given: bool  #: the model in force is this fit's (the compliance fit no longer gives)


class CourseState(NamedTuple):
    """State of the course fusion between calls (the open interval is its own record).

    Attributes:
        ring: the last ``RING`` closed intervals, oldest first (only the last ``n_iv`` are real).
        n_iv: closed intervals held (at most ``RING``).
        omega_now: measured yaw rate at the last interval's end [rad/s].
        v_now: measured speed at the last interval's end [m/s].
        n_chords: chords fitted.
        slip: the slip fit.
        speed: the speed sensor's fit.
        stiff: the stiffness fit.
        since: calls since the last interval ended (a measured pose that ends no interval counts).
        age: seconds of chords since the reset (each adds its last interval's time); the lateral
            fits learn from ``FIT_SETTLE_S`` on.
        lat: the joint lateral fit.
    """

    ring: tuple[Interval, ...]
    n_iv: int
    omega_now: float
    v_now: float
    n_chords: int
    slip: SlipFit
    speed: SpeedFit
    stiff: StiffFit
    since: int
    age: float
    lat: LateralFit


@jitable
def course_params(Tc: float, position_sigma: float, has_vehicle: bool, C_f: float, C_r: float, mass: float,
                  inertia: float, a: float, b: float, g: float, Td: float, n_inner: int,
                  lateral: bool = True) -> CourseParams:
    """The parameters from the rates (T_c, T_d and the calls per MPC period), the configured
    position σ and the model vehicle (without one, C_f = C_r = 1 for the prior's arithmetic);
    ``lateral`` the joint lateral fit runs."""
    qf, qr = C_f / STIFF_PRIOR_REL, C_r / STIFF_PRIOR_REL
    den_f, den_r = qf * qf, qr * qr
    per_s = n_inner / Tc  # calls per second
    return CourseParams(Tc, max(position_sigma, 1e-4), has_vehicle, C_f, C_r, mass, inertia, a, b, g,
                        den_f / C_f, den_r / C_r, den_f, den_r, Td, n_inner, BASELINE * n_inner,
                        math.floor(CHORD_MAX_S * per_s + 1e-6), math.floor(STIFF_MAX_SPAN_S * per_s + 1e-6),
                        lateral and has_vehicle)


def course_start(p: CourseParams) -> CourseState:
    """The state after a reset: no interval, the fits at their priors (κ = β = 0, P the prior's
    variances, the noise level at its prior, the compliances at the model's)."""
    slip = SlipFit(0.0, 0.0, SLIP_PRIOR[0] * SLIP_PRIOR[0], 0.0, 0.0, SLIP_PRIOR[1] * SLIP_PRIOR[1],
                   NOISE_PRIOR_CHORDS, NOISE_PRIOR_CHORDS)
    stiff = StiffFit(p.prior_num_f, p.prior_num_r, p.prior_den_f, p.prior_den_r, 0.0, False)
    return CourseState((NO_INTERVAL,) * RING, 0, 0.0, math.nan, 0, slip, SPEED_START, stiff,
                       p.n_inner, 0.0, lateral_start(p))


def lateral_start(p: CourseParams) -> LateralFit:
    """The joint lateral fit at its prior (the model's values; a / L = 0.5 without a vehicle)."""
    u = p.a / (p.a + p.b) if p.has_vehicle else 0.5
    s0, s1, s2, s3, s4 = (q * q for q in LATERAL_PRIOR)
    return LateralFit((u, 1.0, 1.0, 1.0, 0.0), (s0, 0.0, 0.0, 0.0, 0.0, s1, 0.0, 0.0, 0.0, s2, 0.0, 0.0, s3,
                                                0.0, s4), False, False)


@jitable
def course_sample(p: CourseParams, cur: Interval, ok: bool, has_pose: bool, theta: float, v: float,
                  alpha_hat: float, a_y: float, omega: float, delta: float, force: float) -> Interval:
    """One T_d sample into the open interval: speed v (raw) and yaw rate ω (bias-free) measured,
    the estimate's α̂ and â_y = v̂ ω̂, the applied steering δ and force F_xR; ``ok`` False for a
    missing or rejected speed sample (spoils the interval). The heading θ is the measured one when
    an accepted pose came (``has_pose``), else the last sample's plus the trapezoid integral of ω
    over T_d (θ̇ = ω: a missing or rejected pose does not spoil the interval). No interval open:
    unchanged."""
    if not cur.open:
        return cur
    if has_pose and math.isfinite(theta):
        th = theta
    elif cur.n == 0:  # (the opening sample is the opening pose's)
        th = cur.sth
    else:  # between poses: the gyro's integral from the last sample's heading
        th = cur.th_last + 0.5 * (cur.w_last + omega) * p.Td
    if not (ok and math.isfinite(th) and math.isfinite(v) and math.isfinite(alpha_hat)
            and math.isfinite(a_y) and math.isfinite(omega) and math.isfinite(delta)
            and math.isfinite(force)):
        return Interval(cur.open, False, cur.sx, cur.sy, cur.sth, cur.n, cur.sv, cur.sv_dth, cur.sv_alpha,
                        cur.sv_ay, cur.sv_full, cur.s_delta, cur.s_w_v, cur.s_vw, cur.s_F, cur.w_first,
                        cur.ay_ref, cur.v_first, cur.th_last, cur.w_last)
    dth = _wrap(th - cur.sth)
    first = cur.n == 0
    w = 0.5 if first else 1.0  # trapezoid: the opening sample counts half
    return Interval(cur.open, cur.ok, cur.sx, cur.sy, cur.sth, cur.n + 1, cur.sv + w * v,
                    cur.sv_dth + w * v * dth, cur.sv_alpha + v * alpha_hat, cur.sv_ay + v * a_y,
                    cur.sv_full + v, cur.s_delta + delta, cur.s_w_v + omega / max(v, 1.0),
                    cur.s_vw + v * omega, cur.s_F + force, omega if first else cur.w_first, cur.ay_ref,
                    v if first else cur.v_first, th, omega)


@jitable
def course_ends(p: CourseParams, since: int, mpc_step: bool, has_pose: bool, X: float, Y: float,
                theta: float) -> bool:
    """Does an interval end at this call (:func:`course_close`), ``since`` calls after the last end
    (this one counted)? At an accepted, finite pose, at an MPC step or a T_c after the last end."""
    good_pose = has_pose and math.isfinite(X) and math.isfinite(Y) and math.isfinite(theta)
    return good_pose and (mpc_step or since >= p.n_inner)


@jitable
def course_close(p: CourseParams, s: CourseState, cur: Interval, mpc_step: bool, has_pose: bool, X: float,
                 Y: float, theta: float, v: float, omega: float,
                 ay_ref: float) -> tuple[CourseState, Interval]:
    """One call, before its sample (:func:`course_sample`): does an interval end at the measured
    pose (X, Y, θ) now (``has_pose`` False: none came or it was rejected — nothing ends)?

    An accepted pose ends the open interval at an MPC step (``mpc_step``; at the nominal sensors
    every interval is one MPC period) and, between MPC steps, once the interval has lasted a T_c
    (``n_inner`` calls: a pose at any rate ends intervals at its own pace, at most one per T_c).
    The interval is closed on the pose and the speed ``v`` (the closing sample, counted half;
    NaN: missing — the interval is spoilt and none opens until the next end), a measured one goes
    into the speed sensor's fit (:func:`interval_speed`), a chord is fitted
    (:func:`course_chord`) over the shortest run of the latest closed intervals that lasts
    ``BASELINE`` T_c, when they are all measured and it lasts at most ``CHORD_MAX_S``, and the
    next interval opens. ``omega``: measured yaw rate now, ``ay_ref``: the reference's lateral
    acceleration v_d ω_d now. Returns (the state, the open interval)."""
    since = s.since + 1
    if not course_ends(p, since, mpc_step, has_pose, X, Y, theta):
        return CourseState(s.ring, s.n_iv, s.omega_now, s.v_now, s.n_chords, s.slip, s.speed, s.stiff,
                           since, s.age, s.lat), cur
    ay = abs(ay_ref) if math.isfinite(ay_ref) else 0.0
    good = math.isfinite(v)
    ring, n_iv = s.ring, s.n_iv
    k0 = -1  # the chord's first interval in the ring (-1: no chord)
    speed = s.speed
    if cur.open:
        sv, sv_dth, ok = cur.sv, cur.sv_dth, cur.ok
        if good and cur.n > 0 and ok:  # the closing sample, counted half
            dth = _wrap(theta - cur.sth)
            sv += 0.5 * v
            sv_dth += 0.5 * v * dth
        else:
            ok = False
        closed = Interval(cur.open, ok, cur.sx, cur.sy, cur.sth, cur.n, sv, sv_dth, cur.sv_alpha,
                          cur.sv_ay, cur.sv_full, cur.s_delta, cur.s_w_v, cur.s_vw, cur.s_F, cur.w_first,
                          min(cur.ay_ref, ay), cur.v_first, cur.th_last, cur.w_last)
        ring = ring[1:] + (closed,)  # noqa: RUF005 (numba has no starred tuples) the oldest drops out
        n_iv = min(n_iv + 1, RING)
        if ok:
            speed = interval_speed(p, speed, closed, X, Y, theta)
        if good:
            k0 = _chord_start(p, ring, n_iv)
    s = CourseState(ring, n_iv, omega, v, s.n_chords, s.slip, speed, s.stiff, 0, s.age, s.lat)
    if k0 >= 0:
        s = course_chord(p, s, k0, X, Y, theta)
    if not good:
        return s, NO_INTERVAL
    return s, Interval(True, True, X, Y, theta, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ay,
                       math.nan, theta, 0.0)


@jitable
def _chord_start(p: CourseParams, ring: tuple[Interval, ...], n_iv: int) -> int:
    """The ring index of the chord's first interval: the shortest run of the latest ``n_iv``
    closed intervals of ``ring`` that lasts at least ``chord_min`` calls, if they are all measured
    and last at most ``chord_max``; −1 when there is none."""
    steps = 0
    i = RING - 1
    while i >= RING - n_iv:
        iv = ring[i]
        if not iv.ok:
            return -1
        steps += iv.n
        if steps >= p.chord_min:
            return i if steps <= p.chord_max else -1
        i -= 1
    return -1


@jitable
def course_chord(p: CourseParams, s: CourseState, k0: int, ex: float, ey: float, eth: float) -> CourseState:
    """The slip and stiffness fits on the chord of the closed intervals ``k0`` … of
    ``s.ring`` ending at the measured pose (ex, ey, eth) (see the module docstring); a chord
    shorter than ``MIN_CHORD_M`` or without speed changes nothing. The chord lasts its calls
    D = (n / ``n_inner``) T_c (``BASELINE`` T_c at the nominal sensors); each chord adds the time of
    its last interval, dt, to the fits' memories (their forgetting is per second, whatever the
    pose rate). For the first ``FIT_SETTLE_S`` seconds of chords (the start's transient) the slip
    fit takes the chord as an offset β alone (κ and the stiffness fits hold their priors)."""
    ring = s.ring
    first = ring[k0]
    last = ring[RING - 1]
    dx, dy = ex - first.sx, ey - first.sy
    chord = exact_hypot(dx, dy)
    if chord < MIN_CHORD_M:
        return s
    # speed-weighted means over the chord (θ relative to the chord's first pose)
    sv = 0.0
    for i in range(k0, RING):
        sv += ring[i].sv
    if sv <= 0.0:
        return s
    sv_th = 0.0
    n = 0
    sv_full = 0.0
    s_alpha = 0.0
    s_ay = 0.0
    s_vw = 0.0
    s_F = 0.0
    s_wv = 0.0
    s_d = 0.0
    ay_min = first.ay_ref
    for i in range(k0, RING):
        iv = ring[i]
        sv_th += iv.sv_dth + _wrap(iv.sth - first.sth) * iv.sv
        n += iv.n
        sv_full += iv.sv_full
        s_alpha += iv.sv_alpha
        s_ay += iv.sv_ay
        s_vw += iv.s_vw
        s_F += iv.s_F
        s_wv += iv.s_w_v
        s_d += iv.s_delta
        ay_min = min(ay_min, iv.ay_ref)
    th_mean = first.sth + sv_th / sv
    a_course = _wrap(math.atan2(dy, dx) - th_mean)
    alpha_hat = s_alpha / sv_full
    a_y = s_ay / sv_full
    D = (n / p.n_inner) * p.Tc  # the chord's time span
    dt = (last.n / p.n_inner) * p.Tc  # the time it adds (T_c at the nominal sensors)
    # how fast the model's α̂ changes along the chord (its first interval's mean to its last's): a
    # transient's share of the slip error, SLIP_TRANSIENT_S |α̇|
    sep = (n - 0.5 * (first.n + last.n)) / p.n_inner * p.Tc
    al_rate = ((last.sv_alpha / last.sv_full - first.sv_alpha / first.sv_full) / sep
               if sep > 0.0 and first.sv_full > 0.0 and last.sv_full > 0.0 else 0.0)
    settled = s.age >= FIT_SETTLE_S
    slip, noise_sig = _slip_fit(s.slip, dt, a_course - alpha_hat, a_y if settled else 0.0, chord, p.sigma,
                                ay_min >= CORNER_ACCEL, SLIP_TRANSIENT_S * abs(al_rate))
    stiff = s.stiff
    lat = s.lat
    # axle stiffnesses from the course's slip (quasi-steady single track), only where the reference
    # turns (a straight carries no information on C, only the traces of a lightly damped yaw motion),
    # at nearly constant speed (pure slip: STIFF_MAX_ACCEL) and over at most STIFF_MAX_SPAN_S (a
    # longer chord's means mix a corner's transient in); a NaN speed fails the test
    a_x = (s.v_now - first.v_first) / D
    steady = p.has_vehicle and abs(a_x) <= STIFF_MAX_ACCEL * p.g and n <= p.stiff_max
    if settled and p.has_vehicle and math.isfinite(s.omega_now) and ay_min >= CORNER_ACCEL and steady:
        # α̇ from the model's α̂ over consecutive chords (smooth; the course's own α would put its
        # noise through a 1/dt difference into the force)
        al_dot = (alpha_hat - stiff.alpha_prev) / dt if stiff.has_prev else 0.0
        # the speed terms at the ground speed: the measured speed corrected by the speed fit (a
        # speed sensor's offset ô is a force error M ô ω and a slip error b ω ô / v² on every
        # chord: −0.5 m/s at 8–12 m/s set Ĉ_r 12 % low)
        v_meas = sv / n  # the trapezoid mean of the measured speed over the chord's time
        v_g = ground_speed(s.speed, v_meas)
        r = v_g / v_meas if v_meas > 0.0 and v_g > 0.0 else 1.0
        stiff = _stiffness_fit(p, stiff, a_course, alpha_hat, al_dot, r * (s_vw / n), r * v_meas, s_F / n,
                               s.omega_now - first.w_first, (s_wv / n) / r, s_d / n, noise_sig, D, last.n,
                               0.0 if stiff.has_prev else abs(al_rate))  # (no α̇ of its own)
        if p.lateral:
            lat = _lateral_fit(p, lat, a_course, r * (s_vw / n), r * v_meas, s_F / n,
                               s.omega_now - first.w_first, (s_wv / n) / r, s_d / n, noise_sig, D, last.n,
                               al_rate)
    return CourseState(ring, s.n_iv, s.omega_now, s.v_now, s.n_chords + 1, slip, s.speed, stiff, s.since,
                       s.age + dt, lat)


@jitable
def _slip_fit(f: SlipFit, dt: float, z: float, a_y: float, chord: float, sigma: float,
              cornering: bool, e_transient: float = 0.0) -> tuple[SlipFit, float]:
    """One chord in the slip fit z = ᾱ_course − ᾱ̂ = κ ā_y + β (recursive least squares with
    forgetting, φ = [ā_y, 1]), weighted by the chord's noise (positions at both ends, scaled by the
    noise level measured on straights, which a chord where the reference runs straight updates:
    there the slip and the model's error in it are ≈ 0, so the innovation is noise) and by
    ``e_transient`` [rad], the slip error of a chord through a transient (``SLIP_TRANSIENT_S``
    |α̇|: κ and β are the model's steady error, not a lag); the chord adds ``dt`` seconds to the
    memories. Returns (the fit, the chord's slip noise σ from the positions)."""
    sig0 = 2.0 * math.sqrt(2.0) * sigma / chord + 2e-4
    innov = z - (a_y * f.kappa + f.beta)
    n2, n1 = f.n2, f.n1
    if not cornering:
        g_n = 1.0 - dt / NOISE_MEMORY_S
        r = innov / sig0
        n2 = g_n * n2 + r * r
        n1 = g_n * n1 + 1.0
    sig = sig0 * noise_scale(SlipFit(f.kappa, f.beta, f.P00, f.P01, f.P10, f.P11, n2, n1))
    lam = 1.0 - dt / SLIP_MEMORY_S
    P00, P01, P10, P11 = f.P00 / lam, f.P01 / lam, f.P10 / lam, f.P11 / lam
    Pp0 = P00 * a_y + P01  # P φ
    Pp1 = P10 * a_y + P11
    pP0 = a_y * P00 + P10  # φ P
    pP1 = a_y * P01 + P11
    den = sig * sig + e_transient * e_transient + (pP0 * a_y + pP1)
    k0, k1 = Pp0 / den, Pp1 / den
    return SlipFit(f.kappa + k0 * innov, f.beta + k1 * innov, P00 - k0 * pP0, P01 - k0 * pP1,
                   P10 - k1 * pP0, P11 - k1 * pP1, n2, n1), sig


@jitable
def _axle_pair(C0: float, force: float, slip: float, sig: float) -> tuple[float, float]:
    """(F, α) of one axle when the chord's slip is one a plausible stiffness gives its force, up to
    ``STIFF_BAND_SIGMAS`` of its noise ``sig`` (F / α within ``STIFF_RANGE`` × the model's ``C0``),
    else (0, 0): anything else is no quasi-steady pure-slip chord (a transient, a lag between forces
    and slips, a saturated tyre) and would drag the fit to its bounds (on Spa at 22 m/s one corner
    took it to 2× and doubled the largest e_y). The noise widens the band: cut at the band's
    edges, a noisy slip (the response) would be censored and the fit biased into the band."""
    s = slip if force >= 0.0 else -slip
    fa, e = abs(force), STIFF_BAND_SIGMAS * sig
    if fa / (STIFF_RANGE[1] * C0) - e <= s <= fa / (STIFF_RANGE[0] * C0) + e:
        return force, slip
    return 0.0, 0.0


@jitable
def _stiffness_fit(p: CourseParams, f: StiffFit, a_course: float, alpha_hat: float, al_dot: float,
                   vw: float, v_meas: float, F_x: float, d_omega: float, w_v: float, delta: float,
                   sig: float, span: float, n_last: int, e_rate: float = 0.0) -> StiffFit:
    """One cornering chord in the compliance fits. Lateral force S = M (v ω + v α̇) + F_x α and
    yaw moment T = I ω̇ give F_yF = (b S + T)/L, F_yR = (a S − T)/L; slips α_F = δ − α − a ω/v,
    α_R = b ω/v − α (chord means: ``vw`` of v ω, ``w_v`` of ω / v, ``delta``, ``F_x``; ``d_omega``
    the change of ω over the chord). The fit is of the compliance 1/C with the force as regressor
    (slip = F / C): the forces come from v, ω (precise), the slips carry the course's noise — as
    the response, noise does not bias the fit (as a regressor it would pull C towards 0 on every
    straight). The chord lasts ``span`` seconds and adds its last interval's ``n_last`` calls. Each
    chord weighs by its slip noise ``sig`` (or the fit's own floor), shared with the chords within
    the residual's correlation time (``STIFF_CORRELATION`` T_c: one chord per T_c shares it with
    ``STIFF_CORRELATION`` − 1 others, one per second with none), plus, per axle, the error of its
    α̇ term: α̇ is the change of the mean α̂ since the previous chord, which lags the chord by half
    the step between them; the part of the step beyond T_c (none at the nominal sensors, 80 % of
    it at a 2 Hz pose) makes that share of M v α̇ force noise, slip noise F / C on each axle
    (a pose at 1–3 Hz drove the fit 3–4 % below the nominal car's stiffnesses without it, and max
    |e_y| from 0.021 to 0.033 m on the paper reference). The first cornering chord has no previous
    one: its α̇ is taken as 0 and ``e_rate`` [rad/s], how fast α̂ changes within the chord, is its
    error (M v ``e_rate`` of force noise): a corner's entry at speed, where the car's slip is still
    building up (half its steady value on Brands Hatch at 30 m/s, α̇ ≈ 0.02 rad/s: a third of the
    force), otherwise outweighed every later chord and set Ĉ +44 %. Forgetting is per second,
    towards the prior (a fit without excitation returns to the model)."""
    S = p.mass * (vw + v_meas * al_dot) + F_x * a_course
    T = p.inertia * d_omega / span
    L = p.a + p.b
    s_slip = max(sig, STIFF_SLIP_FLOOR)
    F_f, a_f = _axle_pair(p.C_f, (p.b * S + T) / L, delta - a_course - p.a * w_v, s_slip)
    F_r, a_r = _axle_pair(p.C_r, (p.a * S - T) / L, p.b * w_v - a_course, s_slip)
    corr = max(1.0, STIFF_CORRELATION * p.n_inner / n_last)  # chords per independent one
    # the α̇ term's error: the part of the step beyond T_c of M v α̇ (or, without a previous chord,
    # α̂'s change within the chord), per axle as slip (F / C)
    lag = max(n_last - p.n_inner, 0) / n_last
    e_S = p.mass * v_meas * (abs(al_dot) * lag + e_rate)
    e_f = (p.b / L) * e_S / p.C_f
    e_r = (p.a / L) * e_S / p.C_r
    w_f = 1.0 / (corr * s_slip * s_slip + corr * e_f * e_f)
    w_r = 1.0 / (corr * s_slip * s_slip + corr * e_r * e_r)
    g2 = 1.0 - ((n_last / p.n_inner) * p.Tc) / STIFF_MEMORY_S
    return StiffFit(g2 * f.num_f + (1.0 - g2) * p.prior_num_f + w_f * (F_f * a_f),
                    g2 * f.num_r + (1.0 - g2) * p.prior_num_r + w_r * (F_r * a_r),
                    g2 * f.den_f + (1.0 - g2) * p.prior_den_f + w_f * (F_f * F_f),
                    g2 * f.den_r + (1.0 - g2) * p.prior_den_r + w_r * (F_r * F_r),
                    alpha_hat, True)


@jitable
def _lateral_fit(p: CourseParams, f: LateralFit, a_course: float, vw: float, v_meas: float, F_x: float,
                 d_omega: float, w_v: float, delta: float, sig: float, span: float, n_last: int,
                 al_rate: float = 0.0) -> LateralFit:
    """One cornering chord in the joint lateral fit (the chords and the single-track balance of
    :func:`_stiffness_fit`, with a, b = L − a, I_z and the compliances all unknown): the front and
    rear slip equations

        δ + δ_r − α − a ω/v = F_yF / C_f,   b ω/v − α = F_yR / C_r,
        F_yF = (b S + I_z ω̇) / L,   F_yR = (a S − I_z ω̇) / L,   S = M (v ω + v α̇) + F_x α,

    as two scalar measurements of an extended Kalman filter over x = (a / L, I_z / I_z,0,
    C_f,0 / C_f, C_r,0 / C_r, δ_r) (each relinearised at the estimate of the one before), each with
    the chord's slip noise ``sig`` (at least ``STIFF_SLIP_FLOOR``). M is the model's: a mass error
    scales the fitted C and I_z with it (F = M s), which leaves the lateral dynamics the MHE runs with
    the model's M those of the car. α̇ is ``al_rate``, how fast the MHE's α̂ changes along the
    chord (its first interval's mean to its last's), and the same M v |α̇| is the chord's force noise:
    α̂ follows the model this fit hands over, so the term may be as wrong as it is large. (The
    alternatives measured on replayed chords of the paper reference and in closed loop: α̇ = 0
    biased a / L 2–4 % low and C_r 3–8 % high, corner entries and exits at other speeds; the change
    of the course slip between chords put the positions' noise into S and, at 10 × the GNSS
    noise, doubled RMSE y.) Each axle's slip noise adds the tyre's nonlinearity
    (``LATERAL_NONLINEAR``); an axle whose chord is outside the compliance fit's band
    (:func:`_axle_pair`) is not counted. The yaw inertia and the CoG are observable only through ω̇
    and the split of S between the axles: a steady corner informs the compliances and a — at several speeds:
    in one, a and C_r trade off along a ridge — a corner's entry and exit I_z; where nothing informs
    a parameter it holds its prior (no process noise, no forgetting)."""
    L = p.a + p.b
    S = p.mass * (vw + v_meas * al_rate) + F_x * a_course
    wd = d_omega / span
    x = np.empty(5)
    P = np.empty((5, 5))
    k = 0
    for i in range(5):
        x[i] = f.x[i]
        for j in range(i, 5):
            P[i, j] = f.P[k]
            P[j, i] = f.P[k]
            k += 1
    s_slip = max(sig, STIFF_SLIP_FLOOR)
    corr = max(1.0, STIFF_CORRELATION * p.n_inner / n_last)  # chords per independent one
    e_S = p.mass * v_meas * abs(al_rate)  # the α̇ term's error, as large as the term
    H = np.empty(5)
    PH = np.empty(5)
    for axle in range(2):
        u, iz, qf, qr, d_r = x[0], x[1], x[2], x[3], x[4]
        yaw = iz * p.inertia * wd / L  # I_z ω̇ / L
        if axle == 0:  # the axle's force, its share of S, compliance, model stiffness and slip
            F, share, comp, C0 = (1.0 - u) * S + yaw, 1.0 - u, qf / p.C_f, p.C_f
            slip = delta + d_r - a_course - u * L * w_v
            H[0], H[1], H[2] = -L * w_v + comp * S, -comp * yaw / iz, -F / p.C_f
            H[3], H[4] = 0.0, 1.0
        else:
            F, share, comp, C0 = u * S - yaw, u, qr / p.C_r, p.C_r
            slip = (1.0 - u) * L * w_v - a_course
            H[0], H[1], H[2] = -L * w_v - comp * S, comp * yaw / iz, 0.0
            H[3], H[4] = -F / p.C_r, 0.0
        # the compliance fit's band (_axle_pair): a chord whose own F / slip no plausible stiffness
        # gives is no pure-slip chord of this axle (a saturated tyre on a road that lost its grip:
        # Monza's μ step, max |e_y| +8 % without it)
        if _axle_pair(C0, F, slip, s_slip)[0] == 0.0:
            continue
        r = slip - comp * F
        e_r = share * e_S * comp
        fz = p.mass * p.g * share  # the axle's static load
        e_nl = LATERAL_NONLINEAR * (F / fz) ** 2 * abs(F) * comp
        den = corr * (s_slip * s_slip + e_r * e_r + e_nl * e_nl)
        for i in range(5):
            acc = 0.0
            for j in range(5):
                acc += P[i, j] * H[j]
            PH[i] = acc
            den += H[i] * acc
        for i in range(5):
            x[i] -= PH[i] / den * r  # the measurement is 0 = r(x) + noise
        for i in range(5):
            for j in range(5):
                P[i, j] -= PH[i] * PH[j] / den
    x[0] = min(max(x[0], LATERAL_A_RANGE[0]), LATERAL_A_RANGE[1])
    x[1] = min(max(x[1], LATERAL_I_RANGE[0]), LATERAL_I_RANGE[1])
    x[2] = min(max(x[2], 1.0 / STIFF_RANGE[1]), 1.0 / STIFF_RANGE[0])
    x[3] = min(max(x[3], 1.0 / STIFF_RANGE[1]), 1.0 / STIFF_RANGE[0])
    return LateralFit((x[0], x[1], x[2], x[3], x[4]),
                      (P[0, 0], P[0, 1], P[0, 2], P[0, 3], P[0, 4], P[1, 1], P[1, 2], P[1, 3], P[1, 4],
                       P[2, 2], P[2, 3], P[2, 4], P[3, 3], P[3, 4], P[4, 4]), True, f.given)


@jitable
def lateral_model(p: CourseParams, f: LateralFit) -> tuple[float, float, float, float, float]:
    """The joint fit's (C_f, C_r [N/rad], I_z [kg m²], a, b [m])."""
    L = p.a + p.b
    a = f.x[0] * L
    return p.C_f / f.x[2], p.C_r / f.x[3], f.x[1] * p.inertia, a, L - a


@jitable
def slip_correction(f: SlipFit, a_y: float) -> float:
    """κ̂ a_y + β̂ [rad] (a non-finite a_y counts as 0), bounded by ``SLIP_CORRECTION_MAX``."""
    if not math.isfinite(a_y):
        a_y = 0.0
    return min(max(f.kappa * a_y + f.beta, -SLIP_CORRECTION_MAX), SLIP_CORRECTION_MAX)


@jitable
def noise_scale(f: SlipFit) -> float:
    """The chords' slip noise as measured on straights, over the configured σ's (≥ 1: the
    configured σ is a floor)."""
    return math.sqrt(max(1.0, f.n2 / f.n1))


@jitable
def interval_speed(p: CourseParams, f: SpeedFit, iv: Interval, ex: float, ey: float, eth: float) -> SpeedFit:
    """The closed measured interval ``iv`` ending at the pose (ex, ey, eth) in the speed sensor's fit
    (:func:`speed_update`): its ground speed, the arc of its chord (turn Δχ ≈ Δθ) over its time,
    against its trapezoid mean of the measured speed. Every interval counts once, however short (the
    chord's error is the positions', not the distance's): the fit has the sensor's offset from the
    first interval on, at rest too (the car has not moved: the sensor reads its offset)."""
    D = (iv.n / p.n_inner) * p.Tc
    chord = exact_hypot(ex - iv.sx, ey - iv.sy)
    turn = abs(_wrap(eth - iv.sth))
    arc = chord * ((0.5 * turn) / math.sin(0.5 * turn) if turn > 1e-6 else 1.0)
    return speed_update(f, D, D, p.sigma, iv.sv / iv.n if iv.n > 0 else math.nan, arc / D)


@jitable
def speed_update(f: SpeedFit, dt: float, D: float, sigma: float, v_meas: float, v_ground: float) -> SpeedFit:
    """One chord of ``D`` seconds, ``dt`` of them new, in the speed sensor's fit. The sensor's
    v_measured = (1 + e) v + o is, exactly, v̄_measured − v_ground = c + k v̄_measured with
    c = o / (1 + e), k = e / (1 + e): the regressor is the measured speed (φ = [1, v̄_measured]),
    precise, not the ground speed, whose noise in a regressor would bias k by −σ² / (σ² + the
    speed's spread) at a nearly constant speed (on a race track with 1 cm positions that was
    −0.2, the bound). Weighted by the new share of the chord over its ground speed's variance (the
    positions' σ at both ends over D, and ``SPEED_MODEL_SIGMA``), that variance scaled by the noise
    level the fit measures (covariance matching: the mean of (innovation² − its share from the
    estimate's own variance) over the assumed variance, at least 1, forgotten over
    ``NOISE_MEMORY_S``). Without it, positions noisier than configured (a GNSS at 10 × σ) made the
    data outweigh the prior 100-fold and the split of o and e wander with the noise at one speed.
    The information forgets towards the prior (1 − dt / ``SPEED_MEMORY_S`` per chord): what the
    chords do not inform, the scale at a constant speed, returns to its prior instead of drifting."""
    if not (math.isfinite(v_meas) and math.isfinite(v_ground)) or D <= 0.0:
        return f
    g = max(1.0 - dt / SPEED_MEMORY_S, 0.0)
    q0 = 1.0 / (SPEED_PRIOR[0] * SPEED_PRIOR[0])
    q1 = 1.0 / (SPEED_PRIOR[1] * SPEED_PRIOR[1])
    var0 = (2.0 * (sigma / D) ** 2 + SPEED_MODEL_SIGMA * SPEED_MODEL_SIGMA) / min(dt / D, 1.0)
    y = v_meas - v_ground
    # the innovation against the estimate's own variance φᵀ Λ⁻¹ φ (Λ > 0: the prior is in it)
    c, k, det = _speed_solve(f)
    p_var = (f.l11 - 2.0 * f.l01 * v_meas + f.l00 * v_meas * v_meas) / det
    innov = y - c - k * v_meas
    g_n = max(1.0 - dt / NOISE_MEMORY_S, 0.0)
    n2 = g_n * f.n2 + max(innov * innov - p_var, 0.0) / var0
    n1 = g_n * f.n1 + 1.0
    w = 1.0 / (var0 * max(1.0, n2 / n1))
    return SpeedFit(g * f.l00 + (1.0 - g) * q0 + w, g * f.l01 + w * v_meas,
                    g * f.l11 + (1.0 - g) * q1 + w * v_meas * v_meas, g * f.h0 + w * y,
                    g * f.h1 + w * y * v_meas, n2, n1)


@jitable
def _speed_solve(f: SpeedFit) -> tuple[float, float, float]:
    """Λ θ̂ = η of the fit: (ĉ, k̂, det Λ), unbounded; (0, 0, det) without information (det ≤ 0)."""
    det = f.l00 * f.l11 - f.l01 * f.l01
    if not det > 0.0:
        return 0.0, 0.0, det
    return (f.l11 * f.h0 - f.l01 * f.h1) / det, (f.l00 * f.h1 - f.l01 * f.h0) / det, det


@jitable
def _speed_ck(f: SpeedFit) -> tuple[float, float]:
    """The fit's (ĉ [m/s], k̂) of v_measured − v = c + k v_measured, bounded by ``SPEED_OFFSET_MAX``
    and ``SPEED_SCALE_MAX``."""
    c, k, _det = _speed_solve(f)
    return min(max(c, -SPEED_OFFSET_MAX), SPEED_OFFSET_MAX), min(max(k, -SPEED_SCALE_MAX), SPEED_SCALE_MAX)


@jitable
def speed_sensor(f: SpeedFit) -> tuple[float, float]:
    """The speed sensor's estimated (offset ô [m/s], scale error ê) of v_measured = (1 + e) v + o:
    ô = ĉ / (1 − k̂), ê = k̂ / (1 − k̂)."""
    c, k = _speed_ck(f)
    return c / (1.0 - k), k / (1.0 - k)


@jitable
def speed_offset(f: SpeedFit, v: float) -> float:
    """What the speed sensor's errors add to the measured speed ``v`` [m/s] (measured − true):
    ĉ + k̂ v."""
    c, k = _speed_ck(f)
    return c + k * v


@jitable
def ground_speed(f: SpeedFit, v: float) -> float:
    """The speed over ground of the measured speed ``v`` [m/s]: v − :func:`speed_offset`."""
    return v - speed_offset(f, v)


@jitable
def _inverse(num: float, den: float) -> float:
    """1 / (num / den), the compliance at least 1e-12; ∞ for a compliance ≤ 0."""
    comp = num / den
    if not comp > 0.0:
        return math.inf
    return 1.0 / max(comp, 1e-12)


@jitable
def stiffness(p: CourseParams, f: StiffFit) -> tuple[float, float]:
    """(Ĉ_f, Ĉ_r) [N/rad]: the inverse of the fitted compliances (the model's until data outweigh
    the prior), within ``STIFF_RANGE`` × the model's."""
    lo, hi = STIFF_RANGE
    return (min(max(_inverse(f.num_f, f.den_f), lo * p.C_f), hi * p.C_f),
            min(max(_inverse(f.num_r, f.den_r), lo * p.C_r), hi * p.C_r))


@jitable
def model_changed(f: SlipFit) -> SlipFit:
    """The MHE's model got new stiffnesses: the slip fit's κ restarts from its prior (it was the
    a_y-proportional error of the previous model, which the new one no longer makes; kept, it
    corrects a bias that has gone, for its memory). β, a heading-sensor offset that no model change
    explains, is kept (its row and column of P too)."""
    return SlipFit(0.0, f.beta, SLIP_PRIOR[0] * SLIP_PRIOR[0], 0.0, 0.0, f.P11, f.n2, f.n1)


@jitable
def stiffness_update(p: CourseParams, s: CourseState, has_applied: bool, C_f: float, C_r: float,
                     inertia: float, a: float) -> tuple[bool, float, float, float, float, float, CourseState]:
    """The lateral model to give the MHE and the inner loop, against the one they have
    (``has_applied`` False: none yet, the model's): where the reference runs straight (the last
    interval's |v_d ω_d| below ``CORNER_ACCEL``), the joint fit's (C_f, C_r, I_z, a, b) once it has
    fitted a chord; until the joint fit has given one, the compliance fit's (Ĉ_f, Ĉ_r) with the
    model's I_z and CoG, in corners too. Either is given when any of its values moved by over 1 %
    against those given, or none was given yet. Returns (give it, Ĉ_f, Ĉ_r, Î_z, â, b̂, the state —
    when it replaces a given model, the slip fit's κ restarts, :func:`model_changed`).

    Why only on straights: a model replaced under a corner restarts κ and moves the MHE's α̂ and the
    steering feed-forward while the car is at its largest slip (stop 59, a Python-loop trial on the
    paper reference: handed over wherever it moved, draw h49's max |e_y| 0.029 → 0.082 m at its
    hardest corner, the nominal car's 0.020 → 0.022 m; on straights 0.027 and 0.017 m). The
    compliance fit, one parameter per axle, settles within the first corners and keeps giving
    there until the joint fit takes over."""
    lat = s.lat
    straight = s.n_iv > 0 and s.ring[RING - 1].ay_ref < CORNER_ACCEL
    joint = p.lateral and straight and lat.fitted
    if joint:
        ref = (C_f, C_r, inertia, a) if has_applied else (p.C_f, p.C_r, p.inertia, p.a)
        L = p.a + p.b
        dev = max(max(abs(lat.x[0] - ref[3] / L) / math.sqrt(lat.P[0]),
                      abs(lat.x[1] - ref[2] / p.inertia) / math.sqrt(lat.P[5])),
                  max(abs(lat.x[2] - p.C_f / ref[0]) / math.sqrt(lat.P[9]),
                      abs(lat.x[3] - p.C_r / ref[1]) / math.sqrt(lat.P[12])))
        joint = dev > LATERAL_SIGNIFICANCE
    if joint:
        cf, cr, ii, aa, bb = lateral_model(p, lat)
    elif lat.given:  # the joint fit's model stays until the next straight
        return False, C_f, C_r, inertia, a, p.a + p.b - a, s
    else:
        cf, cr = stiffness(p, s.stiff)
        ii, aa, bb = p.inertia, p.a, p.b
    if (has_applied and abs(cf - C_f) <= 0.01 * abs(C_f) and abs(cr - C_r) <= 0.01 * abs(C_r)
            and abs(ii - inertia) <= 0.01 * abs(inertia) and abs(aa - a) <= 0.01 * abs(a)):
        return False, cf, cr, ii, aa, bb, s
    if joint and not lat.given:
        lat = LateralFit(lat.x, lat.P, lat.fitted, True)
    # κ restarts whenever a model replaces one it has learnt against (the first, at the first MPC
    # step, gives the model itself: κ is at its prior)
    slip = model_changed(s.slip) if has_applied else s.slip
    s = CourseState(s.ring, s.n_iv, s.omega_now, s.v_now, s.n_chords, slip, s.speed, s.stiff, s.since, s.age,
                    lat)
    return True, cf, cr, ii, aa, bb, s


class CourseFusion:
    """Course and speed over ground from the measured positions, fitted against the model
    (see the module docstring; the online wrapper of :func:`course_sample`, :func:`course_close`
    and the fits' outputs). Every T_d call: :meth:`close` (before the MPC runs, at an MPC step),
    then :meth:`sample`. ``Td`` and ``n_inner`` are the calls' period and the calls per MPC period
    (the defaults: 10 calls of T_c / 10)."""

    def __init__(self, Tc: float, position_sigma: float, vehicle: VehicleParams | None = None, *,
                 Td: float | None = None, n_inner: int = 10, lateral: bool = True) -> None:
        self.Tc = float(Tc)
        self.Td = self.Tc / n_inner if Td is None else float(Td)
        self.vehicle = vehicle
        p = vehicle
        n_in = int(n_inner)
        self.params = (course_params(self.Tc, float(position_sigma), False, 1.0, 1.0, math.nan, math.nan,
                                     math.nan, math.nan, math.nan, self.Td, n_in) if p is None else
                       course_params(self.Tc, float(position_sigma), True, float(p.C_f), float(p.C_r),
                                     float(p.mass), float(p.inertia), float(p.a), float(p.b), float(p.g),
                                     self.Td, n_in, bool(lateral)))
        self.sigma = self.params.sigma
        self.reset()

    def reset(self) -> None:
        """Forget everything: corrections back to zero."""
        self.state = course_start(self.params)
        self.cur = NO_INTERVAL

    @property
    def n_chords(self) -> int:
        """Chords fitted since the reset."""
        return self.state.n_chords

    @property
    def slip_params(self) -> tuple[float, float]:
        """(κ̂ [rad per m/s²], β̂ [rad])."""
        return self.state.slip.kappa, self.state.slip.beta

    def slip_correction(self, a_y: float) -> float:
        """κ̂ a_y + β̂ [rad], bounded by ``SLIP_CORRECTION_MAX``."""
        return slip_correction(self.state.slip, float(a_y))

    @property
    def noise_scale(self) -> float:
        """The chords' slip noise as measured on straights, over the configured σ's (≥ 1)."""
        return noise_scale(self.state.slip)

    @property
    def speed_sensor(self) -> tuple[float, float]:
        """The speed sensor's estimated (offset [m/s], scale error) of v_measured = (1 + e) v + o."""
        return speed_sensor(self.state.speed)

    def speed_offset(self, v: float) -> float:
        """What the speed sensor's errors add to the measured speed ``v`` [m/s] (measured − true)."""
        return speed_offset(self.state.speed, float(v))

    @property
    def stiffness(self) -> tuple[float, float] | None:
        """(Ĉ_f, Ĉ_r) [N/rad] within ``STIFF_RANGE`` × the model's; None without a vehicle."""
        return stiffness(self.params, self.state.stiff) if self.vehicle is not None else None

    @property
    def lateral(self) -> tuple[float, float, float, float, float] | None:
        """The joint lateral fit's (C_f, C_r [N/rad], I_z [kg m²], a, b [m]); None without a vehicle."""
        return lateral_model(self.params, self.state.lat) if self.vehicle is not None else None

    def model_changed(self) -> None:
        """The MHE's model got new stiffnesses: κ restarts from its prior (:func:`model_changed`)."""
        self.state = self.state._replace(slip=model_changed(self.state.slip))

    def stiffness_update(self, applied: list[float]) -> tuple[float, float, float, float, float] | None:
        """The lateral model to give the MHE and the inner loop, given the one they have
        (``applied`` = [C_f, C_r, I_z, a], empty: the model's): (C_f, C_r, I_z, a, b), or None (no
        vehicle, or no change of over 1 %); when it replaces a given one, κ restarts
        (:func:`stiffness_update`)."""
        if self.vehicle is None:
            return None
        has = bool(applied)
        app = [float(q) for q in applied] if has else [0.0, 0.0, 0.0, 0.0]
        give, cf, cr, ii, aa, bb, self.state = stiffness_update(self.params, self.state, has, *app)
        return (cf, cr, ii, aa, bb) if give else None

    def sample(self, ok: bool, theta: float, v: float, alpha_hat: float, a_y: float,
               omega: float = 0.0, delta: float = 0.0, force: float = 0.0, has_pose: bool = True) -> None:
        """One T_d sample (:func:`course_sample`): ``ok`` the speed and yaw rate were accepted,
        ``has_pose`` a pose was (θ its heading; else the gyro's integral is used)."""
        self.cur = course_sample(self.params, self.cur, ok, has_pose, theta, v, alpha_hat, a_y, omega, delta,
                                 force)

    def close(self, pose: NDArray[np.float64] | None, v: float, omega: float = 0.0,
              ay_ref: float = 0.0, mpc_step: bool = True) -> None:
        """One call before its sample (:func:`course_close`): ``pose`` the accepted pose now (None
        if missing or rejected: nothing ends here), ``v`` and ``omega`` the measured speed and yaw
        rate now, ``ay_ref`` the reference's lateral acceleration v_d ω_d now, ``mpc_step`` the
        call is an MPC step."""
        if pose is None:
            self.close_at(False, math.nan, math.nan, math.nan, float(v), float(omega), float(ay_ref),
                          bool(mpc_step))
        else:
            self.close_at(True, float(pose[0]), float(pose[1]), float(pose[2]), float(v), float(omega),
                          float(ay_ref), bool(mpc_step))

    def close_at(self, has_pose: bool, X: float, Y: float, th: float, v: float, omega: float, ay_ref: float,
                 mpc_step: bool) -> None:
        """:meth:`close` on floats: ``has_pose`` an accepted pose (X, Y, θ) now, else NaNs."""
        if not has_pose:
            X = Y = th = math.nan
        self.state, self.cur = course_close(self.params, self.state, self.cur, mpc_step, has_pose, X, Y, th,
                                            v, omega, ay_ref)


# ============================================================================ yaw-rate bias
class GyroParams(NamedTuple):
    """Parameters of the yaw-rate bias fit (:func:`gyro_params` builds them).

    Attributes:
        Td: call period T_d [s] (one sample).
        var_theta: variance of one measured heading [rad²] (the configured σ_θ, at least
            ``GYRO_HEADING_FLOOR``).
        var_omega: variance of one measured yaw rate [rad²/s²] (the configured σ_ω).
        prior_w: the prior's weight 1 / ``GYRO_PRIOR_SIGMA``² [s²/rad²] (prior mean 0).
    """

    Td: float
    var_theta: float
    var_omega: float
    prior_w: float


class GyroState(NamedTuple):
    """State of the yaw-rate bias fit: the open chord and the weighted mean of the chords' bias.

    Attributes:
        open: a chord is open (it started at a measured heading with a measured yaw rate).
        th0: the measured heading at the chord's start [rad].
        n: T_d steps since the chord's start.
        integ: ∫ ω_measured dt over the chord so far (trapezoid, raw ω) [rad].
        w_last: the last measured yaw rate (held over missing samples) [rad/s].
        gap: T_d steps since the last measured yaw rate.
        sb: Σ w b (bias of each chord b, its weight w, with forgetting; the prior's mean is 0).
        sw: Σ w (the prior's weight included) [s²/rad²].
        n_chords: chords fitted since the reset.
    """

    open: bool
    th0: float
    n: int
    integ: float
    w_last: float
    gap: int
    sb: float
    sw: float
    n_chords: int


@jitable
def gyro_params(Td: float, sigma_theta: float, sigma_omega: float) -> GyroParams:
    """The parameters from T_d and the configured heading and yaw-rate noise σ (after scale)."""
    s_th = max(sigma_theta, GYRO_HEADING_FLOOR)
    return GyroParams(Td, s_th * s_th, sigma_omega * sigma_omega,
                      1.0 / (GYRO_PRIOR_SIGMA * GYRO_PRIOR_SIGMA))


@jitable
def gyro_start(p: GyroParams) -> GyroState:
    """The state after a reset: no chord, the bias at its prior (0)."""
    return GyroState(False, 0.0, 0, 0.0, 0.0, 0, 0.0, p.prior_w, 0)


@jitable
def gyro_sample(p: GyroParams, s: GyroState, has_heading: bool, theta: float, has_omega: bool,
                omega: float) -> GyroState:
    """One T_d sample: the measured heading θ (``has_heading`` False or NaN: none — no pose, a
    pose without heading, a rejected pose) and the raw measured yaw rate ω (``has_omega`` False or
    NaN: missing; the last one is held, for at most ``GYRO_MAX_GAP_S``). A chord that has lasted
    ``GYRO_CHORD_S`` (or, sooner, that weighs as much as the fit so far: a fresh fit's chords grow
    geometrically from one sample) ends at a measured heading: its bias b = wrap(∫ω dt − (θ − θ₀)) / D enters
    the weighted mean (weight D² / (2 σ_θ² + D T_d σ_ω²), forgetting exp(−D / ``GYRO_MEMORY_S``)
    towards the prior), and the next chord starts there. Without headings nothing is fitted and
    the estimate holds."""
    th_ok = has_heading and math.isfinite(theta)
    om_ok = has_omega and math.isfinite(omega)
    if not s.open:
        if th_ok and om_ok:  # a chord starts here
            return GyroState(True, theta, 0, 0.0, omega, 0, s.sb, s.sw, s.n_chords)
        return s
    w_now = omega if om_ok else s.w_last
    gap = 0 if om_ok else s.gap + 1
    n = s.n + 1
    integ = s.integ + 0.5 * (s.w_last + w_now) * p.Td  # trapezoid over the step just ended
    if gap * p.Td > GYRO_MAX_GAP_S:  # held too long: the chord is spoilt, none open
        return GyroState(False, 0.0, 0, 0.0, 0.0, 0, s.sb, s.sw, s.n_chords)
    D = n * p.Td
    w = D * D / (2.0 * p.var_theta + D * p.Td * p.var_omega)
    # a chord ends at GYRO_CHORD_S, or sooner while it alone weighs as much as the fit so far (from
    # the prior: chords of one sample, then growing geometrically to GYRO_CHORD_S, so a fresh fit
    # has the bias within a few tenths of a second)
    if not (th_ok and (D >= GYRO_CHORD_S - 1e-9 or w >= s.sw)):
        return GyroState(True, s.th0, n, integ, w_now, gap, s.sb, s.sw, s.n_chords)
    b = _wrap(integ - (theta - s.th0)) / D
    g = math.exp(-D / GYRO_MEMORY_S)
    sb = g * s.sb + w * b
    sw = g * s.sw + (1.0 - g) * p.prior_w + w
    return GyroState(True, theta, 0, 0.0, w_now, gap, sb, sw, s.n_chords + 1)


@jitable
def gyro_bias(s: GyroState) -> float:
    """Estimated yaw-rate sensor bias [rad/s] (measured − true), bounded by ``GYRO_BIAS_MAX``."""
    return min(max(s.sb / s.sw, -GYRO_BIAS_MAX), GYRO_BIAS_MAX)


class GyroFit:
    """The yaw-rate sensor's bias from the measured headings (see the module docstring; the
    online wrapper of :func:`gyro_sample`). Call :meth:`sample` every T_d."""

    def __init__(self, Td: float, sigma_theta: float, sigma_omega: float) -> None:
        self.params = gyro_params(float(Td), float(sigma_theta), float(sigma_omega))
        self.reset()

    def reset(self) -> None:
        """Forget everything: the bias back to its prior (0)."""
        self.state = gyro_start(self.params)

    @property
    def n_chords(self) -> int:
        """Chords fitted since the reset."""
        return self.state.n_chords

    @property
    def bias(self) -> float:
        """Estimated yaw-rate sensor bias [rad/s] (measured − true)."""
        return gyro_bias(self.state)

    def sample(self, has_heading: bool, theta: float, has_omega: bool, omega: float) -> None:
        """One T_d sample (:func:`gyro_sample`)."""
        self.state = gyro_sample(self.params, self.state, has_heading, theta, has_omega, omega)


# ============================================================================ mass estimator
class MassParams(NamedTuple):
    """Parameters of the mass estimator.

    Attributes:
        mass: the model mass M [kg].
        Td: call period T_d [s].
        window: the MHE's horizon N [samples] (ā is the mean acceleration over it).
        tau: the inner loop's speed time constant τ [s] (its feedback M (v_ref − v̂)/τ).
        speed_feedback: the inner loop has that speed feedback (``lqr.speed_feedback``).
    """

    mass: float
    Td: float
    window: int
    tau: float
    speed_feedback: bool


class MassState(NamedTuple):
    """State of the mass estimator (the speeds of the window are a ring of ``window`` + 1 samples
    outside the record, written in place).

    Attributes:
        n_samples: finite samples since the reset (the ring's write position is ``n_samples`` mod
            its size).
        run: consecutive latest samples above ``MASS_MIN_SPEED`` (at most the ring's size).
        accel: ā, the window's mean acceleration [m/s²].
        lf: the high-pass filter's low-pass part of F̂.
        la: the same of ā.
        open: the fit ran at the previous sample (else the filters restart).
        sxy: Σ x y of the high-passed ā (x) and F̂ (y), with forgetting.
        sxx: Σ x² of the high-passed ā, with forgetting.
    """

    n_samples: int
    run: int
    accel: float
    lf: float
    la: float
    open: bool
    sxy: float
    sxx: float


MASS_START = MassState(0, 0, 0.0, 0.0, 0.0, False, 0.0, 0.0)


@jitable
def mass_update(p: MassParams, s: MassState, ring: NDArray[np.float64] | list[float], v_hat: float,
                F_hat: float) -> MassState:
    """One sample of the MHE's v̂ and F̂ (``ring``: the window's speeds, ``window`` + 1 of them,
    written in place): ā over the window, and — above ``MASS_MIN_SPEED`` all along a full window —
    one step of the high-passed least squares F̂_hp = ΔM ā_hp. A non-finite sample changes nothing
    but stops the fit (its high-pass restarts when it opens again)."""
    if not (math.isfinite(v_hat) and math.isfinite(F_hat)):
        return MassState(s.n_samples, s.run, s.accel, s.lf, s.la, False, s.sxy, s.sxx)
    size = p.window + 1
    ring[s.n_samples % size] = v_hat
    count = s.n_samples + 1
    run = min(s.run + 1, size) if v_hat > MASS_MIN_SPEED else 0
    n = min(count, size) - 1
    oldest = ring[count % size] if count >= size else ring[0]
    accel = (v_hat - oldest) / (n * p.Td) if n > 0 else 0.0
    if run < size:  # a window not yet full, or with a speed at or below MASS_MIN_SPEED
        return MassState(count, run, accel, s.lf, s.la, False, s.sxy, s.sxx)
    lf, la = s.lf, s.la
    if not s.open:
        lf, la = F_hat, accel
    g = p.Td / MASS_HIGHPASS_S
    lf += g * (F_hat - lf)
    la += g * (accel - la)
    y, x = F_hat - lf, accel - la
    lam = 1.0 - p.Td / MASS_MEMORY_S
    return MassState(count, run, accel, lf, la, True, lam * s.sxy + x * y, lam * s.sxx + x * x)


@jitable
def delta_mass(p: MassParams, s: MassState) -> float:
    """ΔM̂ [kg] (0 until the fit is excited, Σ x² ≥ ``MASS_EXCITATION``), within ``MASS_RANGE`` ×
    the model mass."""
    if s.sxx < MASS_EXCITATION:
        return 0.0
    lo, hi = MASS_RANGE
    return min(max(s.sxy / s.sxx, lo * p.mass), hi * p.mass)


@jitable
def inertia_force(p: MassParams, s: MassState, v_hat: float, v_ref: float) -> float:
    """The force to add to the compensated F̂: −ΔM̂ ā (the mass error's inertia is not friction)
    + ΔM̂ (v_ref − v̂)/τ with the speed feedback (its missing mass); 0 without an estimate or with
    a non-finite v̂ or v_ref."""
    dm = delta_mass(p, s)
    if dm == 0.0 or not (math.isfinite(v_hat) and math.isfinite(v_ref)):
        return 0.0
    out = -dm * s.accel
    if p.speed_feedback:
        out += dm * (v_ref - v_hat) / p.tau
    return out


class MassEstimator:
    """ΔM from the friction estimate and the window's acceleration (see the module docstring; the
    online wrapper of :func:`mass_update`). Call :meth:`update` every T_d with the MHE's v̂ and F̂."""

    def __init__(self, mass: float, Td: float, window: int, tau: float = 1.0,
                 speed_feedback: bool = False) -> None:
        self.mass = float(mass)
        self.Td = float(Td)
        self.window = int(window)
        self.params = MassParams(self.mass, self.Td, self.window, float(tau), bool(speed_feedback))
        self.reset()

    def reset(self) -> None:
        """Forget everything: ΔM̂ = 0."""
        self.state = MASS_START
        self._ring = [0.0] * (self.window + 1)

    @property
    def accel(self) -> float:
        """ā, the window's mean acceleration at the last sample [m/s²]."""
        return self.state.accel

    @property
    def delta_mass(self) -> float:
        """ΔM̂ [kg] (0 until the fit is excited), within ``MASS_RANGE`` × the model mass."""
        return delta_mass(self.params, self.state)

    def update(self, v_hat: float, F_hat: float) -> float:
        """Add one sample; returns ā, the window's mean acceleration [m/s²]."""
        self.state = mass_update(self.params, self.state, self._ring, v_hat, F_hat)
        return self.state.accel

    def inertia_terms(self, v_hat: float, F_hat: float, v_ref: float) -> float:
        """Add one sample; the force to add to the compensated F̂ (:func:`inertia_force`)."""
        self.state = mass_update(self.params, self.state, self._ring, v_hat, F_hat)
        return inertia_force(self.params, self.state, v_hat, v_ref)


# ============================================================================ steering offset
#: Prior σ of the steering-angle offset δ₀ [rad]: 1°, the class of issue 35 (a toe or steering
#: sensor misalignment; beyond a few degrees a car would be repaired, not estimated).
STEER_PRIOR_SIGMA = math.radians(1.0)
#: Prior σ of the understeer-gradient error ΔK [rad per m/s²], a nuisance regressor: C_f, C_r and
#: CoG errors change the steady steering at a given lateral acceleration (δ_eq grows by ΔK a_y),
#: and without it every curve would be read as an offset.
STEER_K_PRIOR_SIGMA = 0.01
#: Memory of the fit [s] (forgetting towards the prior's information).
STEER_MEMORY_S = 25.0
#: σ of the steady-state residual over one second of correlated samples [rad] (sensor noise, the
#: transients the quasi-steady balance does not model).
STEER_RESID_SIGMA = math.radians(0.5)
#: Time constant of the first-order filter on ω and on the steering sent [s]: both see the same
#: lag, so a transient's lag does not bias the balance.
STEER_FILTER_S = 0.3
#: The lateral dynamics' lag [s]: a moving steering inflates the residual's variance by
#: (lag · δ̇_f / STEER_RESID_SIGMA)², so transients count for little.
STEER_LAG_S = 0.3
#: Below this speed [m/s] the yaw balance says nothing (standstill, start-up): the fit holds.
STEER_V_MIN = 2.0
#: Above this |a_y| [m/s²] the tyres leave their linear range (the balance's model): it holds.
STEER_AY_MAX = 4.0
#: Bound of the estimate [rad] (3 σ of the prior).
STEER_MAX = math.radians(3.0)
#: Dead band b of the applied correction [rad]: the estimate d is applied as d³ / (d² + b²), so the
#: fit's wander on a run without offset (±2e-4 rad on the paper reference) mostly is not (31 % of
#: 2e-4 is) and a real offset is in full (99.98 % of 1°). A hard dead band, |d| − b, left b of
#: every offset in the command: on the generalisation benchmark's draws (offsets up to ±1°) that
#: 0.3 mrad made the largest lateral error up to 1.3 × larger (main set: median worst-column
#: ratio 1.53 → 1.41, 90th percentile 2.33 → 2.04 with the shrinkage).
STEER_DEADBAND = 3e-4


class SteerParams(NamedTuple):
    """Parameters of the steering-offset fit (:func:`steer_params` builds them; every tunable is a
    field, so the run engine gets them all through its float parameters).

    Attributes:
        Td: call period T_d [s] (one sample).
        C_f: front axle cornering stiffness of the balance's model [N/rad] (the stiffness fit's
            when ``stiffness_estimate`` has replaced the config's: :func:`steer_stiffness`).
        C_r: rear axle cornering stiffness of the balance's model [N/rad] (likewise).
        a: distance of the CoG to the front axle [m].
        b: distance of the CoG to the rear axle [m].
        M: mass [kg].
        I: yaw inertia [kg m²].
        lam: forgetting per T_d, exp(−T_d / ``STEER_MEMORY_S``).
        beta: the filters' gain per T_d, 1 − exp(−T_d / ``STEER_FILTER_S``).
        var_r: variance of one T_d residual [rad²] (``STEER_RESID_SIGMA``² × 1 s / T_d).
        w0: prior information of δ₀, 1 / ``STEER_PRIOR_SIGMA``² [1/rad²].
        wk: prior information of ΔK, 1 / ``STEER_K_PRIOR_SIGMA``².
        resid_sigma: ``STEER_RESID_SIGMA`` [rad].
        lag: ``STEER_LAG_S`` [s].
        v_min: ``STEER_V_MIN`` [m/s].
        ay_max: ``STEER_AY_MAX`` [m/s²].
        max_offset: ``STEER_MAX`` [rad].
        deadband: ``STEER_DEADBAND`` [rad].
    """

    Td: float
    C_f: float
    C_r: float
    a: float
    b: float
    M: float
    I: float
    lam: float
    beta: float
    var_r: float
    w0: float
    wk: float
    resid_sigma: float
    lag: float
    v_min: float
    ay_max: float
    max_offset: float
    deadband: float


class SteerState(NamedTuple):
    """State of the steering-offset fit: the filtered ω and δ, and the information form of the
    two-parameter least squares (δ₀, ΔK).

    Attributes:
        init: the filters run (they restart at the next usable sample when False).
        om_f: the filtered bias-free yaw rate [rad/s].
        de_f: the filtered steering sent [rad].
        dd_f: the rate of ``de_f`` [rad/s].
        s11: the information matrix's (δ₀, δ₀) entry (the prior's included).
        s12: its (δ₀, ΔK) entry.
        s22: its (ΔK, ΔK) entry (the prior's included).
        b1: the information vector's δ₀ entry (the prior's mean is 0).
        b2: its ΔK entry.
        n: samples fitted since the reset.
    """

    init: bool
    om_f: float
    de_f: float
    dd_f: float
    s11: float
    s12: float
    s22: float
    b1: float
    b2: float
    n: int


@jitable
def steer_params(Td: float, C_f: float, C_r: float, a: float, b: float, M: float, I: float) -> SteerParams:
    """The parameters from T_d and the MHE's vehicle (C_f, C_r, a, b, M, I)."""
    return SteerParams(Td, C_f, C_r, a, b, M, I, math.exp(-Td / STEER_MEMORY_S),
                       1.0 - math.exp(-Td / STEER_FILTER_S),
                       STEER_RESID_SIGMA * STEER_RESID_SIGMA / Td,
                       1.0 / (STEER_PRIOR_SIGMA * STEER_PRIOR_SIGMA),
                       1.0 / (STEER_K_PRIOR_SIGMA * STEER_K_PRIOR_SIGMA),
                       STEER_RESID_SIGMA, STEER_LAG_S, STEER_V_MIN, STEER_AY_MAX, STEER_MAX, STEER_DEADBAND)


@jitable
def steer_stiffness(p: SteerParams, C_f: float, C_r: float, inertia: float, a: float,
                    b: float) -> SteerParams:
    """``p`` with the lateral model (C_f, C_r, I_z, a, b) the stiffness block gave the MHE."""
    return SteerParams(p.Td, C_f, C_r, a, b, p.M, inertia, p.lam, p.beta, p.var_r, p.w0, p.wk,
                       p.resid_sigma, p.lag, p.v_min, p.ay_max, p.max_offset, p.deadband)


@jitable
def steer_start(p: SteerParams) -> SteerState:
    """The state after a reset: δ₀ = ΔK = 0 with the priors' information, the filters off."""
    return SteerState(False, 0.0, 0.0, 0.0, p.w0, 0.0, p.wk, 0.0, 0.0, 0)


@jitable
def steer_gain(p: SteerParams, v: float) -> float:
    """g(v) = δ_eq / ω [s] of the model's steady turn at speed v > 0: the α̇ = ω̇ = 0 rows of the
    single-track model (paper eq. "dynamic model", the MHE's; cos δ ≈ 1),
    ``[A22 B22; A32 B32] [α; δ] = −[A23; A33] ω``, solved for δ. It is the familiar
    δ_eq ≈ (L / v + K_us v) ω with the understeer gradient K_us of the model."""
    A22 = -(p.C_r + p.C_f) / (p.M * v)
    A23 = (p.C_r * p.b - p.C_f * p.a) / (p.M * v * v) - 1.0
    A32 = (p.C_r * p.b - p.C_f * p.a) / p.I
    A33 = -(p.C_f * p.a * p.a + p.C_r * p.b * p.b) / (p.I * v)
    B22 = p.C_f / (p.M * v)
    B32 = p.C_f * p.a / p.I
    det = A22 * B32 - B22 * A32
    return (A32 * A23 - A22 * A33) / det


@jitable
def steer_sample(p: SteerParams, s: SteerState, ok: bool, v: float, omega: float,
                 delta_sent: float) -> SteerState:
    """One T_d sample: v the estimated speed [m/s], ω the bias-free measured yaw rate [rad/s], δ
    the steering the servo was sent [rad] (the wheels stand at δ + δ₀).

    ``ok`` False (a missing or rejected sample, a failed MHE, a saturated or blind inner loop) or a
    non-finite input: the state is returned unchanged (filters and fit hold, nothing is
    forgotten). v < ``v_min`` or |v ω| > ``ay_max``: the fit holds, the filters restart at the
    next usable sample. Else the filtered residual of the steady yaw balance,
    r = g(v) ω_f − δ_f = δ₀ + ΔK v ω_f + e, enters the information-form least squares with
    forgetting ``lam`` towards the prior; the sample's variance grows with the filtered steering's
    rate (a transient is no steady state)."""
    if not (ok and math.isfinite(v) and math.isfinite(omega) and math.isfinite(delta_sent)):
        return s
    if v < p.v_min or abs(v * omega) > p.ay_max:
        return SteerState(False, omega, delta_sent, 0.0, s.s11, s.s12, s.s22, s.b1, s.b2, s.n)
    if not s.init:  # the filters start at the sample
        return SteerState(True, omega, delta_sent, 0.0, s.s11, s.s12, s.s22, s.b1, s.b2, s.n)
    om_f = s.om_f + p.beta * (omega - s.om_f)
    de_f = s.de_f + p.beta * (delta_sent - s.de_f)
    dd_f = (de_f - s.de_f) / p.Td
    r = steer_gain(p, v) * om_f - de_f
    x2 = v * om_f
    z = p.lag * dd_f / p.resid_sigma
    var = p.var_r * (1.0 + z * z)
    lam, q = p.lam, 1.0 - p.lam
    s11 = lam * s.s11 + q * p.w0 + 1.0 / var
    s12 = lam * s.s12 + x2 / var
    s22 = lam * s.s22 + q * p.wk + x2 * x2 / var
    b1 = lam * s.b1 + r / var
    b2 = lam * s.b2 + x2 * r / var
    return SteerState(True, om_f, de_f, dd_f, s11, s12, s22, b1, b2, s.n + 1)


@jitable
def steer_offset(p: SteerParams, s: SteerState) -> float:
    """The estimated δ₀ [rad] (the wheels' angle less the servo's), within ±``max_offset``."""
    det = s.s11 * s.s22 - s.s12 * s.s12
    d0 = (s.s22 * s.b1 - s.s12 * s.b2) / det
    return min(max(d0, -p.max_offset), p.max_offset)


@jitable
def steer_sigma(s: SteerState) -> float:
    """The estimate's σ [rad] (from the information matrix; samples taken as independent, so it is
    optimistic by the residual's correlation)."""
    det = s.s11 * s.s22 - s.s12 * s.s12
    return math.sqrt(max(s.s22 / det, 0.0))


@jitable
def steer_correction(p: SteerParams, s: SteerState) -> float:
    """The offset removed from the steering command [rad]: the estimate d shrunk by the dead band
    b, d³ / (d² + b²)."""
    d = steer_offset(p, s)
    return d * d * d / (d * d + p.deadband * p.deadband) if d != 0.0 else 0.0


@jitable
def steer_command(delta: float, offset: float, d_min: float, d_max: float) -> tuple[float, float]:
    """(the angle sent to the servo, the wheels' intended angle) for the inner loop's ``delta``
    [rad] with the correction ``offset`` [rad] in force: δ − offset within the servo's limits
    [d_min, d_max] (the inner loop's); the wheels' angle is ``delta`` itself unless that clip
    acted (then what the clipped command gives, sent + offset)."""
    sent = min(max(delta - offset, d_min), d_max)
    return sent, (delta if sent == delta - offset else sent + offset)


class Fusion:
    """The records of ``cfg.fusion``'s estimators that the cascade holds: the course fusion, the
    yaw-rate bias fit, the steering-offset fit and its parameters (the per-step glue around them,
    each part idle when its switch is off, is :mod:`tsmpc.control.fusion_block`)."""

    def __init__(self, cfg: Config) -> None:
        self.settings: FusionSettings = cfg.fusion
        self.Td, self.Tc = cfg.rates.Td, cfg.rates.Tc
        self.tau = cfg.lqr.speed_time_constant
        self.speed_feedback = cfg.lqr.speed_feedback
        self.course = CourseFusion(self.Tc, cfg.noise.position * cfg.noise.scale, cfg.vehicle, Td=self.Td,
                                   n_inner=cfg.rates.inner_per_outer, lateral=cfg.fusion.lateral_fit)
        nz = cfg.noise
        self.gyro = GyroFit(self.Td, nz.theta * nz.scale, nz.omega * nz.scale)
        veh = cfg.vehicle
        self._steer_p0 = steer_params(self.Td, veh.C_f, veh.C_r, veh.a, veh.b, veh.mass, veh.inertia)
        self.steer_p = self._steer_p0
        self.steer = steer_start(self.steer_p)

    def reset(self, pose: NDArray[np.float64] | None) -> None:
        """Start over from ``pose`` (None: the first measured one)."""
        self.course.reset()
        self.gyro.reset()
        self.steer_p = self._steer_p0  # (the cascade's reset gives the blocks the config's stiffnesses)
        self.steer = steer_start(self.steer_p)

    @property
    def any_course(self) -> bool:
        """The course fusion runs (for the slip, the speed or the stiffnesses)."""
        s = self.settings
        return s.course_slip or s.course_speed or s.stiffness_estimate

    def speed_offset(self, v: float) -> float:
        """What to remove from the measured speed ``v`` [m/s] (0 with ``course_speed`` off)."""
        return speed_offset(self.course.state.speed, float(v)) if self.settings.course_speed else 0.0

    def set_stiffness(self, C_f: float, C_r: float, inertia: float, a: float, b: float) -> None:
        """The stiffness block gave the MHE the lateral model (C_f, C_r, I_z, a, b): the
        steering-offset fit's balance uses it."""
        self.steer_p = steer_stiffness(self._steer_p0, float(C_f), float(C_r), float(inertia), float(a),
                                       float(b))

    def slip_correction(self, a_y: float) -> float:
        """The correction added to α̂ for the outer loop (0 with ``course_slip`` off)."""
        return self.course.slip_correction(a_y) if self.settings.course_slip else 0.0
