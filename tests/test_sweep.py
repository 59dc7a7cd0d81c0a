"""Sweeps on Dask (issue 8): validation before any task, expansion, a 2-worker LocalCluster run,
a worker killed mid-sweep, resume after an interruption, and an end-to-end simulated sweep."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pandas as pd
import pytest

from _paths import need_data
from tsmpc.errors import ConfigError
from tsmpc.sweep import dry_run, expand, load_sweep, run_sweep

GRID8 = """
name = "t"
duration_s = 2.0
[grid]
method = ["ref", "fzn"]
scenario = ["nominal", "noise_x10"]
seed = [1, 2]
"""


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(("text", "needle"), [
    ("[grid]\nmethods = ['ref']\n", "grid.methods: unknown field"),
    ("[grid]\nmethod = []\n", "axis 'method' is empty"),
    ("[grid]\nnoise_scale = ['loud']\n", "grid.noise_scale.0"),
    ("[grid]\nmethod = ['mpc']\n", "unknown method 'mpc'"),
    ("[grid]\nscenario = ['hail']\n", "unknown robustness scenario 'hail'"),
    ("duration_s = -1\n", "duration_s"),
    ("[random]\nn = 2\nranges = { method = [1, 2] }\n", "'method' is not a numeric axis"),
    ("[random]\nn = 0\n", "random.n"),
    ("[grid]\ntrack = ['nowhere.csv']\n", "track: 'nowhere.csv'"),
    ("[config.vehicle]\nmas = 700\n", "config: vehicle.mas: unknown field"),
    ("base_config = 'missing.toml'\n", "cannot read config file"),
    ("[grid\n", "invalid TOML"),
])
def test_bad_sweep_files_fail_before_any_task_naming_the_field(
    tmp_path: Path, text: str, needle: str
) -> None:
    with pytest.raises(ConfigError) as err:
        load_sweep(_write(tmp_path, text))
    assert needle in str(err.value)


def test_expansion_is_a_stable_cartesian_product_with_seeded_random_draws(tmp_path: Path) -> None:
    spec = load_sweep(_write(tmp_path, GRID8))
    tasks = expand(spec)
    assert len(tasks) == 8 and len({t.id for t in tasks}) == 8
    assert [t.id for t in expand(spec)] == [t.id for t in tasks]  # ids hash the inputs only
    text = GRID8 + "[random]\nn = 3\nseed = 4\nranges = { mass_scale = [0.9, 1.1] }\n"
    rnd = expand(load_sweep(_write(tmp_path, text, "r.toml")))
    assert len(rnd) == 24
    masses = {t.params.mass_scale for t in rnd}
    assert len(masses) == 3 and all(0.9 <= m <= 1.1 for m in masses)
    assert [t.id for t in rnd] == [t.id for t in expand(load_sweep(tmp_path / "r.toml"))]
    # A different base config changes every id: resumed results are never stale.
    changed = expand(load_sweep(_write(tmp_path, GRID8 + "[config.mpc]\nN = 30\n", "c.toml")))
    assert not {t.id for t in changed} & {t.id for t in tasks}


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as c:
        yield c


def _records(out: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in (out / "runs").glob("*.json")}


def test_two_worker_sweep_writes_one_record_and_one_row_per_run(tmp_path: Path, cluster) -> None:
    spec = load_sweep(_write(tmp_path, GRID8))
    res = run_sweep(spec, tmp_path / "out", scheduler=cluster.scheduler_address, run_fn=dry_run,
                    plots=False)
    assert (res.n_runs, res.executed, res.skipped, res.failed, res.duplicates) == (8, 8, 0, 0, 0)
    recs = _records(tmp_path / "out")
    assert set(recs) == {t.id for t in expand(spec)}
    assert len({r["worker_pid"] for r in recs.values()}) == 2  # both workers did work
    table = pd.read_csv(tmp_path / "out" / "aggregate.csv")
    assert len(table) == 8 and table["id"].is_unique
    assert pd.read_parquet(tmp_path / "out" / "aggregate.parquet").equals(res.table)
    assert set(table["method"]) == {"REF", "FZN"} and set(table["seed"]) == {1, 2}
    # Without --resume an existing sweep folder is refused, not overwritten.
    with pytest.raises(ConfigError, match="--resume"):
        run_sweep(spec, tmp_path / "out", scheduler=cluster.scheduler_address, run_fn=dry_run)


def test_a_worker_killed_mid_sweep_loses_nothing_and_counts_nothing_twice(tmp_path: Path) -> None:
    from dask.distributed import Client, LocalCluster

    text = GRID8.replace('seed = [1, 2]', 'seed = [1, 2, 3]')  # 12 runs of 0.2–0.4 s
    spec = load_sweep(_write(tmp_path, text))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as c:
        # A second client open during the sweep makes distributed flaky (futures' events bound
        # to another event loop): ask for the worker pids, then close it.
        with Client(c) as client:
            pids = list(client.run(os.getpid).values())
        killed: list[int] = []

        def kill_one(done: int, total: int, rec: dict) -> None:
            if done == 2 and not killed:  # mid-sweep: the other worker is busy with a task
                victim = pids[0] if rec["worker_pid"] != pids[0] else pids[1]
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        res = run_sweep(spec, tmp_path / "out", scheduler=c.scheduler_address, run_fn=dry_run,
                        progress=kill_one, plots=False)
    assert killed
    assert (res.executed, res.failed, res.duplicates) == (12, 0, 0)
    recs = _records(tmp_path / "out")
    assert set(recs) == {t.id for t in expand(spec)}
    assert all(r["status"] == "completed" for r in recs.values())
    assert len(pd.read_csv(tmp_path / "out" / "aggregate.csv")) == 12


def _counting_dry_run(task):  # picklable by value (see below): counts executions per run id
    import uuid

    rec = dry_run(task)
    folder = Path(task.root) / "executions"
    folder.mkdir(exist_ok=True)
    (folder / f"{task.id}.{uuid.uuid4().hex}").touch()
    return rec


def test_records_already_received_are_not_recomputed_after_a_worker_loss(tmp_path: Path) -> None:
    """Kill the worker that computed the first records (their results would still sit in its
    memory if the client kept the futures): none of those runs executes a second time."""
    import sys

    import cloudpickle
    from dask.distributed import LocalCluster

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    text = GRID8.replace('seed = [1, 2]', 'seed = [1, 2, 3]')  # 12 runs of 0.2–0.4 s
    spec = load_sweep(_write(tmp_path, text))
    received: list[str] = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as c:
        def kill_producer(done: int, total: int, rec: dict) -> None:
            received.append(rec["id"])
            if done == 3:
                os.kill(rec["worker_pid"], signal.SIGKILL)

        res = run_sweep(spec, tmp_path / "out", scheduler=c.scheduler_address,
                        run_fn=_counting_dry_run, progress=kill_producer, plots=False)
    assert (res.executed, res.failed, res.duplicates) == (12, 0, 0)
    runs = [p.name.split(".")[0] for p in (tmp_path / "executions").iterdir()]
    for rid in received[:3]:
        assert runs.count(rid) == 1, f"{rid} ran {runs.count(rid)} times"
    # At most the task running on the killed worker is executed twice.
    assert len(runs) <= 13


def test_resume_after_an_interruption_runs_only_what_is_missing(tmp_path: Path, cluster) -> None:
    spec = load_sweep(_write(tmp_path, GRID8))
    out = tmp_path / "out"

    class Interrupt(Exception):
        pass

    def stop_after_three(done: int, total: int, rec: dict) -> None:
        if done == 3:
            raise Interrupt

    with pytest.raises(Interrupt):
        run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=dry_run,
                  progress=stop_after_three, plots=False)
    first = _records(out)
    assert len(first) == 3
    res = run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=dry_run, resume=True,
                    plots=False)
    assert (res.skipped, res.executed) == (3, 5)
    second = _records(out)
    assert len(second) == 8
    for rid, rec in first.items():  # finished runs were not re-run or rewritten
        assert second[rid] == rec


@pytest.mark.slow
def test_end_to_end_sweep_simulates_every_run(tmp_path: Path, cluster, tracks_dir: Path) -> None:
    """Real simulations (4 s each): the robustness scenarios that change the sensors, the plant and
    the surface, and one race track; all complete and track within a few centimetres."""
    text = f"""
name = "e2e"
duration_s = 4.0
[grid]
method = ["ref"]
scenario = ["nominal", "ice_patch", "nan_bursts", "mass_stiffness_mismatch"]
track = ["builtin", "{tracks_dir / 'Monza.csv'}"]
"""
    spec = load_sweep(_write(tmp_path, text))
    res = run_sweep(spec, tmp_path / "out", scheduler=cluster.scheduler_address)
    t = res.table
    assert len(t) == 8 and (t["status"] == "completed").all(), t[["status", "reason"]]
    assert (abs(t["simulated_s"] - 4.0) < 0.11).all()
    assert (t["max_abs_lateral_m"] < 0.2).all()
    assert (t.loc[t["scenario"] == "nan_bursts", "events_mhe_rejected"] > 0).all()
    assert (tmp_path / "out" / "by_scenario.png").stat().st_size > 1000


def test_cli_sweep_dry_run_and_bad_file(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from tsmpc.cli import app

    sweep = _write(tmp_path, GRID8)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sweep", str(sweep), "--dry-run", "--workers", "2", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert len(pd.read_csv(out / "aggregate.csv")) == 8
    assert (out / "by_method.png").is_file() and (out / "solve_times.png").is_file()
    again = CliRunner().invoke(app, ["sweep", str(sweep), "--dry-run", "--out", str(out), "--resume"])
    assert again.exit_code == 0 and "0 run now, 8 resumed" in again.output
    bad = CliRunner().invoke(app, ["sweep", str(_write(tmp_path, "[grid]\nmethod = []\n", "b.toml"))])
    assert bad.exit_code == 2 and "axis 'method' is empty" in bad.output


def test_cli_sweep_refuses_a_full_out_folder_before_any_design_work(tmp_path: Path, monkeypatch) -> None:
    """A non-empty --out (without --resume) is refused with one line before the LMI designs are
    loaded or solved; a design failure leaves no folder the command created."""
    from typer.testing import CliRunner

    import tsmpc.cli.sweep as cli_sweep
    from tsmpc.cli import app
    from tsmpc.errors import SolverError

    calls = []

    def designs(cfg):
        calls.append(cfg)
        raise SolverError("dynamic LMI infeasible (injected)")

    monkeypatch.setattr(cli_sweep, "design_status", designs)
    sweep = _write(tmp_path, GRID8)
    full = tmp_path / "full"
    full.mkdir()
    (full / "notes.txt").write_text("mine")
    res = CliRunner().invoke(app, ["sweep", str(sweep), "--out", str(full)])
    assert res.exit_code == 2 and "folder is not empty" in res.output and not calls
    fresh = tmp_path / "fresh"
    res = CliRunner().invoke(app, ["sweep", str(sweep), "--out", str(fresh)])
    assert res.exit_code == 2 and "infeasible (injected)" in res.output and len(calls) == 1
    assert not fresh.exists()


def test_a_track_may_be_a_dataset_name(tmp_path: Path) -> None:
    """``track = ["paper"]`` (or a track's name, ``monza``) is the fetched dataset, as on the command
    line (tsmpc.datasets); a name that is neither a dataset nor a file is still refused."""
    from tsmpc import datasets
    from tsmpc.sweep import track_file

    need_data("paper")
    spec = load_sweep(_write(tmp_path, "[grid]\ntrack = ['paper']\nmethod = ['ref']\n"))
    assert track_file("paper", spec.root) == datasets.resolve("paper")
    assert [t.params.track for t in expand(spec)] == ["paper"]
    with pytest.raises(ConfigError, match="neither 'builtin', a dataset name nor a readable file"):
        load_sweep(_write(tmp_path, "[grid]\ntrack = ['paperr']\n", "bad.toml"))
