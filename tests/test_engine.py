"""The compiled run engine (tsmpc.sim.engine, issue 25 item 1) against the Python loop it replaces:
the same RunLog — states to ≤ 1e-8 (in practice bit for bit), identical event counters, statuses
and termination — on the paper reference and the built-in circuit, default config and paper
preset, FZN, REF and ITER; with sensor faults, slow paths, divergence and a block that raises; and
the applicability check that sends everything else to the Python loop."""

from __future__ import annotations

import math
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest

from tsmpc.conditions import EventFriction, ResolvedEvent, apply_conditions
from tsmpc.config import Config, apply_overrides, replace
from tsmpc.planning.reference import Reference
from tsmpc.robustness import apply_robustness
from tsmpc.scenarios import ConstantFriction
from tsmpc.sim import engine as eng
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.experiment import prepare
from tsmpc.sim.log import RunLog
from tsmpc.sim.simulator import Scenario, default_plant, simulate

#: Wall-clock timings differ between the paths; every other array must agree.
_TIMINGS = {"mpc_time_s", "mhe_time_s", "lqr_time_s"}


def _both(cfg: Config, method: str, sc: Scenario, **kw) -> tuple[RunLog, RunLog]:
    """(engine, Python loop) logs of the same run; fails if the engine did not run."""
    eng.LAST_RUN.clear()
    le = simulate(cfg, method, sc, engine=True, **kw)
    assert eng.LAST_RUN, f"the engine did not run: {eng.applicability(cfg, method, sc)}"
    lp = simulate(cfg, method, sc, engine=False, **kw)
    return le, lp


def _assert_same(le: RunLog, lp: RunLog) -> None:
    assert le.termination == lp.termination
    assert le.events == lp.events
    assert le.meta == lp.meta
    assert (le.method, le.scenario, le.Tc, le.Td) == (lp.method, lp.scenario, lp.Tc, lp.Td)
    a, b = le.arrays(), lp.arrays()
    assert a.keys() == b.keys()
    planned = le.n_outer - (1 if le.termination.startswith("diverged") else 0)  # rows the MPC ran
    for name in a.keys() - _TIMINGS:
        x, y = a[name], b[name]
        assert x.shape == y.shape and x.dtype.kind == y.dtype.kind, name
        if name == "mpc_status":
            x, y = x[:planned], y[:planned]
        if x.dtype.kind == "f":
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-8, equal_nan=True, err_msg=name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)
    for name in _TIMINGS:  # measured by the engine too (cycle counter), finite and non-negative
        assert a[name].shape == b[name].shape and np.all(np.isfinite(a[name])) and np.all(a[name] >= 0)


@pytest.fixture(scope="module")
def paper_cfgs() -> dict[str, Config]:
    return {"default": Config(), "paper": Config.preset("paper")}


#: Every method with both presets and on both references, pairwise (6 of the 12 combinations, each
#: run whole): every (method, preset), (method, reference) and (preset, reference) pair is run once.
#: The three inner laws and fusions differ by method; the presets by the MPC path (the paper
#: preset's start-up takes the QP path, asserted below); the references by their shape and length
#: (both under the paper's time-based friction profile, whose events every whole run crosses). The
#: full 12-case matrix cost twice the CPU (~42 s) for no code path these six do not reach.
_MATRIX = [("FZN", "default", "paper"), ("FZN", "paper", "circuit"),
           ("REF", "default", "circuit"), ("REF", "paper", "paper"),
           ("ITER", "default", "paper"), ("ITER", "paper", "circuit")]


@pytest.mark.parametrize(("method", "preset", "where"), _MATRIX)
def test_engine_equals_the_python_loop(preset: str, where: str, method: str, paper_cfgs,
                                       paper_reference_path: Path) -> None:
    cfg = paper_cfgs[preset]
    sc = load_scenario(cfg, paper_reference_path if where == "paper" else None)
    assert eng.applicability(cfg, method, sc) is None
    le, lp = _both(cfg, method, sc)
    assert le.termination == "completed"
    _assert_same(le, lp)
    if preset == "paper":  # the paper preset's start-up needs the MPC's QP path: resumed, equal
        assert eng.LAST_RUN["slow_paths"]["mpc"] > 0 and le.events["mpc_fallback"] == 0


def test_sensor_dropouts_bursts_biases_and_delay(cfg: Config, paper_reference_path: Path) -> None:
    """The sensor faults as data: SensorModel dropouts (NaN, then held samples), biases, drifts,
    extra GNSS noise and delay on top of a stalled-bus fault (DropoutFault), and NaN bursts. The
    fault objects are left as the Python loop leaves them (it runs second on the same objects)."""
    base = load_scenario(cfg, paper_reference_path)
    sensors = {"dropout_probability": 0.05, "v_bias": 0.1, "omega_bias": -0.01, "omega_drift": 1e-4,
               "theta_bias": 0.005, "delay_s": 0.02, "gnss_noise_scale": 3.0}
    c0, s0 = apply_robustness("sensor_dropout", cfg, base)
    for hold in (False, True):
        c = replace(c0, scenario=replace(c0.scenario, sensors=replace(
            c0.scenario.sensors, **sensors, dropout_hold=hold)))
        c2, s2 = apply_conditions(c, s0)
        le, lp = _both(c2, "REF", s2, max_steps=400)
        _assert_same(le, lp)
        n_lost = int(np.sum(np.isnan(lp.measurement[:, 0])))
        assert (n_lost == 0) if hold else (n_lost > 100), n_lost
        assert le.events["mhe_rejected" if not hold else "repeated_rejected"] > 50
    c, s = apply_robustness("nan_bursts", cfg, base)
    _assert_same(*_both(c, "ITER", s, max_steps=300))


def test_slow_paths_friction_events_and_mismatch(cfg: Config, paper_reference_path: Path) -> None:
    """The offset start needs the MPC's QP path and the MHE's dense QP (a state bound active):
    resumed in the kernel, equal; so are friction events over the paper profile and a plant
    with other mass and tyres (the stiffness and mass fits at work). The offset start's slow
    paths are all in its first 100 steps (measured: 11 MPC QPs and 133 MHE dense QPs, the whole
    run's), so it runs 150, not the whole reference (the matrix above runs whole references)."""
    base = load_scenario(cfg, paper_reference_path)
    c, s = apply_robustness("offset_start", cfg, base)
    le, lp = _both(c, "REF", s, max_steps=150)
    _assert_same(le, lp)
    slow = eng.LAST_RUN["slow_paths"]
    assert slow["mpc"] >= 10 and slow["mhe"] >= 100, slow
    c = replace(cfg, scenario=replace(cfg.scenario, plant=replace(
        cfg.scenario.plant, mass_scale=1.15, cornering_front_scale=0.85), friction=(
        {"at_s": 20.0, "mu": 0.4, "ramp_s": 1.0, "duration_s": 5.0},
        {"at_m": 150.0, "mu": 0.6, "ramp_m": 5.0, "length_m": 40.0})))
    c2, s2 = apply_conditions(c, base)
    _assert_same(*_both(c2, "FZN", s2, max_steps=600))


def test_actuators(cfg: Config, paper_reference_path: Path) -> None:
    """A steering servo (lag, rate limit) and a force lag in front of the plant, the applied
    steering measured and given to the MHE: the actuators as data, equal."""
    c, s = apply_robustness("actuator_lag", cfg, load_scenario(cfg, paper_reference_path))
    assert s.measured_steering and s.actuators is not None
    _assert_same(*_both(c, "REF", s, max_steps=500))


@pytest.mark.parametrize("servo", [False, True])
def test_a_steering_offset_is_fitted_alike(servo: bool, cfg: Config, paper_reference_path: Path) -> None:
    """fusion.steering_offset at work: the wheels stand 1° off the servo's angle; the fit moves and
    its correction reaches the servo and the MHE alike (with a servo whose measured angle the MHE
    gets, the offset in force added to it). That it acts: the same engine run without the fit
    tracks three times worse."""
    sets = ["scenario.plant.steering_offset_rad=0.017453"]
    if servo:
        sets += ["scenario.actuators.steering_time_constant_s=0.05",
                 "scenario.actuators.measured_steering=true"]
    c, s = apply_conditions(apply_overrides(cfg, sets), load_scenario(cfg, paper_reference_path))
    assert c.fusion.steering_offset and (s.measured_steering == servo)
    le, lp = _both(c, "REF", s, max_steps=250)
    _assert_same(le, lp)
    off = replace(c, fusion=replace(c.fusion, steering_offset=False))
    eng.LAST_RUN.clear()
    lo = simulate(off, "REF", s, engine=True, max_steps=250)
    assert eng.LAST_RUN

    def rms(log: RunLog) -> float:
        return float(np.sqrt(np.mean(log.errors[:, 1] ** 2)))

    # measured RMS e_y over these 25 s: 0.0121 m with the fit, 0.0386 m without (both servos)
    assert rms(le) < 0.5 * rms(lo), (rms(le), rms(lo))


def test_a_closed_lap_wraps_alike(cfg: Config) -> None:
    """Two laps of a closed circle: the MPC's look-ahead wraps into the next lap at every lap's
    end (Reference.window), in the engine as in the Python loop."""
    n, v, dt = 300, 10.0, cfg.rates.Tc
    R = n * v * dt / (2.0 * np.pi)
    phi = np.arange(n) * v * dt / R
    lap = Reference(np.arange(n) * dt, R * np.sin(phi), R * (1.0 - np.cos(phi)), phi,
                    np.full(n, v), np.full(n, v / R), np.full(n, 1.0 / R), closed=True)
    sc = Scenario("circle", lap.repeat(2), ConstantFriction(0.8))
    le, lp = _both(cfg, "REF", sc)
    assert le.n_outer == 2 * n
    _assert_same(le, lp)


def test_a_diverging_run_ends_alike(cfg: Config, paper_reference_path: Path) -> None:
    """A heavier car with weaker rear tyres and combined slip leaves the road: the same |e_y|,
    time and logs up to that step. (Without the speed governor: with it, on by default, the start's
    spin slows the reference and the car completes the run.)"""
    c = replace(cfg, scenario=replace(cfg.scenario, plant=replace(
        cfg.scenario.plant, mass_scale=1.2, cornering_rear_scale=0.7, combined_slip=True)),
        governor=replace(cfg.governor, enabled=False))
    c2, s2 = apply_conditions(c, load_scenario(cfg, paper_reference_path))
    le, lp = _both(c2, "REF", s2)
    assert lp.termination.startswith("diverged: |e_y|") and lp.n_outer < 200
    _assert_same(le, lp)


def test_a_non_finite_plant_step_ends_alike(cfg: Config) -> None:
    """μ(road) turning NaN at 2 s: the plant refuses the step; the engine hands it to the plant's
    Python step, which words the same error."""
    sc = load_scenario(cfg)
    nan_road = ResolvedEvent(True, 2.0, 0.0, math.inf, math.nan)
    sc = dc_replace(sc, friction=EventFriction(ConstantFriction(0.9), (nan_road,)))
    le, lp = _both(cfg, "REF", sc, max_steps=100)
    assert lp.termination.startswith("plant diverged at t = 2.00 s: plant: non-finite input")
    assert eng.LAST_RUN["slow_paths"]["plant"] == 1
    _assert_same(le, lp)


#: Paper reference, μ 0.9 → 0.5 at 30 s, the combined-slip tyre whose grip follows the road (the
#: config's tyre: plant and governor agree): the speed governor's acceptance case (issue 36). It
#: acts there: the start's spin, the drop.
_MU_DROP = ["scenario.plant.combined_slip=true", "tyre.scale_grip_with_road=true",
            "scenario.base_mu=0.9", "scenario.friction=[{at_s = 30.0, mu = 0.5}]", "governor.enabled=true"]


@pytest.mark.parametrize(("source", "car", "steps"), [("estimate", [], None), ("oracle", [], 600), (
    "estimate", ["scenario.plant.mass_scale=1.15", "scenario.plant.cornering_front_scale=0.75",
                 "scenario.plant.cornering_rear_scale=0.85"], 600)])
def test_the_speed_governor_runs_alike(source: str, car: list[str], steps: int | None,
                                       paper_reference_path: Path) -> None:
    """The speed governor in the engine (its block functions compiled in: governor_inputs,
    governor_update, the governed window's interpolation): the grip from the inner
    loop's estimate (nominal and mismatched car) or the scenario's μ(t) (the oracle row, the
    engine's friction program); a governed run — the reference sampled at the governed time,
    the errors logged against it, the MPC's window re-timed — equal to the Python loop's bit for
    bit, counters and meta included. The nominal estimate row runs whole (the governed run's end
    on the reference's last samples, every governor action); the other two the first 60 s: the
    start's spin and the drop at 30 s, at least 2 governor actions each (the later ones take the
    same path)."""
    cfg = apply_overrides(Config(), [*_MU_DROP, *car, f'governor.grip_source="{source}"'])
    exp = prepare(cfg, ["ref"], reference=paper_reference_path)
    assert eng.applicability(exp.config, "REF", exp.scenario) is None
    le, lp = _both(exp.config, "REF", exp.scenario, max_steps=steps or exp.max_steps)
    assert lp.termination == "completed"
    assert lp.events["governor_actions"] >= 2 and lp.events["governor_steps"] > 70, lp.events
    _assert_same(le, lp)
    for name in ("state", "ref", "errors", "errors_measured", "command"):  # bit for bit
        np.testing.assert_array_equal(getattr(le, name), getattr(lp, name), err_msg=name)
    assert np.any(lp.ref[:, 3] < np.asarray(lp.meta["planned_v"]) - 1e-6)  # it was governed


def test_the_oracle_governor_reads_the_road_of_its_step(cfg: Config) -> None:
    """The oracle row reads μ(t) of the MPC step's own time from the engine's friction program:
    a drop 5 ms after an MPC step (built-in circuit, 0.9 → 0.3 at 1.005 s, the governor still at
    rate 1) is seen one MPC step later, in the engine as in the Python loop."""
    c = apply_overrides(cfg, [*_MU_DROP, "scenario.friction=[{at_s = 1.005, mu = 0.3}]",
                              'governor.grip_source="oracle"'])
    exp = prepare(c, ["ref"], duration=4.0)
    le, lp = _both(exp.config, "REF", exp.scenario, max_steps=exp.max_steps)
    slowed = np.flatnonzero(lp.ref[:, 3] < np.asarray(lp.meta["planned_v"]) - 1e-9)
    assert lp.t_outer[slowed[0]] == pytest.approx(1.2, abs=1e-9)
    _assert_same(le, lp)


@pytest.mark.parametrize("deadband", [0.05, 0.5])
def test_governed_windows_on_the_qp_path_run_alike(paper_reference_path: Path, monkeypatch,
                                                   deadband: float) -> None:
    """The paper preset with the governor on (the drop road): the launch governs the reference (its
    force budget, the start's spin) and reaches the MPC's QP path (the caller's slow path) with
    governed windows; the run completes. With a wide deadband the governor acts later, the car leaves
    the road, and the MHE's dense QP runs too, beside governed windows. Equal, to the same step."""
    windows: list[int] = []
    mpc = eng._Run._mpc

    def recorded(self) -> None:
        windows.append(int(self.a.si[self.ke.SI_GWIN]))
        mpc(self)

    monkeypatch.setattr(eng._Run, "_mpc", recorded)
    c = apply_overrides(Config.preset("paper"), [*_MU_DROP, f"governor.deadband={deadband}"])
    exp = prepare(c, ["ref"], reference=paper_reference_path, duration=12.0)
    le, lp = _both(exp.config, "REF", exp.scenario, max_steps=exp.max_steps)
    assert lp.events["governor_actions"] >= 1
    if deadband < 0.1:
        assert sum(windows) > 10 and lp.termination == "completed", windows
    else:
        assert sum(windows) > 0 and eng.LAST_RUN["slow_paths"]["mhe"] > 0, windows
        assert lp.termination.startswith("diverged")
    _assert_same(le, lp)
    np.testing.assert_array_equal(le.state, lp.state)


def test_a_block_that_raises_runs_in_python(paper_reference_path: Path, monkeypatch) -> None:
    """The cascade catches an exception escaping the MPC (step_errors, shifted plan); the engine
    does not reproduce that catch: it gives up and simulate() runs the Python loop, so the
    result is the Python loop's."""
    import tsmpc.control.ts_mpc as ts_mpc

    def broken(*args, **kwargs):
        raise RuntimeError("solver crashed")

    monkeypatch.setattr(ts_mpc, "solve_daqp", broken)
    pcfg = Config.preset("paper")  # its start-up reaches the QP path (from 2.6 s)
    sc = load_scenario(pcfg, paper_reference_path)
    eng.LAST_RUN.clear()
    le = simulate(pcfg, "REF", sc, engine=True, max_steps=60)
    assert not eng.LAST_RUN  # the engine gave up
    lp = simulate(pcfg, "REF", sc, engine=False, max_steps=60)
    assert lp.events["step_errors"] > 0
    _assert_same(le, lp)


def test_a_run_that_blinds_the_cascade_runs_in_python(cfg: Config, monkeypatch) -> None:
    """The recovery's blind stop and restart are the Python loop's: the kernel runs the cascade's
    time phases (control/_clock.py) and returns when the blind stop begins, and simulate() runs
    the Python loop. Here applicability()'s guard against blinding faults is switched off, so a
    NaN burst longer than recovery.blind_after_s reaches the kernel (without the kernel's check it
    ran on with the TS-LQR instead of the blind stop: 0 blind steps)."""
    from tsmpc.sensors import NaNBurstFault

    sc = dc_replace(load_scenario(cfg), sensor_fault=NaNBurstFault(period_s=9.0, duration_s=1.2, start_s=4.0))
    assert "blind" in (eng.applicability(cfg, "REF", sc) or "")
    monkeypatch.setattr(eng, "_blinding_fault", lambda *a: None)
    assert eng.applicability(cfg, "REF", sc) is None
    eng.LAST_RUN.clear()
    le = simulate(cfg, "REF", sc, engine=True, max_steps=100)
    assert not eng.LAST_RUN  # the engine gave up
    lp = simulate(cfg, "REF", sc, engine=False, max_steps=100)
    assert lp.events["blind_steps"] > 0 and lp.events["recoveries"] >= 1
    _assert_same(le, lp)


def test_the_engine_starts_only_from_a_reset_it_can_read(cfg: Config) -> None:
    """The kernel takes its start state from the reset cascade and its blocks' arrays (no reset of
    its own); what it cannot hold it refuses: a cascade without x0 (started by its first
    measurement), a last command or plan before the first call."""
    from tsmpc.control.cascade import Cascade, Measurement
    from tsmpc.sim.start import _start_state

    sc = load_scenario(cfg)
    x0 = _start_state(sc.reference, sc.initial_error)
    cas = Cascade(cfg, "REF", sc.reference)
    assert "first measurement" in (eng._start_problem(cas) or "")
    cas.reset(x0)
    assert eng._start_problem(cas) is None
    cas.step(0.0, Measurement((x0[0], x0[1], x0[2]), x0[3], x0[5]))
    assert "last command" in (eng._start_problem(cas) or "")
    cas.reset(x0)
    assert eng._start_problem(cas) is None
    cas.mpc._prev = object()  # (a plan the MPC kept over its reset)
    assert "plan" in (eng._start_problem(cas) or "")


def test_progress_is_reported_for_every_outer_step(cfg: Config) -> None:
    sc = load_scenario(cfg)
    seen: dict[bool, list[tuple[int, int]]] = {True: [], False: []}
    for engine in (True, False):
        simulate(cfg, "REF", sc, engine=engine, max_steps=123,
                 progress=lambda k, K, e=engine: seen[e].append((k, K)))
    assert seen[True] == seen[False] == [(k, 123) for k in range(1, 124)]


def test_what_the_engine_does_not_run_goes_to_python(cfg: Config, monkeypatch) -> None:
    sc = load_scenario(cfg)
    assert eng.applicability(cfg, "REF", sc) is None
    reasons = {
        "NL": eng.applicability(cfg, "NL", sc),
        "pure pursuit": eng.applicability(cfg, "pure_pursuit", sc),
        "plant": eng.applicability(cfg, "REF", sc, plant=default_plant(cfg, sc)),
        "oracle": eng.applicability(cfg, "REF", sc, oracle=True),
        "paper-as-run": eng.applicability(Config.preset("paper-as-run"), "REF", sc),
        "uio": eng.applicability(replace(cfg, mhe=replace(cfg.mhe, form="uio")), "REF", sc),
        "friction": eng.applicability(cfg, "REF", dc_replace(sc, friction=_OwnFriction())),
        "fault": eng.applicability(cfg, "REF", dc_replace(sc, sensor_fault=lambda t, y: y)),
    }
    for what, why in reasons.items():
        assert isinstance(why, str) and why, what
    assert "NL" in reasons["NL"] and "oracle" in reasons["oracle"]
    # instrumentation (a test's recorder) replaces a method: only the Python loop runs it
    from tsmpc.control.ts_lqr import TSLQR

    step = TSLQR.step
    monkeypatch.setattr(TSLQR, "step", lambda self, *a, **k: step(self, *a, **k))
    assert "TSLQR.step was replaced" in eng.applicability(cfg, "REF", sc)
    monkeypatch.undo()
    # the switches: engine=False and TSMPC_ENGINE=0
    eng.LAST_RUN.clear()
    simulate(cfg, "REF", sc, engine=False, max_steps=3)
    assert not eng.LAST_RUN
    monkeypatch.setenv("TSMPC_ENGINE", "0")
    simulate(cfg, "REF", sc, max_steps=3)
    assert not eng.LAST_RUN
    monkeypatch.setenv("TSMPC_ENGINE", "1")
    simulate(cfg, "REF", sc, max_steps=3)
    assert eng.LAST_RUN["loop_s"] > 0


class _OwnFriction:
    """A user's friction profile (a class the engine has no data form for)."""

    def mu(self, t: float, s: float = 0.0) -> float:
        return 0.9


def test_the_engine_reproduces_the_current_python_code() -> None:
    """The Python code the kernel ports is the code it was ported from. If this fails, the loop,
    the cascade's glue, a fusion, an estimator wrapper or a scenario class changed: port the
    change to src/tsmpc/kernels/engine.py (the equality tests above must pass), then refresh the
    table _PORTED in src/tsmpc/sim/engine.py with ``python -m tsmpc.sim.engine``. Until then
    simulate() runs the Python loop (correct, slower)."""
    stale = eng.stale_ports()
    assert not stale, f"changed since the engine's port: {stale}"
