"""Multi-rate closed-loop simulation of the cascade (the paper's cascade; the paper's scenario).

A thin loop: every T_d the simulator reads the plant's state, adds sensor noise and faults, calls
the :class:`~tsmpc.control.cascade.Cascade` (outer MPC every T_c/T_d calls, MHE-UIO + TS-LQR
every call) and applies its command to the plant (any :class:`~tsmpc.sim.plant.Plant`; tsmpc's
own integrates RK4 steps of h). Time is an integer step counter (no accumulated floating-point
time, so nothing drifts). The blocks only compute; this module logs everything into a
:class:`~tsmpc.sim.log.RunLog`.

A run is reproducible from ``cfg.seed``: the sensor noise is the only random draw.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config
from tsmpc.control.cascade import (
    _MPC_STATUS_CODE,
    STATUS_CODE,
    Cascade,
    Command,
    Measurement,
    Method,
    build_outer_controller,
)
from tsmpc.errors import ConfigError, NonFiniteError
from tsmpc.scenarios import Scenario, SensorFault
from tsmpc.sensors import SensorRun
from tsmpc.sim.log import RunLog
from tsmpc.sim.plant import Plant
from tsmpc.sim.record_block import (
    LI_TLQR,
    LI_TMHE,
    LO_TMPC,
    logged_reference,
    new_records,
    off_road,
    record_inner,
    record_outer,
    record_plan,
    run_log,
    travelled,
)
from tsmpc.sim.start import _start_state, default_plant, tracked_steps

__all__ = ["Method", "Scenario", "SensorFault", "build_outer_controller", "default_plant", "simulate",
           "tracked_steps"]

ProgressFn = Callable[[int, int], None]


class _Recorder:
    """The run's log: the recorder block's records (:mod:`tsmpc.sim.record_block`, the engine's
    too), written by its functions from the cascade's objects."""

    def __init__(self, K: int, n_in: int, N: int) -> None:
        self.r = new_records(K, n_in, N)

    def outer(self, k: int, t: float, x: NDArray[np.float64], c: Cascade) -> float:
        """Log the true state at outer step k against the reference the cascade tracks (the
        outer block's records); returns the true lateral error e_y."""
        row = logged_reference(c._ob_p, c._ref_rec, c._ob, c._oc, k, t, c._ob_buf)
        return float(record_outer(self.r.lo, k, x, row))

    def plan(self, k: int, cmd: Command) -> None:
        res = cmd.plan
        assert res is not None and cmd.errors_measured is not None
        record_plan(self.r.lo, self.r.loi, self.r.lxp, k, cmd.errors_measured, res.u[0], res.u[1],
                    np.asarray(res.x_pred), _MPC_STATUS_CODE[res.status], res.iterations, res.qp_iterations,
                    res.n_clipped)
        self.r.lo[k, LO_TMPC] = cmd.mpc_time_s

    def inner(self, m: int, x: NDArray[np.float64], y: NDArray[np.float64], cmd: Command,
              mu: float, f_true: float | None) -> None:
        e = cmd.estimate
        record_inner(self.r.li, self.r.lstat, self.r.lsat, m, x, e.x, y[3], y[4], e.F_fr, e.F_fr_raw,
                     math.nan if f_true is None else f_true, mu, cmd.F_xR, cmd.delta, STATUS_CODE[e.status],
                     cmd.saturated)
        self.r.li[m, LI_TMHE], self.r.li[m, LI_TLQR] = cmd.mhe_time_s, cmd.lqr_time_s


def _measurement(y: NDArray[np.float64], x: NDArray[np.float64], plant: Plant, oracle: bool,
                 sc: Scenario) -> Measurement:
    """The sensor sample the cascade gets: noisy [X, Y, θ, v, ω], plus the applied steering /
    force where the platform measures them, plus the true [v, α, ω] in the oracle ablation."""
    u = plant.applied_input if (sc.measured_steering or sc.measured_force) else None
    return Measurement.from_array(y, state=x[3:6].copy() if oracle else None,
                                  force=float(u[0]) if u is not None and sc.measured_force else None,
                                  steering=float(u[1]) if u is not None and sc.measured_steering
                                  else None)


def simulate(
    cfg: Config, method: Method | str, scenario: Scenario, *, oracle: bool = False,
    plant: Plant | None = None, kinematic_design: Any = None, dynamic_design: Any = None,
    progress: ProgressFn | None = None, max_steps: int | None = None, engine: bool | None = None,
) -> RunLog:
    """Run ``method`` on ``scenario``: ``plant`` (any :class:`~tsmpc.sim.plant.Plant`; None:
    :func:`default_plant`) ↔ :class:`~tsmpc.control.cascade.Cascade` every T_d, all logged.
    ``oracle`` (or ``cfg.lqr.oracle``): the TS-LQR gets the true [v, α, ω] and no friction
    compensation (the MHE still runs). Designs: the cache's when None; ``progress(k, K)`` after
    each outer step; ``max_steps`` shortens the run. A non-finite plant state or |e_y| beyond
    ``scenario.divergence_bound_m`` (the track's half-width; None: the config's) ends the run
    (``termination`` says why); closed laps run to their end (:func:`tracked_steps`); block
    failures are counted in ``events``, never raised. One BLAS thread unless
    ``TSMPC_BLAS_THREADS`` says otherwise (:mod:`tsmpc.blas`). ``engine``: run the whole run in
    the compiled engine where it applies (:mod:`tsmpc.sim.engine`; None = unless
    ``TSMPC_ENGINE=0``), False = this Python loop."""
    from tsmpc.blas import limit_blas_threads

    limit_blas_threads()
    import tsmpc.sim.engine as eng  # (imports this module: not at the top)

    if (eng.enabled() if engine is None else engine) and eng.applicability(
            cfg, method, scenario, oracle=oracle, plant=plant) is None:
        try:
            log = eng.run(cfg, method, scenario, kinematic_design=kinematic_design,
                          dynamic_design=dynamic_design, progress=progress, max_steps=max_steps)
        except eng.EngineFallback:  # a block raised: the Python loop reproduces the cascade's catch
            log = None
        if log is not None:
            return log
    oracle = oracle or cfg.lqr.oracle
    true_state = cfg.lqr.true_state_feedback  # the published run's quirk
    cascade = Cascade(cfg, method, scenario.reference, kinematic_design=kinematic_design,
                      dynamic_design=dynamic_design)
    ref, N, Tc, Td, n_in = cascade.reference, cfg.mpc.N, cfg.rates.Tc, cfg.rates.Td, cascade.n_inner
    K = tracked_steps(ref, N)
    if K < 1:
        raise ConfigError(f"reference has {len(ref)} samples: needs more than N = {N} for look-ahead")
    K = K if max_steps is None else min(K, int(max_steps))
    plant = plant if plant is not None else default_plant(cfg, scenario)
    x = _start_state(ref, scenario.initial_error)
    plant.reset(x)
    cascade.reset(x)
    rec = _Recorder(K, n_in, N)
    sensors = SensorRun(cfg.noise, cfg.seed, scenario.sensor_fault, K * n_in, n_in, Tc, Td)
    bound = scenario.divergence_bound_m or cfg.divergence_bound_m or math.inf  # off the road: diverged
    termination, done, rows, n_calls, s_travel, t_start = "completed", K, 0, 0, 0.0, time.perf_counter()
    for m in range(K * n_in):
        k, j = divmod(m, n_in)
        t = m * Td
        y = sensors.sample(m, x)  # (tsmpc.sensors.sensor_step: noise, the fault, the sensor model)
        n_calls = m + 1
        if cascade.governor is not None:  # the oracle's μ (governor.py)
            cascade.road_mu = float(scenario.friction.mu(t, s_travel))
        e_y = rec.outer(k, t, x, cascade) if j == 0 else 0.0
        if off_road(e_y, bound):
            termination = f"diverged: |e_y| = {abs(e_y):.2f} m > {bound:g} m at t = {k * Tc:.1f} s"
            done = k + 1
            break
        cmd = cascade.step(t, _measurement(y, x, plant, oracle or true_state, scenario))
        if cmd.plan is not None:
            rec.plan(k, cmd)
        mu = float(scenario.friction.mu(t, s_travel))
        try:
            x_next = plant.step(cmd.u, Td, mu)
            if not np.all(np.isfinite(x_next)):
                raise NonFiniteError(f"plant: non-finite state {x_next}")
        except NonFiniteError as err:
            termination, done, x_next = f"plant diverged at t = {k * Tc:.2f} s: {err}", k + 1, None
        rec.inner(m, x, y, cmd, mu, plant.friction_force)
        rows = m + 1
        if x_next is None:
            break
        x = x_next
        s_travel = travelled(s_travel, x[3], Td)
        if progress is not None and j == n_in - 1:
            progress(k + 1, K)
    sensors.finish(n_calls)
    return run_log(rec.r, method=cascade.method.value, scenario=scenario.name, Tc=Tc, Td=Td,
                   t0=float(ref.t[0]), done=done, rows=rows, wall_s=time.perf_counter() - t_start,
                   termination=termination, events=cascade.events,
                   meta={"oracle": oracle, "seed": cfg.seed, **scenario.meta, "final_state": x.tolist(),
                         **({} if cascade.governor is None else {"planned_v": ref.v[:done].tolist(),
                                                                 "plan_delay_s": cascade.plan_delay})})
