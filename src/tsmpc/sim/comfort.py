"""Comfort and effort metrics of a run (issue 26): lateral acceleration and jerk, longitudinal jerk,
steering rate, force-command rate, settling time — what Autoware's controller evaluation and the
ride-comfort literature compare besides the tracking error.

Every signal comes from the run log's *true* plant state and the *commands* sent to the plant,
both sampled every T_d (:class:`~tsmpc.sim.log.RunLog`):

* **Accelerations** of the CoG in the body frame, from the state [X, Y, θ, v, α, ω]: the velocity
  in the body frame is v (cos α, sin α), so (exact kinematics, no model)::

      a_x = v̇ cos α − v sin α (α̇ + ω),     a_y = v̇ sin α + v cos α (α̇ + ω)

  (a_y ≈ v ω in a steady corner). v̇ and α̇ are central differences of the true state
  (``numpy.gradient``; one-sided at the ends).
* **Filtering.** The plant input is held over each T_d, so the true accelerations jump at every
  inner step (the steering steps) and the commands carry the inner loop's reaction to sensor noise
  at up to 50 Hz: a raw difference of a difference measures that chatter, not the ride. Before each
  time derivative that a metric reports (the jerks, the steering and force rates) and for the
  accelerations themselves, the signal passes a **zero-phase 2nd-order Butterworth low-pass at
  :data:`CUTOFF_HZ` = 5 Hz** (``scipy.signal.filtfilt``: no delay, gain |H|² = 1/(1 + (f/5)⁴),
  i.e. > 0.9999 below 0.5 Hz and 0.5 at 5 Hz). 5 Hz is the Nyquist frequency of the 10 Hz outer
  loop: every guidance law's own content lies below it, so the metrics compare the guidance laws
  and not the inner loop's noise response (which is the same cascade for all of them).
  Derivatives of the filtered signal are central differences. Signals shorter than the filter's
  padding are differentiated unfiltered.
* **Reported**: max |·| and RMS over the run of a_y, lateral jerk ȧ_y, longitudinal jerk ȧ_x,
  steering rate δ̇ (of the commanded steering), force-command rate Ḟ_xR.
* **Settling time**: the first time (from the start of the run) after which |e_y| — the true
  lateral error, sampled every T_c — stays at or below :data:`SETTLING_BAND_M` = 0.10 m for the rest of
  the run: 0 if it never exceeds the band, +inf if the last sample is outside it (it has not
  settled within the run; NaN only for a run without samples). Meant for the
  ``offset_start`` scenario (2 m, 0.2 rad off the path at t = 0); on other runs it says when the
  last excursion beyond 0.10 m ended.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.sim.log import RunLog

__all__ = [
    "CUTOFF_HZ",
    "SETTLING_BAND_M",
    "ComfortMetrics",
    "body_accelerations",
    "comfort_metrics",
    "lowpass",
    "rate",
    "run_comfort",
    "settling_time",
]

#: Cut-off of the zero-phase low-pass applied before every reported derivative [Hz].
CUTOFF_HZ = 5.0
#: Band of the settling time: |e_y| ≤ this for the rest of the run [m].
SETTLING_BAND_M = 0.10
_ORDER = 2


def lowpass(x: ArrayLike, dt: float, cutoff_hz: float = CUTOFF_HZ) -> NDArray[np.float64]:
    """Zero-phase 2nd-order Butterworth low-pass of ``x`` sampled every ``dt`` (unchanged when the
    cut-off is at or above Nyquist or the signal is too short to pad)."""
    from scipy.signal import butter, filtfilt

    a = np.asarray(x, dtype=float)
    wn = 2.0 * cutoff_hz * dt  # cut-off relative to Nyquist
    if not 0.0 < wn < 1.0:
        return a.copy()
    # (scipy's butter is unannotated: pyright infers its return over every output= and finds None)
    ba: Any = butter(_ORDER, wn)
    b, den = ba
    pad = 3 * max(len(b), len(den))
    if a.size <= pad:
        return a.copy()
    return np.asarray(filtfilt(b, den, a), dtype=float)


def rate(x: ArrayLike, dt: float, cutoff_hz: float = CUTOFF_HZ) -> NDArray[np.float64]:
    """Time derivative of ``x`` after :func:`lowpass`: central differences (one-sided at the ends)."""
    a = lowpass(x, dt, cutoff_hz)
    return np.gradient(a, dt) if a.size > 1 else np.zeros_like(a)


def body_accelerations(state: ArrayLike, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(a_x, a_y) [m/s²] of the CoG in the body frame from the state (M, 6) [X, Y, θ, v, α, ω]
    sampled every ``dt`` (unfiltered)."""
    x = np.asarray(state, dtype=float).reshape(-1, 6)
    v, al, om = x[:, 3], x[:, 4], x[:, 5]
    if v.size < 2:
        return np.zeros_like(v), np.zeros_like(v)
    vd, ald = np.gradient(v, dt), np.gradient(al, dt)
    turn = v * (ald + om)
    ca, sa = np.cos(al), np.sin(al)
    return vd * ca - sa * turn, vd * sa + ca * turn


def settling_time(t: ArrayLike, e_y: ArrayLike, band: float = SETTLING_BAND_M) -> float:
    """First time (relative to ``t[0]``) after which |e_y| ≤ ``band`` for the rest of the samples;
    0 if never outside, +inf if the last sample is outside (not settled within the record), NaN
    if there are no samples."""
    tt = np.asarray(t, dtype=float)
    e = np.abs(np.asarray(e_y, dtype=float))
    if e.size == 0:
        return float("nan")
    if not e[-1] <= band:
        return float("inf")
    out = np.flatnonzero(~(e <= band))  # NaN counts as outside
    if out.size == 0:
        return 0.0
    return float(tt[out[-1] + 1] - tt[0])


def _max_rms(a: NDArray[np.float64]) -> tuple[float, float]:
    if a.size == 0:
        return float("nan"), float("nan")
    return float(np.max(np.abs(a))), float(np.sqrt(np.mean(a * a)))


@dataclass(frozen=True)
class ComfortMetrics:
    """Comfort and effort of one run (module docstring: definitions and filtering)."""

    lat_accel_max: float  #: max |a_y| [m/s²]
    lat_accel_rms: float  #: RMS a_y [m/s²]
    lat_jerk_max: float  #: max |ȧ_y| [m/s³]
    lat_jerk_rms: float  #: RMS ȧ_y [m/s³]
    lon_jerk_max: float  #: max |ȧ_x| [m/s³]
    lon_jerk_rms: float  #: RMS ȧ_x [m/s³]
    steering_rate_max: float  #: max |δ̇| of the commanded steering [rad/s]
    steering_rate_rms: float  #: RMS δ̇ [rad/s]
    force_rate_max: float  #: max |Ḟ_xR| of the commanded force [N/s]
    force_rate_rms: float  #: RMS Ḟ_xR [N/s]
    settling_time_s: float  #: |e_y| ≤ settling_band_m from then on [s]; +inf: not settled
    settling_band_m: float = SETTLING_BAND_M
    cutoff_hz: float = CUTOFF_HZ  #: low-pass cut-off before the derivatives [Hz]

    def as_dict(self) -> dict[str, float]:
        """The metrics.json entry ``comfort``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def comfort_metrics(
    state: ArrayLike, command: ArrayLike, dt: float, t_outer: ArrayLike, e_y: ArrayLike,
    *, cutoff_hz: float = CUTOFF_HZ, band: float = SETTLING_BAND_M,
) -> ComfortMetrics:
    """Comfort metrics from plain arrays: the true state (M, 6) and the commands (M, 2)
    [F_xR, δ] every ``dt``; the true lateral error ``e_y`` at the times ``t_outer``."""
    ax, ay = body_accelerations(state, dt)
    cmd = np.asarray(command, dtype=float).reshape(-1, 2)
    ay_f = lowpass(ay, dt, cutoff_hz)
    jy = np.gradient(ay_f, dt) if ay_f.size > 1 else np.zeros_like(ay_f)
    jx = rate(ax, dt, cutoff_hz)
    ddel = rate(cmd[:, 1], dt, cutoff_hz)
    dF = rate(cmd[:, 0], dt, cutoff_hz)
    vals = (*_max_rms(ay_f), *_max_rms(jy), *_max_rms(jx), *_max_rms(ddel), *_max_rms(dF))
    return ComfortMetrics(*vals, settling_time_s=settling_time(t_outer, e_y, band),
                          settling_band_m=band, cutoff_hz=cutoff_hz)


def run_comfort(log: RunLog) -> ComfortMetrics:
    """:func:`comfort_metrics` of a run log (true state and commands every T_d, true e_y every T_c)."""
    return comfort_metrics(log.state, log.command, log.Td, log.t_outer, log.errors[:, 1])
