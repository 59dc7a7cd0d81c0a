"""The sensors of a run (the paper's scenario, and the sensor class of issue 35): the seeded noise,
the sensor model of ``[scenario.sensors]`` and the bursts of the named robustness scenarios.

The per-sample logic is written once, as ``@jitable`` functions over ``NamedTuple`` records
(:mod:`tsmpc.kernels.jit`). The simulator's sensor step :func:`sensor_step` (the plant's true
[X, Y, θ, v, ω] plus the seeded noise, then the scenario's burst fault, then the sensor model, at
the fault's time :func:`fault_time`) is one definition: the simulator's Python loop calls it
through :class:`SensorRun`, the run engine and the batch compile it
(``tsmpc.kernels.engine._sensor``) on the same records. :class:`SensorModel`,
:class:`DropoutFault` and :class:`NaNBurstFault` call the same blocks as objects (a fault of the
user's, or a model after one, runs that way in the Python loop). A sample is a 5-tuple
[X, Y, θ, v, ω]; NaN in a channel is a missing measurement.

The random numbers are the caller's: the classes draw them one sample at a time, a run
(:class:`SensorRun`, both loops) draws the same streams for the whole run beforehand
(:func:`model_draws`, :func:`noise_draws`), so every way sees the same numbers.

What :func:`sensor_sample` does to a noisy sample, in order (each off by default):

1. per channel, ``scale · y + (bias + drift · t + walk)``: a scale factor, a constant offset, a
   linear drift and a random walk (``walk`` grows by ``walk_sigma · √T_d`` · N(0, 1) per sample,
   from 0 at the first sample);
2. extra GNSS noise on X and Y;
3. the heading left out of the pose (θ missing), and each sensor's sample rate: a sample that is
   not due is missing (NaN), as a dropout is — the pose (X, Y, θ), the speed and the yaw rate
   each have their own rate; a sample is due at the first call at or after each multiple of
   1/rate;
4. the transport delay (a FIFO of whole samples);
5. dropouts (the whole sample lost, as NaN, or the previous one repeated: a stalled bus).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import NoiseSettings, SensorFaults
from tsmpc.kernels.jit import jitable

__all__ = [
    "BURST_HOLD",
    "BURST_NAN",
    "BURST_PASS",
    "FAULT_HOLD_BURST",
    "FAULT_NAN_BURST",
    "FAULT_NONE",
    "BurstParams",
    "BurstState",
    "DropoutFault",
    "NaNBurstFault",
    "SensorBlockParams",
    "SensorDraws",
    "SensorFault",
    "SensorModel",
    "SensorNoise",
    "SensorParams",
    "SensorRun",
    "SensorState",
    "burst_action",
    "burst_sample",
    "fault_problem",
    "fault_time",
    "model_draws",
    "noise_draws",
    "sensor_sample",
    "sensor_step",
    "split_fault",
]

#: A sensor sample [X, Y, θ, v, ω] (NaN: missing).
Sample = tuple[float, float, float, float, float]
_NAN5: Sample = (math.nan, math.nan, math.nan, math.nan, math.nan)
_ZERO5: Sample = (0.0, 0.0, 0.0, 0.0, 0.0)
_ONE5: Sample = (1.0, 1.0, 1.0, 1.0, 1.0)

#: Kinds of burst fault (:class:`BurstParams`): none, samples held, samples NaN.
FAULT_NONE, FAULT_HOLD_BURST, FAULT_NAN_BURST = 0, 1, 2
#: Samples the noise is drawn in (the stream depends only on the seed).
_NOISE_BLOCK = 4096
#: Offsets of the sensor model's random streams from the run's seed: dropouts, GNSS, random walks.
_STREAM_DROP, _STREAM_GNSS, _STREAM_WALK = 1, 2, 3


# ------------------------------------------------------------------------------------------- noise
def _sigma(settings: NoiseSettings) -> NDArray[np.float64]:
    s = settings
    return s.scale * np.array([s.position, s.position, s.theta, s.v, s.omega])


def noise_draws(settings: NoiseSettings, seed: int, n: int) -> NDArray[np.float64]:
    """The first ``n`` (at least) samples :class:`SensorNoise` draws, (whole blocks × 5)."""
    sigma = _sigma(settings)
    rng = np.random.default_rng(seed)
    # one draw of the whole blocks: the generator fills in order, so it is SensorNoise's blocks
    return rng.standard_normal((max(-(-n // _NOISE_BLOCK), 1) * _NOISE_BLOCK, 5)) * sigma


class SensorNoise:
    """Zero-mean Gaussian noise of [X, Y, θ, v, ω], seeded (the paper's scenario defaults × scale)."""

    def __init__(self, settings: NoiseSettings, seed: int) -> None:
        self.sigma = _sigma(settings)
        self._rng = np.random.default_rng(seed)
        self._buf = np.empty((0, 5))
        self._i = 0

    def sample(self) -> NDArray[np.float64]:
        """One draw (5,) = noise of [X, Y, θ, v, ω]. Drawn in blocks for speed; the sequence
        depends only on the seed (:func:`noise_draws` draws the same)."""
        if self._i >= self._buf.shape[0]:
            self._buf = self._rng.standard_normal((_NOISE_BLOCK, 5)) * self.sigma
            self._i = 0
        out = self._buf[self._i]
        self._i += 1
        return out


# ------------------------------------------------------------------------------------------ bursts
class BurstParams(NamedTuple):
    """A burst fault of the robustness scenarios: ``duration`` [s] every ``period`` [s] from
    ``start`` [s], the samples held (:data:`FAULT_HOLD_BURST`) or NaN (:data:`FAULT_NAN_BURST`)."""

    kind: int = FAULT_NONE
    period: float = 1.0
    duration: float = 0.0
    start: float = 0.0


class BurstState(NamedTuple):
    """The last sample delivered outside a burst (``has_held``: there is one)."""

    held: Sample = _NAN5
    has_held: bool = False


@jitable
def _in_burst(t: float, start: float, period: float, duration: float) -> bool:
    # A tiny tolerance so that sample instants k·T_d on a burst edge are classified consistently.
    return t >= start - 1e-9 and bool(np.fmod(t - start + 1e-9, period) < duration)


#: What a burst fault does with a sample (:func:`burst_action`): pass it (and keep it as the last
#: sample before a burst), deliver the kept one instead, deliver NaN.
BURST_PASS, BURST_HOLD, BURST_NAN = 0, 1, 2


@jitable
def burst_action(p: BurstParams, t: float, has_held: bool) -> int:
    """What the burst fault ``p`` does at time ``t`` [s]: inside a burst NaN, or the last sample
    before it held (a stalled bus; the sample itself when none was kept yet)."""
    if p.kind == FAULT_NONE:
        return BURST_PASS
    burst = _in_burst(t, p.start, p.period, p.duration)
    if p.kind == FAULT_NAN_BURST:
        return BURST_NAN if burst else BURST_PASS
    return BURST_HOLD if burst and has_held else BURST_PASS


@jitable
def burst_sample(p: BurstParams, s: BurstState, t: float, y: Sample) -> tuple[Sample, BurstState]:
    """(the sample delivered at time ``t``, the new state): :func:`burst_action` on a sample."""
    act = burst_action(p, t, s.has_held)
    if act == BURST_NAN:
        return _NAN5, s
    if act == BURST_HOLD:
        return s.held, s
    if p.kind == FAULT_HOLD_BURST:
        return y, BurstState(y, True)
    return y, s


def _as_sample(y: NDArray[np.float64]) -> Sample:
    return float(y[0]), float(y[1]), float(y[2]), float(y[3]), float(y[4])


@dataclass
class DropoutFault:
    """Measurements frozen at their last value for ``duration_s`` every ``period_s`` (from
    ``start_s``): a stalled sensor bus (:func:`burst_action`). Stateful: one instance per run."""

    period_s: float = 5.0
    duration_s: float = 0.2
    start_s: float = 2.0
    _held: NDArray[np.float64] | None = field(default=None, repr=False)

    @property
    def params(self) -> BurstParams:
        return BurstParams(FAULT_HOLD_BURST, float(self.period_s), float(self.duration_s),
                           float(self.start_s))

    def __call__(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        if burst_action(self.params, float(t), self._held is not None) == BURST_HOLD:
            return self._held.copy()  # type: ignore[union-attr]
        self._held = np.array(y, dtype=float)
        return y


@dataclass(frozen=True)
class NaNBurstFault:
    """All measurements NaN for ``duration_s`` every ``period_s`` (from ``start_s``;
    :func:`burst_action`)."""

    period_s: float = 7.0
    duration_s: float = 0.05
    start_s: float = 3.0

    @property
    def params(self) -> BurstParams:
        return BurstParams(FAULT_NAN_BURST, float(self.period_s), float(self.duration_s),
                           float(self.start_s))

    def __call__(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        if burst_action(self.params, float(t), False) == BURST_NAN:
            return np.full_like(y, np.nan)
        return y


# ------------------------------------------------------------------------------------ sensor model
class SensorParams(NamedTuple):
    """The sensor model of ``[scenario.sensors]`` (:class:`~tsmpc.config.SensorFaults`) as the
    block reads it; every 5-tuple is over [X, Y, θ, v, ω].

    Attributes:
        scale: scale factors [-] (1: none).
        bias: constant offsets [m, m, rad, m/s, rad/s].
        drift: linear offset growth [unit/s].
        walk: σ of one sample's random-walk step [unit] (walk_sigma · √T_d).
        extra_sigma: σ of the extra GNSS noise on X and Y [m].
        p_drop: probability that a sample is lost [-].
        hold: a lost sample repeats the previous one (else NaN).
        delay_n: delay in whole samples.
        heading: the pose sensor delivers the heading θ (else θ is missing).
        rate_pose: the pose's samples per call, rate · T_d (1: every call).
        rate_v: the speed sensor's samples per call, rate · T_d.
        rate_omega: the yaw-rate sensor's samples per call, rate · T_d.
    """

    scale: Sample = _ONE5
    bias: Sample = _ZERO5
    drift: Sample = _ZERO5
    walk: Sample = _ZERO5
    extra_sigma: float = 0.0
    p_drop: float = 0.0
    hold: bool = False
    delay_n: int = 0
    heading: bool = True
    rate_pose: float = 1.0
    rate_v: float = 1.0
    rate_omega: float = 1.0


class SensorState(NamedTuple):
    """State of the sensor model: the delay FIFO (a ring of ``delay_n + 1`` rows, written in
    place; ``head`` the oldest row, ``n`` rows filled), the last sample delivered, the random
    walks and the calls so far."""

    fifo: NDArray[np.float64]
    head: int = 0
    n: int = 0
    last: Sample = _NAN5
    has_last: bool = False
    walk: Sample = _ZERO5
    calls: int = 0


@jitable
def _due(rate: float, calls: int) -> bool:
    """Is a sensor of ``rate`` samples per call due at call ``calls`` (0-based)? At the first call
    at or after each multiple of 1/rate."""
    if rate >= 1.0:
        return True
    return math.floor(calls * rate + 1e-9) > math.floor((calls - 1) * rate + 1e-9)


@jitable
def _channel(y: float, scale: float, bias: float, drift: float, walk: float, t: float) -> float:
    return scale * y + (bias + drift * t + walk)


@jitable
def sensor_sample(p: SensorParams, s: SensorState, t: float, y: Sample, u_drop: float, g_x: float,
                  g_y: float, w: Sample) -> tuple[Sample, SensorState]:
    """(the sample the sensors deliver at time ``t`` [s] for the noisy sample ``y``, the new state)
    — see the module docstring for the order. The random numbers: ``u_drop`` U(0, 1) (read when
    ``p_drop > 0``), ``g_x``, ``g_y`` N(0, 1) of the GNSS noise (when ``extra_sigma > 0``), ``w``
    N(0, 1) of the random-walk steps."""
    sc, b, d, wk = p.scale, p.bias, p.drift, s.walk
    X = _channel(y[0], sc[0], b[0], d[0], wk[0], t)
    Y = _channel(y[1], sc[1], b[1], d[1], wk[1], t)
    th = _channel(y[2], sc[2], b[2], d[2], wk[2], t)
    v = _channel(y[3], sc[3], b[3], d[3], wk[3], t)
    om = _channel(y[4], sc[4], b[4], d[4], wk[4], t)
    pw = p.walk
    walk = (wk[0] + pw[0] * w[0], wk[1] + pw[1] * w[1], wk[2] + pw[2] * w[2], wk[3] + pw[3] * w[3],
            wk[4] + pw[4] * w[4])
    if p.extra_sigma > 0.0:
        X += p.extra_sigma * g_x
        Y += p.extra_sigma * g_y
    if not p.heading:
        th = math.nan
    if not _due(p.rate_pose, s.calls):
        X, Y, th = math.nan, math.nan, math.nan
    if not _due(p.rate_v, s.calls):
        v = math.nan
    if not _due(p.rate_omega, s.calls):
        om = math.nan
    # delay: the FIFO holds delay_n + 1 samples; the oldest is delivered
    fifo = s.fifo
    cap = p.delay_n + 1
    head, n = s.head, s.n
    if n == cap:
        head = (head + 1) % cap
        n -= 1
    r = (head + n) % cap
    fifo[r, 0], fifo[r, 1], fifo[r, 2], fifo[r, 3], fifo[r, 4] = X, Y, th, v, om
    n += 1
    out = (fifo[head, 0], fifo[head, 1], fifo[head, 2], fifo[head, 3], fifo[head, 4])
    if p.p_drop > 0.0 and u_drop < p.p_drop:
        out = s.last if p.hold and s.has_last else _NAN5
    return out, SensorState(fifo, head, n, out, True, walk, s.calls + 1)


def sensor_params(faults: SensorFaults, Td: float, position_sigma: float) -> SensorParams:
    """The block's parameters of ``faults`` at sample period ``Td`` [s]; ``position_sigma`` is the
    configured position noise σ [m] (the GNSS scale multiplies it)."""
    f = faults
    g = f.gnss_noise_scale
    root = math.sqrt(Td)

    def per_call(hz: float | None) -> float:
        return 1.0 if hz is None else min(float(hz) * Td, 1.0)

    return SensorParams(
        scale=(f.position_scale, f.position_scale, 1.0, f.v_scale, f.omega_scale),
        bias=(f.x_bias, f.y_bias, f.theta_bias, f.v_bias, f.omega_bias),
        drift=(0.0, 0.0, f.theta_drift, f.v_drift, f.omega_drift),
        walk=(f.position_walk * root, f.position_walk * root, f.theta_walk * root, f.v_walk * root,
              f.omega_walk * root),
        extra_sigma=position_sigma * math.sqrt(max(g * g - 1.0, 0.0)),
        p_drop=float(f.dropout_probability), hold=bool(f.dropout_hold),
        delay_n=round(f.delay_s / Td), heading=bool(f.pose_heading),
        rate_pose=per_call(f.pose_rate_hz), rate_v=per_call(f.v_rate_hz),
        rate_omega=per_call(f.omega_rate_hz))


def _streams(seed: int) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The sensor model's generators (dropouts, GNSS, random walks) of a run's seed."""
    return tuple(np.random.default_rng([seed, 21, k])  # type: ignore[return-value]
                 for k in (_STREAM_DROP, _STREAM_GNSS, _STREAM_WALK))


def _walks(p: SensorParams) -> bool:
    return any(w != 0.0 for w in p.walk)


class SensorModel:
    """Sensor faults of ``[scenario.sensors]`` on the noisy sample [X, Y, θ, v, ω] (a
    :class:`SensorFault`), after an optional ``inner`` fault: :func:`sensor_sample` with its own
    seeded draws. Restarts when time goes back (the next method of a comparison starts its run at
    t = 0 with the same draws).

    Args:
        faults: the settings.
        Td: sample period of the calls [s] (the delay is rounded to whole samples).
        position_sigma: σ of the configured position noise [m] (the GNSS scale multiplies it).
        seed: the run's seed.
        inner: a fault applied first (e.g. a named robustness scenario's).
    """

    def __init__(self, faults: SensorFaults, Td: float, position_sigma: float, seed: int,
                 inner: SensorFault | None = None) -> None:
        self.faults = faults
        self.Td = float(Td)
        self.params = sensor_params(faults, self.Td, position_sigma)
        self.delay_n = self.params.delay_n
        self.extra_sigma = self.params.extra_sigma
        self.seed = int(seed)
        self.inner = inner
        self._reset()

    def _reset(self) -> None:
        self._drop, self._gnss, self._walk = _streams(self.seed)
        self.state = SensorState(np.zeros((self.delay_n + 1, 5)))
        self._t: float | None = None

    def __call__(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._t is not None and t < self._t - 1e-12:
            self._reset()
        self._t = t
        if self.inner is not None:
            y = self.inner(t, y)
        p = self.params
        g = self._gnss.standard_normal(2) if p.extra_sigma > 0.0 else (0.0, 0.0)
        u = self._drop.random() if p.p_drop > 0.0 else 1.0
        w = _as_sample(self._walk.standard_normal(5)) if _walks(p) else _ZERO5
        out, self.state = sensor_sample(p, self.state, float(t), _as_sample(y), u, float(g[0]),
                                        float(g[1]), w)
        return np.array(out)


def model_draws(model: SensorModel, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The random numbers ``model`` draws in its first ``n`` calls, drawn at once from the same
    streams: (U(0, 1) of the dropouts (n,), N(0, 1) (n, 7): the GNSS noise's X, Y, then the five
    random-walk steps); zeros where the model draws none."""
    p = model.params
    drop, gnss, walk = _streams(model.seed)
    u = drop.random(n) if p.p_drop > 0.0 else np.ones(n)
    g = np.zeros((n, 7))
    if p.extra_sigma > 0.0:
        g[:, 0:2] = gnss.standard_normal((n, 2))
    if _walks(p):
        g[:, 2:7] = walk.standard_normal((n, 5))
    return u, g


def advance_streams(model: SensorModel, n: int) -> None:
    """Restart ``model``'s streams and consume the draws of ``n`` calls (the state an engine run
    of ``n`` samples leaves them in)."""
    p = model.params
    model._drop, model._gnss, model._walk = _streams(model.seed)
    if p.p_drop > 0.0:
        model._drop.random(n)
    if p.extra_sigma > 0.0:
        model._gnss.standard_normal((n, 2))
    if _walks(p):
        model._walk.standard_normal((n, 5))


class SensorFault(Protocol):
    """Corrupts measurements: called every T_d with the time and the noisy measurement
    ``[X, Y, θ, v, ω]``; returns what the sensors deliver (may hold values or return NaN)."""

    def __call__(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]: ...


# ---------------------------------------------------------------------------- the step of a run
class SensorBlockParams(NamedTuple):
    """The sensors of a run as the step reads them: the scenario's burst fault (a named robustness
    scenario's; kind :data:`FAULT_NONE` when there is none), then the sensor model of
    ``[scenario.sensors]`` when ``has_model``."""

    burst: BurstParams = BurstParams()
    has_model: bool = False
    model: SensorParams = SensorParams()


class SensorDraws(NamedTuple):
    """A run's random numbers, drawn before it (:func:`noise_draws`, :func:`model_draws`): the
    noise of sample m ``noise[m]`` (5,); the sensor model's ``u_drop[m]`` and ``draws[m]`` (7,)
    (read only with a model: one row each without one)."""

    noise: NDArray[np.float64]
    u_drop: NDArray[np.float64]
    draws: NDArray[np.float64]


@jitable
def fault_time(m: int, n_in: int, Tc: float, Td: float) -> float:
    """The time [s] a fault is given at sample ``m`` (``n_in`` samples per outer step): an outer
    step's sample at k·T_c (the MPC's clock), the others at m·T_d."""
    k = m // n_in
    return k * Tc if m - k * n_in == 0 else m * Td


@jitable
def sensor_step(p: SensorBlockParams, d: SensorDraws, bs: BurstState, ms: SensorState, m: int, n_in: int,
                Tc: float, Td: float, x: NDArray[np.float64]) -> tuple[Sample, BurstState, SensorState]:
    """The simulator's sensor step, one definition for its Python loop, the run engine and the
    batch: (the sample [X, Y, θ, v, ω] the cascade gets at sample ``m`` of the plant state ``x``
    (6,), the new states). The true [X, Y, θ, v, ω] plus the seeded noise, then the burst fault
    (:func:`burst_sample`), then the sensor model (:func:`sensor_sample`), both at
    :func:`fault_time`."""
    n = d.noise[m]
    s = (x[0] + n[0], x[1] + n[1], x[2] + n[2], x[3] + n[3], x[5] + n[4])
    tf = fault_time(m, n_in, Tc, Td)
    s, bs = burst_sample(p.burst, bs, tf, s)
    if p.has_model:
        g = d.draws[m]
        s, ms = sensor_sample(p.model, ms, tf, s, d.u_drop[m], g[0], g[1], (g[2], g[3], g[4], g[5], g[6]))
    return s, bs, ms


def split_fault(fault: SensorFault | None) -> tuple[SensorModel | None, SensorFault | None]:
    """(sensor model, the fault before it) of a scenario's sensor fault."""
    if type(fault) is SensorModel:
        return fault, fault.inner
    return None, fault


def fault_problem(fault: SensorFault | None) -> str | None:
    """Why ``fault`` has no data form for :func:`sensor_step` (a fault class of the user's, a
    sensor model in the middle of a run); None when it has one (no fault, :class:`DropoutFault`,
    :class:`NaNBurstFault`, a :class:`SensorModel` after one of them or none)."""
    if fault is None:
        return None
    model, inner = split_fault(fault)
    if inner is not None and type(inner) not in (DropoutFault, NaNBurstFault):
        return f"sensor fault {type(inner).__name__} (no data form)"
    if model is not None and model._t is not None and not model._t > 1e-12:
        return "a sensor model in the middle of a run (its first call would not restart it)"
    return None


class SensorRun:
    """The sensors of one run of ``M`` samples (``n_in`` per outer step of ``Tc``, every ``Td``):
    the noise of ``settings`` and ``seed``, then the scenario's ``fault``. A fault with a data form
    (:func:`fault_problem`) runs as :func:`sensor_step` over the records :attr:`params`,
    :attr:`burst`, :attr:`model` and the run's draws :attr:`draws` — the records and draws the run
    engine packs into its slots; any other fault is called as the object it is. The fault objects
    start from where they are (a :class:`DropoutFault`'s last sample; a :class:`SensorModel`
    restarts) and :meth:`finish` leaves them as the run does."""

    def __init__(self, settings: NoiseSettings, seed: int, fault: SensorFault | None, M: int, n_in: int,
                 Tc: float, Td: float) -> None:
        self.fault, self.n_in, self.Tc, self.Td = fault, int(n_in), float(Tc), float(Td)
        self.data = fault_problem(fault) is None
        model, inner = split_fault(fault)
        burst, self.burst = BurstParams(), BurstState()
        if inner is not None and self.data:
            burst = inner.params  # type: ignore[attr-defined]
            held = getattr(inner, "_held", None)
            if held is not None:  # a DropoutFault keeps its last sample from a previous run
                self.burst = BurstState(_as_sample(held), True)
        u_drop, draws, fifo = np.zeros(1), np.zeros((1, 7)), np.zeros((1, 5))
        if model is not None and self.data:
            u_drop, draws = model_draws(model, M)
            fifo = np.zeros((model.delay_n + 1, 5))
        self.params = SensorBlockParams(burst, model is not None, SensorParams() if model is None
                                        else model.params)
        self.draws = SensorDraws(noise_draws(settings, seed, M), u_drop, draws)
        self.model = SensorState(fifo)

    def sample(self, m: int, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The sample [X, Y, θ, v, ω] the cascade gets at sample ``m`` of the plant state ``x``."""
        if self.data:
            out, self.burst, self.model = sensor_step(self.params, self.draws, self.burst, self.model, m,
                                                      self.n_in, self.Tc, self.Td, x)
            return np.array(out)
        y = np.array([x[0], x[1], x[2], x[3], x[5]]) + self.draws.noise[m]
        assert self.fault is not None  # (no fault has a data form)
        return self.fault(fault_time(m, self.n_in, self.Tc, self.Td), y)

    def finish(self, n_calls: int) -> None:
        """Leave the fault objects as ``n_calls`` samples of the run leave them (a comparison runs
        its next method on the same objects)."""
        if not self.data:
            return
        model, inner = split_fault(self.fault)
        if isinstance(inner, DropoutFault):
            inner._held = np.array(self.burst.held) if self.burst.has_held else None
        if model is not None and n_calls > 0:
            advance_streams(model, n_calls)
            model.state = self.model._replace(fifo=self.model.fifo.copy())
            model._t = fault_time(n_calls - 1, self.n_in, self.Tc, self.Td)


# --------------------------------------------------------------- the records as the engine's arrays
#: Length of :func:`pack_params`'s array and of :func:`pack_state`'s.
N_SP = 33
N_SS = 20


def pack_params(burst: BurstParams, model: SensorParams | None) -> NDArray[np.float64]:
    """The records as the flat float array the engine keeps (:func:`unpack_params` reads it)."""
    p = model if model is not None else SensorParams()
    out = np.array([float(burst.kind), burst.period, burst.duration, burst.start,
                    1.0 if model is not None else 0.0, *p.scale, *p.bias, *p.drift, *p.walk,
                    p.extra_sigma, p.p_drop, float(p.hold), float(p.delay_n), float(p.heading),
                    p.rate_pose, p.rate_v, p.rate_omega], dtype=float)
    assert out.shape == (N_SP,)
    return out


@jitable
def _five(a: NDArray[np.float64], i: int) -> Sample:
    return a[i], a[i + 1], a[i + 2], a[i + 3], a[i + 4]


@jitable
def unpack_params(a: NDArray[np.float64]) -> SensorBlockParams:
    """The records of :func:`pack_params`'s array."""
    burst = BurstParams(int(a[0]), a[1], a[2], a[3])
    p = SensorParams(_five(a, 5), _five(a, 10), _five(a, 15), _five(a, 20), a[25], a[26], a[27] != 0.0,
                     int(a[28]), a[29] != 0.0, a[30], a[31], a[32])
    return SensorBlockParams(burst, a[4] != 0.0, p)


def pack_state(burst: BurstState, model: SensorState | None) -> NDArray[np.float64]:
    """The states' scalars as a flat float array (the FIFO stays its own array)."""
    s = model if model is not None else SensorState(np.zeros((1, 5)))
    out = np.array([*burst.held, float(burst.has_held), *s.last, float(s.has_last), *s.walk,
                    float(s.head), float(s.n), float(s.calls)], dtype=float)
    assert out.shape == (N_SS,)
    return out


@jitable
def unpack_state(a: NDArray[np.float64], fifo: NDArray[np.float64]) -> tuple[BurstState, SensorState]:
    """The states of :func:`pack_state`'s array and the FIFO."""
    return (BurstState(_five(a, 0), a[5] != 0.0),
            SensorState(fifo, int(a[17]), int(a[18]), _five(a, 6), a[11] != 0.0, _five(a, 12), int(a[19])))


@jitable
def store_state(a: NDArray[np.float64], burst: BurstState, s: SensorState) -> None:
    """Write the states' scalars back into :func:`pack_state`'s array."""
    a[0], a[1], a[2], a[3], a[4] = burst.held
    a[5] = 1.0 if burst.has_held else 0.0
    a[6], a[7], a[8], a[9], a[10] = s.last
    a[11] = 1.0 if s.has_last else 0.0
    a[12], a[13], a[14], a[15], a[16] = s.walk
    a[17], a[18], a[19] = float(s.head), float(s.n), float(s.calls)
