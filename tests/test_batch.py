"""Batched runs (tsmpc.sim.batch, issue 25 item 2) against the run engine they vectorise: each
lane's RunLog equals ``simulate()``'s — bit for bit with the engine's scalar plant
(``exact_plant``), to ≤ 1e-8 in the states with the vectorised plant (whose polynomial sin/cos/
atan/atan2/tanh are ≤ 2 ulp from the truth) — whatever the batch's other lanes are; lanes with their
own plant parameters, slow paths, divergence, and runs the engine does not take; the polynomials
against long double; the sweep's batched tasks against its one-run tasks."""

from __future__ import annotations

from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.conditions import apply_conditions
from tsmpc.config import Config, replace
from tsmpc.kernels import batch as batch_k
from tsmpc.robustness import apply_robustness
from tsmpc.sim import batch
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.log import RunLog
from tsmpc.sim.simulator import Scenario, simulate
from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

pytestmark = pytest.mark.skipif(not kernels.enabled(), reason="compiled kernels are off")

STEPS = 300  # 30 s of the paper reference: the start-up, the first corners, friction changes


@pytest.fixture(scope="module")
def setup(paper_reference_path: Path) -> tuple[Config, Scenario, tuple]:
    cfg = Config()
    sc = load_scenario(cfg, paper_reference_path)
    return cfg, sc, (load_or_design_kinematic(cfg), load_or_design_dynamic(cfg))


def _single(cfg: Config, method: str, sc: Scenario, designs: tuple, seed: int,
            steps: int | None = STEPS) -> RunLog:
    return simulate(replace(cfg, seed=seed), method, sc, kinematic_design=designs[0],
                    dynamic_design=designs[1], max_steps=steps, engine=True)


def _close(a: RunLog, b: RunLog) -> None:
    """Equal but for the vectorised plant's rounding: statuses, events, termination and every
    integer array exactly; the states (and final state) to 1e-8; the other signals to 1e-8
    relative (the drive force of ~5 kN carries the states' rounding times the gains)."""
    assert (a.termination, a.events) == (b.termination, b.events)
    assert {k: v for k, v in a.meta.items() if k != "final_state"} == \
        {k: v for k, v in b.meta.items() if k != "final_state"}
    np.testing.assert_allclose(a.meta["final_state"], b.meta["final_state"], rtol=0, atol=1e-8)
    x, y = a.arrays(), b.arrays()
    assert x.keys() == y.keys()
    for name in x.keys() - {"mpc_time_s", "mhe_time_s", "lqr_time_s"}:
        if x[name].dtype.kind != "f":
            np.testing.assert_array_equal(x[name], y[name], err_msg=name)
        elif name in ("state", "state_outer"):
            np.testing.assert_allclose(x[name], y[name], rtol=0, atol=1e-8, err_msg=name)
        else:
            np.testing.assert_allclose(x[name], y[name], rtol=1e-8, atol=1e-8, equal_nan=True,
                                       err_msg=name)


def _bits_equal(a: RunLog, b: RunLog) -> None:
    x, y = a.arrays(), b.arrays()
    assert x.keys() == y.keys() and a.events == b.events and a.termination == b.termination
    assert a.meta == b.meta
    for name in x.keys() - {"mpc_time_s", "mhe_time_s", "lqr_time_s"}:
        np.testing.assert_array_equal(x[name], y[name], err_msg=name)


# -------------------------------------------------------------------------- transcendentals
def _ulps(got: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """|got − exact| in units in the last place of the double nearest to exact."""
    nearest = exact.astype(np.float64)
    return np.abs(got.astype(np.longdouble) - exact) / np.spacing(np.abs(nearest)).astype(np.longdouble)


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 60, reason="needs x87 long double")
def test_vector_transcendentals_are_within_two_ulp_of_long_double() -> None:
    """The plant's vectorised right-hand side uses these polynomials instead of libm: over the
    ranges a run meets (angles up to 1e5 rad, Pacejka's arguments, the resistance's tanh) each is
    ≤ 2 ulp from the long-double value. One ulp more than libm's, so a batched run and the
    engine differ by rounding only."""
    from numba import njit

    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-4, 4, 20000), rng.uniform(-1e5, 1e5, 5000),
                        10.0 ** rng.uniform(-300, 0, 2000) * rng.choice([-1, 1], 2000),
                        [0.0, -0.0, np.pi / 2, np.pi, 1e5]])
    y = rng.uniform(-30, 30, x.size)
    @njit
    def call(f, a):
        out = np.empty_like(a)
        for i in range(a.size):
            out[i] = f(a[i])
        return out

    @njit
    def sc(a):
        out = np.empty((a.size, 2))
        for i in range(a.size):
            out[i, 0], out[i, 1] = batch_k.sincos_v(a[i])
        return out

    @njit
    def a2(a, b):
        out = np.empty_like(a)
        for i in range(a.size):
            out[i] = batch_k.atan2_v(a[i], b[i])
        return out

    xl, yl = x.astype(np.longdouble), y.astype(np.longdouble)
    s_c = sc(x)
    assert _ulps(s_c[:, 0], np.sin(xl)).max() <= 2.0
    assert _ulps(s_c[:, 1], np.cos(xl)).max() <= 2.0
    wide = np.concatenate([x, 10.0 ** rng.uniform(0, 300, 2000), [np.inf, -np.inf]])
    assert _ulps(call(batch_k.atan_v, wide), np.arctan(wide.astype(np.longdouble))).max() <= 2.0
    t = np.concatenate([rng.uniform(-40, 40, 20000), x[:20000] * 1e-3])
    assert _ulps(call(batch_k.tanh_v, t), np.tanh(t.astype(np.longdouble))).max() <= 2.0
    got = a2(y, x)  # every quadrant, and the axes
    assert _ulps(got, np.arctan2(yl, xl)).max() <= 2.0


# -------------------------------------------------------------------------- runs
def test_a_batch_equals_the_engine_run_by_run(setup) -> None:
    """Seven seeds of REF: with the engine's scalar plant every lane is the engine's run bit for
    bit; with the vectorised plant within 1e-8 (measured: ~1e-12 m over 30 s), same events."""
    cfg, sc, designs = setup
    seeds = [0, 1, 2, 3, 4, 5, 6]
    exact = batch.simulate_batch(cfg, "REF", sc, seeds=seeds, kinematic_design=designs[0],
                                 dynamic_design=designs[1], max_steps=STEPS, exact_plant=True)
    assert batch.LAST_BATCH["batched"] == len(seeds) and not batch.LAST_BATCH["single"]
    fast = batch.simulate_batch(cfg, "REF", sc, seeds=seeds, kinematic_design=designs[0],
                                dynamic_design=designs[1], max_steps=STEPS)
    assert batch.LAST_BATCH["plant_lanes"] == len(seeds) * STEPS * 10  # vectorised, every step
    worst = 0.0
    for s, le, lf in zip(seeds, exact, fast, strict=True):
        ref = _single(cfg, "REF", sc, designs, s)
        assert ref.termination == "completed"
        _bits_equal(le, ref)
        _close(lf, ref)
        worst = max(worst, float(np.max(np.abs(lf.state - ref.state))))
    assert worst > 0.0, "the vectorised plant is not in use (bit-identical to libm)"


def test_a_lane_does_not_depend_on_the_others(setup) -> None:
    """The same seed alone and as the fourth of nine lanes (two vector groups of the MHE and the
    plant): bit for bit the same run, so a sweep's records do not depend on how it was cut."""
    cfg, sc, designs = setup
    alone = batch.simulate_batch(cfg, "FZN", sc, seeds=[3], kinematic_design=designs[0],
                                 dynamic_design=designs[1], max_steps=120)[0]
    among = batch.simulate_batch(cfg, "FZN", sc, seeds=[9, 8, 7, 3, 2, 1, 0, 5, 6],
                                 kinematic_design=designs[0], dynamic_design=designs[1],
                                 max_steps=120)[3]
    _bits_equal(alone, among)


def test_lanes_with_their_own_plant_and_faults(setup) -> None:
    """Lanes differ in the plant's mass and stiffness (the scenario's plant_vehicle), in a sensor
    fault with NaN bursts (the MHE's and MPC's slow paths: the lane waits for Python), one
    diverges (initial offset beyond a tight bound), one has a biased, drifting gyro: each equals
    its own engine run. (Without the
    speed governor, on by default: with it these lanes took no slow path, measured, and the slow
    paths are what this test exercises; tests/test_governor.py batches governed lanes.)"""
    cfg, sc, designs = setup
    cfg = replace(cfg, governor=replace(cfg.governor, enabled=False))
    v = cfg.vehicle
    heavy = dc_replace(sc, plant_vehicle=replace(v.with_stiffness_scaled(0.8), mass=1.2 * v.mass))
    _, bursts = apply_robustness("nan_bursts", cfg, sc)
    off = dc_replace(sc, initial_error=(0.4, 0.0), divergence_bound_m=0.3)
    # a yaw-rate sensor 0.02 rad/s off, drifting (fusion.gyro_bias busy all along)
    gyro = apply_conditions(replace(cfg, scenario=replace(cfg.scenario, sensors=replace(
        cfg.scenario.sensors, omega_bias=0.02, omega_drift=2e-4))), sc).scenario
    scs = [sc, heavy, bursts, off, gyro]
    logs = batch.simulate_batch(cfg, "ITER", scs, seeds=[0, 1, 2, 3, 4], kinematic_design=designs[0],
                                dynamic_design=designs[1], max_steps=200)
    assert batch.LAST_BATCH["batched"] == 5
    assert sum(batch.LAST_BATCH["slow_paths"].values()) > 0  # the bursts took Python's path
    for s, (scn, log) in enumerate(zip(scs, logs, strict=True)):
        _close(log, _single(cfg, "ITER", scn, designs, s, 200))
    assert logs[3].termination.startswith("diverged") and logs[2].events["mhe_rejected"] > 0


def test_runs_the_engine_does_not_take_run_one_by_one(setup) -> None:
    """A friction profile with no data form: that lane goes to simulate() (the Python loop), the
    others are batched; the answer is complete and in order."""
    cfg, sc, designs = setup

    class Wet:
        def mu(self, t: float, s: float = 0.0) -> float:
            return 0.6

    wet = dc_replace(sc, friction=Wet())
    logs = batch.simulate_batch(cfg, "REF", [sc, wet, sc], seeds=[4, 5, 6],
                                kinematic_design=designs[0], dynamic_design=designs[1], max_steps=50)
    assert batch.LAST_BATCH["batched"] == 2 and list(batch.LAST_BATCH["single"]) == [1]
    assert "friction" in batch.LAST_BATCH["single"][1]
    _bits_equal(logs[1], simulate(replace(cfg, seed=5), "REF", wet, kinematic_design=designs[0],
                                  dynamic_design=designs[1], max_steps=50))
    _close(logs[2], _single(cfg, "REF", sc, designs, 6, 50))


def test_a_lane_that_blinds_the_cascade_runs_one_by_one(setup, monkeypatch) -> None:
    """A lane whose sensors blind the cascade (the guard of applicability() switched off, so the
    lane is batched): the kernel returns when the blind stop begins and the lane falls back to
    simulate(), the Python loop; the other lane stays batched."""
    from tsmpc.sensors import NaNBurstFault
    from tsmpc.sim import engine as eng

    cfg, sc, designs = setup
    blind = dc_replace(sc, sensor_fault=NaNBurstFault(period_s=9.0, duration_s=1.2, start_s=2.0))
    monkeypatch.setattr(eng, "_blinding_fault", lambda *a: None)
    logs = batch.simulate_batch(cfg, "REF", [blind, sc], seeds=[4, 5], kinematic_design=designs[0],
                                dynamic_design=designs[1], max_steps=40)
    assert batch.LAST_BATCH["batched"] == 1
    lp = simulate(replace(cfg, seed=4), "REF", blind, kinematic_design=designs[0], dynamic_design=designs[1],
                  max_steps=40, engine=False)
    assert lp.events["blind_steps"] > 0
    _bits_equal(logs[0], lp)
    _close(logs[1], _single(cfg, "REF", sc, designs, 5, 40))


def test_bad_arguments(setup) -> None:
    cfg, sc, designs = setup
    with pytest.raises(ValueError, match="2 seeds for 3 scenarios"):
        batch.simulate_batch(cfg, "REF", [sc, sc, sc], seeds=[1, 2], kinematic_design=designs[0],
                             dynamic_design=designs[1])


# -------------------------------------------------------------------------- the sweep's tasks
def test_sweep_batches_equal_one_run_tasks(tmp_path: Path, paper_reference_path: Path) -> None:
    """run_batch (what ``tsmpc sweep`` sends to a worker) against run_task per run: the same
    statuses and reasons, metrics to 1e-9 relative (rounding of the vectorised plant); the
    chunks group runs of one controller and give every worker two or more."""
    from tsmpc.sweep import batch_key, batches, expand, load_sweep, run_batch, run_task

    f = tmp_path / "s.toml"
    f.write_text(f'name = "b"\nduration_s = 12.0\n[grid]\nmethod = ["ref", "fzn"]\n'
                 f'scenario = ["nominal", "nan_bursts"]\nseed = [1, 2]\nmass_scale = [1.0, 1.2]\n'
                 f'track = ["{paper_reference_path}"]\n')
    tasks = expand(load_sweep(f))
    assert len(tasks) == 16
    chunks, singles = batches(tasks, 64, 2)
    assert [len(c) for c in chunks] == [8, 8] and singles == []  # a chunk per method, ≥ 8 runs
    assert all(len({t.params.method for t in c}) == 1 for c in chunks)
    assert sorted(t.id for c in chunks for t in c) == sorted(t.id for t in tasks)
    assert len({batch_key(c) for c in chunks}) == 2
    assert [len(c) for c in batches(tasks, 3, 1)[0]] == [3, 3, 2, 3, 3, 2]
    assert batches(tasks, 1, 2) == ([], tasks)  # --batch 1: one run per task
    # Whether a run is batched depends on the whole sweep, not on what is pending (--resume):
    # five pending REF runs of a controller with 8 runs in the sweep are batched, alone they are not.
    ref = [t for t in tasks if t.params.method == "REF"][:5]
    assert batches(ref, 64, 2) == ([], ref)
    assert batches(ref, 64, 2, among=tasks) == ([ref], [])
    got = run_batch(tasks)
    assert [r["id"] for r in got] == [t.id for t in tasks]
    for rec, task in zip(got, tasks, strict=True):
        one = run_task(task)
        assert (rec["status"], rec["reason"], rec["params"]) == (one["status"], one["reason"],
                                                                  one["params"])
        for k, v in one["metrics"]["rmse"].items():
            assert rec["metrics"]["rmse"][k] == pytest.approx(v, rel=1e-9, abs=1e-12), k
        assert rec["elapsed_s"] > 0


def test_a_run_that_cannot_be_set_up_is_an_error_record(tmp_path: Path,
                                                        paper_reference_path: Path) -> None:
    """A track file gone by the time the worker runs (a worker without the shared disk): that
    run's record says so; the batch's other runs complete."""
    import shutil

    from tsmpc.sweep import expand, load_sweep, run_batch

    shutil.copy(paper_reference_path, tmp_path / "gone.csv")
    f = tmp_path / "s.toml"
    f.write_text('name = "b"\nduration_s = 2.0\n[grid]\nseed = [1, 2]\n'
                 'track = ["builtin", "gone.csv"]\n')
    tasks = expand(load_sweep(f))
    (tmp_path / "gone.csv").unlink()
    recs = run_batch(tasks)
    assert [r["id"] for r in recs] == [t.id for t in tasks]
    for r in recs:
        if r["params"]["track"] == "builtin":
            assert r["status"] == "completed", r["reason"]
        else:
            assert r["status"] == "error" and "gone.csv" in r["reason"], r["reason"]


@pytest.mark.parametrize("value", ["0", "2000", '"64"', "true", "6.5"])
def test_a_bad_batch_size_is_refused_naming_the_field(tmp_path: Path, value: str) -> None:
    from tsmpc.errors import ConfigError
    from tsmpc.sweep import load_sweep

    f = tmp_path / "s.toml"
    f.write_text(f'name = "b"\nbatch = {value}\n[grid]\nseed = [1]\n')
    with pytest.raises(ConfigError, match="batch"):
        load_sweep(f)


def test_cli_batch_is_validated_before_anything_runs(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from tsmpc.cli import app

    f = tmp_path / "s.toml"
    f.write_text('name = "b"\n[grid]\nseed = [1]\n')
    for args, why in ((["--batch", "0"], "--batch"), (["--batch", "4", "--dry-run"], "no effect")):
        res = CliRunner().invoke(app, ["sweep", str(f), "--out", str(tmp_path / "o"), *args])
        assert res.exit_code == 2 and why in res.output, res.output
        assert not (tmp_path / "o").exists()
