"""The fusion's glue in the cascade as one block (issue 34): what the cascade does every T_d around
the estimators of :mod:`tsmpc.estimation.fusion` (``cfg.fusion``'s ``gyro_bias``, the course fits
and ``steering_offset``).

* :func:`fusion_before` — before the MPC and the MHE: the yaw-rate bias fit's sample (the raw ω
  against the accepted pose's heading, :func:`~tsmpc.estimation.fusion.gyro_sample`) and ω less
  the bias for every block after it; then the course fusion's close
  (:func:`~tsmpc.estimation.fusion.course_close`: an accepted pose may end the open interval and a
  chord) on the speed and bias-free ω when the gates accepted them (NaN else) and the reference's
  lateral acceleration v_d ω_d at the sample of the call's time (:func:`ay_ref_at`).
* :func:`fusion_after` — after the MHE: the course fusion's sample
  (:func:`~tsmpc.estimation.fusion.course_sample`: the accepted speed, the estimate's α̂ and
  v̂ ω̂, the bias-free ω, the input the MHE's model saw) and the steering-offset fit's sample
  (:func:`~tsmpc.estimation.fusion.steer_sample`: the steady yaw balance of v̂ and ω against the
  angle last sent), frozen (:func:`steer_usable`) while the sample is refused, the MHE's estimate
  is not OK, the cascade is blind or the last command was saturated.
* :func:`servo` — the angle sent: the inner loop's δ less the steering offset in force
  (:func:`~tsmpc.estimation.fusion.steer_correction`) within the steering limits, and the wheels'
  intended angle (:func:`~tsmpc.estimation.fusion.steer_command`); with ``steering_offset`` off
  the inner loop's δ itself, unclipped, no offset.

A part switched off does nothing (its state is returned as it came; the bias and the offset are
0): the switches are the block's parameters (:class:`FusionParams`), not the caller's branches.

One definition, three callers: :class:`~tsmpc.control.cascade.Cascade` calls the three functions
as Python on the records its :class:`~tsmpc.estimation.fusion.Fusion` holds (a plain tuple back:
a NamedTuple costs the cascade ≈ 0.2 µs a call); the run engine (``tsmpc.kernels.engine.run``)
and the batch (which runs ``run`` per lane) compile the same functions through
:func:`before_at`, :func:`after_at` and :func:`servo_at`, which keep the records in a float
vector of named slots (``FB_*``): the yaw-rate and steering fits' (:func:`gyro_load` /
:func:`gyro_store`, :func:`steer_load` / :func:`steer_store`), the servo's, the bias-free ω of
the call (``FB_OMEGA``: the engine's phases resume between the parts) and the course fusion's
:class:`~tsmpc.estimation.fusion.CourseState` but its ring (:func:`course_load` /
:func:`course_store`; the outer block reads its slip fit, :func:`slip_load`), the ring's
intervals and the open one in rows of their own (``IV_*``: :func:`iv_load` / :func:`iv_store`).
:func:`fusion_state` makes the vector and rows of a cascade's records. The parameters cross
into compiled code as one float vector (:func:`pack_fusion` / :func:`unpack_fusion`). The four
step functions are inlined into their compiled callers (``jitable_inline``): the course state
passed by value through two call layers cost the engine's paper run ≈ 2 % (0.140 → 0.143 s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.inner_block import EST_OK
from tsmpc.control.stiffness_block import SA_A, SA_B, SA_CF, SA_CR, SA_HAS, SA_I
from tsmpc.estimation.fusion import (
    RING,
    CourseParams,
    CourseState,
    GyroParams,
    GyroState,
    Interval,
    LateralFit,
    SlipFit,
    SpeedFit,
    SteerParams,
    SteerState,
    StiffFit,
    course_close,
    course_ends,
    course_sample,
    gyro_bias,
    gyro_sample,
    steer_command,
    steer_correction,
    steer_sample,
    steer_stiffness,
)
from tsmpc.kernels.jit import jitable, jitable_inline

__all__ = [
    "FB_AHPREV", "FB_BETA", "FB_DENF", "FB_DENR", "FB_GYCHORDS", "FB_GYGAP", "FB_GYINT", "FB_GYN",
    "FB_GYOPEN", "FB_GYSB", "FB_GYSW", "FB_GYTH0", "FB_GYWLAST", "FB_HASAH", "FB_KAPPA", "FB_LFIT",
    "FB_LGIVEN", "FB_LP", "FB_LX", "FB_N1", "FB_N2", "FB_NCHORDS", "FB_NIV", "FB_NUMF", "FB_NUMR", "FB_OFF",
    "FB_OMEGA", "FB_OMNOW", "FB_P00", "FB_P01", "FB_P10", "FB_P11", "FB_SENT", "FB_SH0", "FB_SH1", "FB_SINCE",
    "FB_SL00", "FB_SL01", "FB_SL11", "FB_SN1", "FB_SN2", "FB_STB1", "FB_STB2", "FB_STDDF", "FB_STDEF",
    "FB_STINIT", "FB_STN", "FB_STOMF", "FB_STS11", "FB_STS12", "FB_STS22", "FB_VNOW", "IV_AYREF", "IV_N",
    "IV_OK", "IV_OPEN", "IV_SDELTA", "IV_SF", "IV_STH", "IV_SV", "IV_SVALPHA", "IV_SVAY", "IV_SVDTH",
    "IV_SVFULL", "IV_SVW", "IV_SWV", "IV_SX", "IV_SY", "IV_THLAST", "IV_VFIRST", "IV_WFIRST", "IV_WLAST",
    "N_FB", "N_FBP", "N_IV", "FusionParams", "after_at", "ay_ref_at", "before_at", "course_load",
    "course_store", "fusion_after", "fusion_before", "fusion_state", "given_steer", "gyro_load", "gyro_store",
    "iv_load", "iv_store", "lateral_load", "pack_fusion", "servo", "servo_at", "slip_load", "speed_load",
    "steer_load", "steer_store", "steer_usable", "unpack_fusion",
]

#: The block's state vector (floats; flags 1.0 / 0.0, counts whole numbers): the yaw-rate bias
#: fit's GyroState, the steering-offset fit's SteerState (their fields in order), the steering
#: offset the last command took off, the angle last sent, and the bias-free ω of the call.
(FB_GYOPEN, FB_GYTH0, FB_GYN, FB_GYINT, FB_GYWLAST, FB_GYGAP, FB_GYSB, FB_GYSW, FB_GYCHORDS,
 FB_STINIT, FB_STOMF, FB_STDEF, FB_STDDF, FB_STS11, FB_STS12, FB_STS22, FB_STB1, FB_STB2, FB_STN,
 FB_OFF, FB_SENT, FB_OMEGA) = range(22)
#: Then the course fusion's CourseState but its ring (the ring's intervals and the open interval are
#: rows of their own arrays: ``IV_*`` slots): the slip fit (κ, β, P, the noise sums), the speed
#: fit, the stiffness fit, the measured ω and v at the last interval's end, the intervals held,
#: the chords fitted, the calls since the last interval ended, the seconds of chords (the age).
(FB_KAPPA, FB_BETA, FB_P00, FB_P01, FB_P10, FB_P11, FB_N2, FB_N1, FB_SL00, FB_SL01, FB_SL11, FB_SH0,
 FB_SH1, FB_SN2, FB_SN1, FB_NUMF, FB_NUMR, FB_DENF, FB_DENR, FB_AHPREV, FB_HASAH, FB_OMNOW, FB_VNOW, FB_NIV,
 FB_NCHORDS, FB_SINCE, FB_AGE) = range(22, 49)
#: Then the joint lateral fit (fusion.LateralFit): its x (5), the upper triangle of P (15), the
#: flags "a chord was fitted" and "its model is in force".
FB_LX, FB_LP, FB_LFIT, FB_LGIVEN = 49, 54, 69, 70
N_FB = 71
#: An :class:`~tsmpc.estimation.fusion.Interval`'s fields in a row (the ring's, the open interval's).
(IV_OPEN, IV_OK, IV_SX, IV_SY, IV_STH, IV_N, IV_SV, IV_SVDTH, IV_SVALPHA, IV_SVAY, IV_SVFULL,
 IV_SDELTA, IV_SWV, IV_SVW, IV_SF, IV_WFIRST, IV_AYREF, IV_VFIRST, IV_THLAST, IV_WLAST) = range(20)
N_IV = 20
assert RING == 8  # course_load lists the ring's intervals one by one


class FusionParams(NamedTuple):
    """The block's constants.

    Attributes:
        gyro: the yaw-rate bias fit runs and its bias is removed (``fusion.gyro_bias``).
        course: the course fusion runs (``course_slip``, ``course_speed`` or ``stiffness_estimate``).
        steer: the steering-offset fit runs and the servo takes its offset off
            (``fusion.steering_offset``).
        slip: the slip fit's course correction κ̂ a_y + β̂ is used (``fusion.course_slip``): the
            dead reckoning's velocity heading takes it too.
        d_min: the servo's lower steering limit [rad] (the inner loop's).
        d_max: its upper limit [rad].
        gp: the yaw-rate bias fit's parameters.
        cp: the course fusion's parameters.
    """

    gyro: bool
    course: bool
    steer: bool
    slip: bool
    d_min: float
    d_max: float
    gp: GyroParams
    cp: CourseParams


#: Values of :func:`pack_fusion`'s vector: the switches, the limits, GyroParams' 4 fields, the
#: steering-offset fit's SteerParams (18 fields) as the config gives them.
N_FBP = 28


@jitable
def ay_ref_at(Tc: float, t: float, t_off: float, v_d: Sequence[float] | NDArray[np.float64],
              w_d: Sequence[float] | NDArray[np.float64]) -> float:
    """The reference's lateral acceleration v_d ω_d at the sample of time ``t`` (the reference time
    t − ``t_off``, within the reference's samples)."""
    kc = min(max(math.floor((t - t_off) / Tc + 1e-6), 0), len(v_d) - 1)
    return v_d[kc] * w_d[kc]


@jitable_inline
def fusion_before(p: FusionParams, g: GyroState, cs: CourseState, cur: Interval, pose_ok: bool, X: float,
                  Y: float, th: float, ok: bool, v: float, omega: float, mpc_step: bool, t: float,
                  t_off: float, v_d: Sequence[float] | NDArray[np.float64],
                  w_d: Sequence[float] | NDArray[np.float64]
                  ) -> tuple[float, GyroState, CourseState, Interval]:
    """The part before the MPC and the MHE, on the pose (X, Y, θ) (``pose_ok``: the gates accepted
    it) and the speed v and raw yaw rate ω (``ok``: accepted and fresh): (ω less the bias, the
    yaw-rate fit's state, the course state, the open interval)."""
    om, g = gyro_before(p, g, pose_ok, th, ok, omega)
    if p.course:  # an accepted pose may end the open interval (only samples the gates accepted)
        cs, cur = course_close(p.cp, cs, cur, mpc_step, pose_ok, X, Y, th, v if ok else math.nan,
                               om if ok else math.nan, ay_ref_at(p.cp.Tc, t, t_off, v_d, w_d))
    return om, g, cs, cur


@jitable
def gyro_before(p: FusionParams, g: GyroState, pose_ok: bool, th: float, ok: bool,
                omega: float) -> tuple[float, GyroState]:
    """:func:`fusion_before`'s yaw-rate bias fit: (ω less the bias, the fit's state)."""
    b = 0.0
    if p.gyro:
        g = gyro_sample(p.gp, g, pose_ok, th, ok, omega)
        b = gyro_bias(g)
    return omega - b, g


@jitable
def steer_usable(ok: bool, est_status: int, blind: bool, last_saturated: bool) -> bool:
    """The steering-offset fit takes the sample: accepted, the MHE's estimate OK, not blind, the
    last command not saturated."""
    return ok and est_status == EST_OK and not blind and not last_saturated


@jitable_inline
def fusion_after(p: FusionParams, sp: SteerParams, st: SteerState, cur: Interval, ok: bool, pose_ok: bool,
                 th: float, v: float, v_hat: float, a_hat: float, w_hat: float, omega: float, delta: float,
                 force: float, est_status: int, blind: bool, last_saturated: bool,
                 sent: float) -> tuple[Interval, SteerState]:
    """The part after the MHE, on the estimate (v̂, α̂, ω̂) and its status code, the bias-free ω,
    the input [F_xR, δ] the MHE's model saw (``force``, ``delta``) and the angle last ``sent``:
    (the open interval, the steering-offset fit's state). A rejected speed is garbage and a
    rejected or missing heading the gyro's integral since the last accepted one (course_sample)."""
    if p.course:
        cur = course_sample(p.cp, cur, ok, pose_ok, th, v, a_hat, v_hat * w_hat, omega, delta, force)
    if p.steer:
        st = steer_sample(sp, st, steer_usable(ok, est_status, blind, last_saturated), v_hat, omega, sent)
    return cur, st


@jitable
def servo(p: FusionParams, sp: SteerParams, st: SteerState, delta: float) -> tuple[float, float, float]:
    """The inner loop's ``delta`` to the servo: (the angle sent, the wheels' intended angle — what
    the MHE's model sees next —, the steering offset in force)."""
    if not p.steer:
        return delta, delta, 0.0
    off = steer_correction(sp, st)
    sent, wheels = steer_command(delta, off, p.d_min, p.d_max)
    return sent, wheels, off


@jitable
def given_steer(sp: SteerParams, sa: NDArray[np.float64] | list[float]) -> SteerParams:
    """The steering-offset fit's parameters ``sp`` (the config's) with the lateral model the stiffness
    block gave the MHE, once it has (its record ``sa``: tsmpc.control.stiffness_block's SA_*)."""
    if sa[SA_HAS] != 0.0:
        return steer_stiffness(sp, sa[SA_CF], sa[SA_CR], sa[SA_I], sa[SA_A], sa[SA_B])
    return sp


# ---------------------------------------------------------------------------- the state vector
@jitable
def gyro_load(fb: NDArray[np.float64]) -> GyroState:
    """The yaw-rate bias fit's record of the state vector."""
    return GyroState(fb[FB_GYOPEN] != 0.0, fb[FB_GYTH0], int(fb[FB_GYN]), fb[FB_GYINT], fb[FB_GYWLAST],
                     int(fb[FB_GYGAP]), fb[FB_GYSB], fb[FB_GYSW], int(fb[FB_GYCHORDS]))


@jitable
def gyro_store(s: GyroState, fb: NDArray[np.float64]) -> None:
    """The yaw-rate bias fit's record into the state vector."""
    fb[FB_GYOPEN], fb[FB_GYTH0], fb[FB_GYN] = 1.0 if s.open else 0.0, s.th0, float(s.n)
    fb[FB_GYINT], fb[FB_GYWLAST], fb[FB_GYGAP] = s.integ, s.w_last, float(s.gap)
    fb[FB_GYSB], fb[FB_GYSW], fb[FB_GYCHORDS] = s.sb, s.sw, float(s.n_chords)


@jitable
def steer_load(fb: NDArray[np.float64]) -> SteerState:
    """The steering-offset fit's record of the state vector."""
    return SteerState(fb[FB_STINIT] != 0.0, fb[FB_STOMF], fb[FB_STDEF], fb[FB_STDDF], fb[FB_STS11],
                      fb[FB_STS12], fb[FB_STS22], fb[FB_STB1], fb[FB_STB2], int(fb[FB_STN]))


@jitable
def steer_store(s: SteerState, fb: NDArray[np.float64]) -> None:
    """The steering-offset fit's record into the state vector."""
    fb[FB_STINIT], fb[FB_STOMF], fb[FB_STDEF], fb[FB_STDDF] = 1.0 if s.init else 0.0, s.om_f, s.de_f, s.dd_f
    fb[FB_STS11], fb[FB_STS12], fb[FB_STS22] = s.s11, s.s12, s.s22
    fb[FB_STB1], fb[FB_STB2], fb[FB_STN] = s.b1, s.b2, float(s.n)


@jitable
def iv_load(a: NDArray[np.float64]) -> Interval:
    """The interval of a row (``IV_*`` slots)."""
    return Interval(a[IV_OPEN] != 0.0, a[IV_OK] != 0.0, a[IV_SX], a[IV_SY], a[IV_STH], int(a[IV_N]),
                    a[IV_SV], a[IV_SVDTH], a[IV_SVALPHA], a[IV_SVAY], a[IV_SVFULL], a[IV_SDELTA],
                    a[IV_SWV], a[IV_SVW], a[IV_SF], a[IV_WFIRST], a[IV_AYREF], a[IV_VFIRST], a[IV_THLAST],
                    a[IV_WLAST])


@jitable
def iv_store(iv: Interval, a: NDArray[np.float64]) -> None:
    """An interval into a row."""
    a[IV_OPEN], a[IV_OK] = 1.0 if iv.open else 0.0, 1.0 if iv.ok else 0.0
    a[IV_SX], a[IV_SY], a[IV_STH], a[IV_N] = iv.sx, iv.sy, iv.sth, float(iv.n)
    a[IV_SV], a[IV_SVDTH], a[IV_SVALPHA], a[IV_SVAY] = iv.sv, iv.sv_dth, iv.sv_alpha, iv.sv_ay
    a[IV_SVFULL], a[IV_SDELTA], a[IV_SWV], a[IV_SVW] = iv.sv_full, iv.s_delta, iv.s_w_v, iv.s_vw
    a[IV_SF], a[IV_WFIRST], a[IV_AYREF], a[IV_VFIRST] = iv.s_F, iv.w_first, iv.ay_ref, iv.v_first
    a[IV_THLAST], a[IV_WLAST] = iv.th_last, iv.w_last


@jitable
def slip_load(fb: NDArray[np.float64]) -> SlipFit:
    """The slip fit's record of the state vector (the outer block's course correction reads it)."""
    return SlipFit(fb[FB_KAPPA], fb[FB_BETA], fb[FB_P00], fb[FB_P01], fb[FB_P10], fb[FB_P11], fb[FB_N2],
                   fb[FB_N1])


@jitable
def speed_load(fb: NDArray[np.float64]) -> SpeedFit:
    """The speed sensor's fit of the state vector (the MHE's input reads it)."""
    return SpeedFit(fb[FB_SL00], fb[FB_SL01], fb[FB_SL11], fb[FB_SH0], fb[FB_SH1], fb[FB_SN2], fb[FB_SN1])


@jitable
def course_load(fb: NDArray[np.float64], ivs: NDArray[np.float64]) -> CourseState:
    """The course fusion's state of the state vector and the ring's rows ``ivs`` (RING, N_IV)."""
    ring = (iv_load(ivs[0]), iv_load(ivs[1]), iv_load(ivs[2]), iv_load(ivs[3]), iv_load(ivs[4]),
            iv_load(ivs[5]), iv_load(ivs[6]), iv_load(ivs[7]))
    stiff = StiffFit(fb[FB_NUMF], fb[FB_NUMR], fb[FB_DENF], fb[FB_DENR], fb[FB_AHPREV], fb[FB_HASAH] != 0.0)
    return CourseState(ring, int(fb[FB_NIV]), fb[FB_OMNOW], fb[FB_VNOW], int(fb[FB_NCHORDS]), slip_load(fb),
                       speed_load(fb), stiff, int(fb[FB_SINCE]), fb[FB_AGE], lateral_load(fb))


@jitable
def lateral_load(fb: NDArray[np.float64]) -> LateralFit:
    """The joint lateral fit's record of the state vector."""
    x, q = FB_LX, FB_LP
    return LateralFit((fb[x], fb[x + 1], fb[x + 2], fb[x + 3], fb[x + 4]),
                      (fb[q], fb[q + 1], fb[q + 2], fb[q + 3], fb[q + 4], fb[q + 5], fb[q + 6], fb[q + 7],
                       fb[q + 8], fb[q + 9], fb[q + 10], fb[q + 11], fb[q + 12], fb[q + 13], fb[q + 14]),
                      fb[FB_LFIT] != 0.0, fb[FB_LGIVEN] != 0.0)


@jitable
def course_store(s: CourseState, fb: NDArray[np.float64], ivs: NDArray[np.float64]) -> None:
    """The course fusion's state into the state vector and the ring's rows."""
    for r in range(RING):
        iv_store(s.ring[r], ivs[r])
    fb[FB_NIV], fb[FB_NCHORDS], fb[FB_SINCE] = float(s.n_iv), float(s.n_chords), float(s.since)
    fb[FB_OMNOW], fb[FB_VNOW], fb[FB_AGE] = s.omega_now, s.v_now, s.age
    f = s.slip
    fb[FB_KAPPA], fb[FB_BETA] = f.kappa, f.beta
    fb[FB_P00], fb[FB_P01], fb[FB_P10], fb[FB_P11] = f.P00, f.P01, f.P10, f.P11
    fb[FB_N2], fb[FB_N1] = f.n2, f.n1
    q = s.speed
    fb[FB_SL00], fb[FB_SL01], fb[FB_SL11], fb[FB_SH0], fb[FB_SH1] = q.l00, q.l01, q.l11, q.h0, q.h1
    fb[FB_SN2], fb[FB_SN1] = q.n2, q.n1
    c = s.stiff
    fb[FB_NUMF], fb[FB_NUMR], fb[FB_DENF], fb[FB_DENR] = c.num_f, c.num_r, c.den_f, c.den_r
    fb[FB_AHPREV], fb[FB_HASAH] = c.alpha_prev, 1.0 if c.has_prev else 0.0
    lat = s.lat
    for i in range(5):
        fb[FB_LX + i] = lat.x[i]
    for i in range(15):
        fb[FB_LP + i] = lat.P[i]
    fb[FB_LFIT], fb[FB_LGIVEN] = 1.0 if lat.fitted else 0.0, 1.0 if lat.given else 0.0


def fusion_state(g: GyroState, st: SteerState, offset: float, sent: float, cs: CourseState,
                 cur: Interval) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(the state vector, the ring's rows, the open interval's row) of the records (a cascade's,
    for a compiled caller that starts from it)."""
    fb, ivs, row = np.zeros(N_FB), np.zeros((RING, N_IV)), np.zeros(N_IV)
    gyro_store(g, fb)
    steer_store(st, fb)
    fb[FB_OFF], fb[FB_SENT] = offset, sent
    course_store(cs, fb, ivs)
    iv_store(cur, row)
    return fb, ivs, row


@jitable_inline
def before_at(p: FusionParams, fb: NDArray[np.float64], ivs: NDArray[np.float64], row: NDArray[np.float64],
              pose_ok: bool, X: float, Y: float, th: float, ok: bool, v: float, omega: float, mpc_step: bool,
              t: float, t_off: float, v_d: Sequence[float] | NDArray[np.float64],
              w_d: Sequence[float] | NDArray[np.float64]) -> float:
    """:func:`fusion_before` on the state vector ``fb``, the ring's rows ``ivs`` and the open
    interval's ``row``: ω less the bias (kept in ``FB_OMEGA`` too)."""
    if p.course and not course_ends(p.cp, int(fb[FB_SINCE]) + 1, mpc_step, pose_ok, X, Y, th):
        # no interval ends (most calls): course_close would only count the call, so the ring's
        # round trip through the records is skipped (the same state, a fraction of the batch's time)
        om, g = gyro_before(p, gyro_load(fb), pose_ok, th, ok, omega)
        fb[FB_SINCE] += 1.0
    else:
        om, g, cs, cur = fusion_before(p, gyro_load(fb), course_load(fb, ivs), iv_load(row), pose_ok, X, Y,
                                       th, ok, v, omega, mpc_step, t, t_off, v_d, w_d)
        if p.course:
            course_store(cs, fb, ivs)
            iv_store(cur, row)
    if p.gyro:
        gyro_store(g, fb)
    fb[FB_OMEGA] = om
    return om


@jitable_inline
def after_at(p: FusionParams, fb: NDArray[np.float64], sp: SteerParams, row: NDArray[np.float64], ok: bool,
             pose_ok: bool, th: float, v: float, v_hat: float, a_hat: float, w_hat: float, delta: float,
             force: float, est_status: int, blind: bool, last_saturated: bool) -> None:
    """:func:`fusion_after` on the state vector ``fb`` (the call's bias-free ω and the angle last
    sent read from it) and the open interval's ``row``."""
    cur, st = fusion_after(p, sp, steer_load(fb), iv_load(row), ok, pose_ok, th, v, v_hat, a_hat, w_hat,
                           fb[FB_OMEGA], delta, force, est_status, blind, last_saturated, fb[FB_SENT])
    if p.course:
        iv_store(cur, row)
    if p.steer:
        steer_store(st, fb)


@jitable
def servo_at(p: FusionParams, fb: NDArray[np.float64], sp: SteerParams, delta: float) -> tuple[float, float]:
    """:func:`servo` on the state vector ``fb`` (the offset in force and the angle sent kept):
    (the angle sent, the wheels' intended angle)."""
    sent, wheels, off = servo(p, sp, steer_load(fb), delta)
    fb[FB_OFF], fb[FB_SENT] = off, sent
    return sent, wheels


# ---------------------------------------------------------------------------- the parameters
def pack_fusion(p: FusionParams, sp: SteerParams) -> NDArray[np.float64]:
    """The record (but its course parameters, which the compiled caller builds) and the
    steering-offset fit's parameters as the config gives them, as the float vector
    :func:`unpack_fusion` reads."""
    return np.array([p.gyro, p.course, p.steer, p.slip, p.d_min, p.d_max, *p.gp, *sp], dtype=np.float64)


@jitable
def unpack_fusion(a: NDArray[np.float64], cp: CourseParams) -> tuple[FusionParams, SteerParams]:
    """The records of :func:`pack_fusion`'s vector, with the course parameters ``cp``."""
    gp = GyroParams(a[6], a[7], a[8], a[9])
    sp = SteerParams(a[10], a[11], a[12], a[13], a[14], a[15], a[16], a[17], a[18], a[19], a[20], a[21],
                     a[22], a[23], a[24], a[25], a[26], a[27])
    return FusionParams(a[0] != 0.0, a[1] != 0.0, a[2] != 0.0, a[3] != 0.0, a[4], a[5], gp, cp), sp
