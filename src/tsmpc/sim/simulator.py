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

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config
from tsmpc.control.cascade import Cascade, Command, Measurement, Method, build_outer_controller
from tsmpc.control.outer_block import pose_errors
from tsmpc.errors import ConfigError, NonFiniteError
from tsmpc.planning.reference import Reference
from tsmpc.scenarios import Scenario, SensorFault
from tsmpc.sensors import SensorRun
from tsmpc.sim.log import RunLog
from tsmpc.sim.plant import Plant
from tsmpc.sim.start import _start_state, default_plant, tracked_steps

__all__ = ["Method", "Scenario", "SensorFault", "build_outer_controller", "default_plant", "simulate",
           "tracked_steps"]

ProgressFn = Callable[[int, int], None]


class _Recorder:
    """Preallocated log arrays of a run (K outer rows, K·T_c/T_d inner rows) → :class:`RunLog`."""

    def __init__(self, ref: Reference, K: int, n_in: int, N: int, Tc: float, Td: float) -> None:
        M = K * n_in
        t0 = float(ref.t[0])
        self.t_outer = np.arange(K) * Tc + t0
        self.t_inner = np.arange(M) * Td + t0
        self.refs = np.stack([ref.x[:K], ref.y[:K], ref.theta[:K], ref.v[:K], ref.omega[:K]], axis=1)
        self.N = N
        z = np.zeros
        self.state_outer, self.errors, self.errors_meas = z((K, 6)), z((K, 3)), z((K, 3))
        self.u_c, self.x_pred, self.mpc_time = z((K, 2)), z((K, N + 1, 3)), z(K)
        self.mpc_status = np.empty(K, dtype="<U16")
        self.mpc_it, self.mpc_qpit, self.mpc_clip = (z(K, dtype=np.int64) for _ in range(3))
        self.state, self.est, self.meas = z((M, 6)), z((M, 3)), z((M, 2))
        self.f_hat, self.f_raw, self.f_true, self.mu, self.mhe_time, self.lqr_time = z((6, M))
        self.cmd, self.sat = z((M, 2)), z(M, dtype=bool)
        self.mhe_status = np.empty(M, dtype="<U16")

    def outer(self, k: int, x: NDArray[np.float64]) -> float:
        """Log the true state at outer step k; returns the true lateral error e_y."""
        r = self.refs[k]
        self.state_outer[k] = x
        pose_errors(x[0], x[1], x[2], r[0], r[1], r[2], self.errors[k])  # (the outer block's, one definition)
        return float(self.errors[k, 1])

    def plan(self, k: int, cmd: Command) -> None:
        res = cmd.plan
        assert res is not None and cmd.errors_measured is not None
        self.errors_meas[k], self.mpc_time[k] = cmd.errors_measured, cmd.mpc_time_s
        self.u_c[k] = res.u
        xp = np.asarray(res.x_pred)
        self.x_pred[k, : xp.shape[0]] = xp[: self.N + 1]
        self.mpc_status[k] = str(res.status)
        self.mpc_it[k], self.mpc_qpit[k], self.mpc_clip[k] = (res.iterations, res.qp_iterations,
                                                              res.n_clipped)

    def inner(self, m: int, x: NDArray[np.float64], y: NDArray[np.float64], cmd: Command,
              mu: float, f_true: float | None) -> None:
        e = cmd.estimate
        self.state[m], self.est[m], self.meas[m] = x, e.x, y
        self.f_hat[m], self.f_raw[m] = e.F_fr, e.F_fr_raw
        self.f_true[m] = np.nan if f_true is None else f_true
        self.mu[m], self.cmd[m], self.sat[m] = mu, (cmd.F_xR, cmd.delta), cmd.saturated
        self.mhe_time[m], self.lqr_time[m], self.mhe_status[m] = (cmd.mhe_time_s, cmd.lqr_time_s,
                                                                  str(cmd.estimate.status))

    def log(self, method: str, scenario: str, Tc: float, Td: float, done: int, m: int, **facts: Any
            ) -> RunLog:
        o, i = slice(0, done), slice(0, m)
        return RunLog(
            method=method, scenario=scenario, Tc=Tc, Td=Td,
            # (float64 in fact: numpy's stubs type int array × float as floating[Any]; this class's
            # syntax tree is fingerprinted for the run engine, tsmpc.sim.engine._PORTED)
            t_outer=self.t_outer[o], ref=self.refs[o], state_outer=self.state_outer[o],  # type: ignore[arg-type]
            errors=self.errors[o], errors_measured=self.errors_meas[o], u_c=self.u_c[o],
            x_pred=self.x_pred[o], mpc_time_s=self.mpc_time[o], mpc_status=self.mpc_status[o],
            mpc_iterations=self.mpc_it[o], mpc_qp_iterations=self.mpc_qpit[o],
            mpc_clipped=self.mpc_clip[o],
            t_inner=self.t_inner[i], state=self.state[i], estimate=self.est[i],  # type: ignore[arg-type]
            measurement=self.meas[i], F_fr_hat=self.f_hat[i], F_fr_raw=self.f_raw[i],
            F_fr_true=self.f_true[i], mu_road=self.mu[i], command=self.cmd[i],
            saturated=self.sat[i], mhe_time_s=self.mhe_time[i], lqr_time_s=self.lqr_time[i],
            mhe_status=self.mhe_status[i], **facts)


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
    rec = _Recorder(ref, K, n_in, N, Tc, Td)
    sensors = SensorRun(cfg.noise, cfg.seed, scenario.sensor_fault, K * n_in, n_in, Tc, Td)
    bound = scenario.divergence_bound_m or cfg.divergence_bound_m  # off the road: diverged
    termination, done, rows, n_calls, s_travel, t_start = "completed", K, 0, 0, 0.0, time.perf_counter()
    for m in range(K * n_in):
        k, j = divmod(m, n_in)
        t = m * Td
        y = sensors.sample(m, x)  # (tsmpc.sensors.sensor_step: noise, the fault, the sensor model)
        n_calls = m + 1
        if cascade.governor is not None:  # the governed reference and the oracle's μ (governor.py)
            cascade.road_mu = float(scenario.friction.mu(t, s_travel))
            if j == 0 and cascade.governed:
                rec.refs[k] = cascade.reference_row(t)
        e_y = rec.outer(k, x) if j == 0 else 0.0
        if bound is not None and abs(e_y) > bound:
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
        rec.inner(m, x, y[3:5], cmd, mu, plant.friction_force)
        rows = m + 1
        if x_next is None:
            break
        x = x_next
        s_travel += max(x[3], 0.0) * Td
        if progress is not None and j == n_in - 1:
            progress(k + 1, K)
    sensors.finish(n_calls)
    return rec.log(cascade.method.value, scenario.name, Tc, Td, done, rows,
                   wall_s=time.perf_counter() - t_start, termination=termination, events=cascade.events,
                   meta={"oracle": oracle, "seed": cfg.seed, **scenario.meta,
                         "final_state": x.tolist(),
                         **({} if cascade.governor is None else {"planned_v": ref.v[:done].tolist(),
                                                                 "plan_delay_s": cascade.plan_delay})})
