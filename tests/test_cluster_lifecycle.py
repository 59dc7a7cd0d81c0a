"""Dask's lifecycle owned (issue 38 item 4).

* A task the *cluster* lost — cancelled (``FutureCancelledError``, reason
  "scheduler-connection-lost"), a closed comm, a timeout — is no result: no record is written,
  the sweep ends non-zero with ``PARTIAL`` naming the missing runs, and ``--resume`` runs exactly
  those. (The client used to exit 0 saying "wrote 2 files and 200 records" with 160 records
  "failed: FutureCancelledError".) A task lost to repeated worker deaths (``KilledWorker``) keeps
  its ``failed`` record, and the sweep is unfinished too.
* A real external scheduler (``dask scheduler`` / ``dask worker`` processes on 127.0.0.1) killed
  with -9 mid-sweep: exit 1, PARTIAL present, no traceback; ``--resume`` on a local cluster
  completes it, with the records of a local sweep.
* SIGINT/SIGTERM during the local cluster's start-up or shutdown: the documented exit code
  (128 + signal), no traceback (``AssertionError: Status.init`` in Dask's atexit callback), and
  no empty folder the sweep created.

Tiny dry sweeps (``--dry-run``: tasks sleep 0.2–0.4 s) on one worker; every wait has a deadline.
"""

from __future__ import annotations

import concurrent.futures
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from _paths import console_script
from tsmpc.cli import app
from tsmpc.cli._common import PARTIAL_MARKER
from tsmpc.sweep import RunTask, dry_run, expand, load_sweep, read_record, run_sweep

SWEEP = 'name = "t"\nduration_s = 1.0\n[grid]\nseed = [1, 2, 3, 4, 5, 6]\n'
runner = CliRunner()


@pytest.fixture(scope="module")
def cluster():
    """One worker process; this module's task functions are shipped by value (the worker cannot
    import a test module)."""
    import cloudpickle
    from dask.distributed import LocalCluster

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=":0") as c:
            yield c
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def _comm_closed() -> Exception:
    from distributed.comm.core import CommClosedError

    return CommClosedError("in <TCP (closed)>: Stream is closed")


def _killed_worker() -> Exception:
    from distributed.scheduler import KilledWorker

    return KilledWorker("tsmpc-run-x", "tcp://127.0.0.1:1", 3)


#: (id, the error the cluster gives for the even seeds, the record they get: None = none)
LOSSES = [
    ("cancelled", lambda: concurrent.futures.CancelledError(
        "tsmpc-run-x cancelled for reason: scheduler-connection-lost."), None),
    ("future-cancelled", lambda: _future_cancelled(), None),
    ("comm-closed", _comm_closed, None),
    ("timeout", lambda: TimeoutError("no reply from the scheduler"), None),
    ("connection-reset", lambda: ConnectionResetError(104, "Connection reset by peer"), None),
    ("killed-worker", _killed_worker, "failed"),
]
_ERRORS = {i: make for i, make, _ in LOSSES}


def _future_cancelled() -> Exception:
    from distributed.client import FutureCancelledError

    return FutureCancelledError("tsmpc-run-x", reason="scheduler-connection-lost")


def _losing(how: str):
    def run(task: RunTask) -> dict[str, Any]:
        if task.params.seed is not None and task.params.seed % 2 == 0:
            raise _ERRORS[how]()
        return dry_run(task)
    return run


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("how", "status"), [pytest.param(i, s, id=i) for i, _, s in LOSSES])
def test_runs_the_cluster_lost_are_no_results_and_resume_runs_them(tmp_path: Path, cluster, how: str,
                                                                   status: str | None) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    spec = load_sweep(sweep)
    tasks = expand(spec)
    lost = sorted(t.id for t in tasks if t.params.seed % 2 == 0)
    out = tmp_path / "out"
    res = run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=_losing(how), plots=False)
    assert not res.complete and sorted(res.incomplete) == lost
    for rid in lost:
        rec = read_record(out / "runs" / f"{rid}.json")
        if status is None:  # no record: not a result
            assert rec is None and not (out / "runs" / f"{rid}.json").exists()
        else:
            assert rec is not None and rec["status"] == status
    assert (res.lost, bool(res.lost_reason)) == ((3, True) if status is None else (0, False))
    again = run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=dry_run, plots=False,
                      resume=True)
    assert again.complete and again.executed == 3 and again.skipped == 3
    assert sorted(again.table["id"]) == sorted(t.id for t in tasks)
    assert set(again.table["status"]) == {"completed"}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("how", ["future-cancelled", "killed-worker"])
def test_the_cli_says_unfinished_exits_1_and_partial_names_the_runs(tmp_path: Path, cluster,
                                                                    monkeypatch, how: str) -> None:
    import tsmpc.sweep as sw

    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    lost = sorted(t.id for t in expand(load_sweep(sweep)) if t.params.seed % 2 == 0)
    monkeypatch.setattr(sw, "dry_run", _losing(how))
    out = tmp_path / "out"
    args = ["sweep", str(sweep), "--dry-run", "--no-plots", "--scheduler", cluster.scheduler_address,
            "--out", str(out)]
    res = runner.invoke(app, args)
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 1, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "3 of 6 runs have no result" in errors[0], res.output
    assert "--resume" in errors[0] and "Traceback" not in res.output
    marker = json.loads((out / PARTIAL_MARKER).read_text())
    assert marker["status"] == "failed"
    assert sorted(marker["missing"] + marker["failed"]) == lost
    monkeypatch.setattr(sw, "dry_run", dry_run)
    res = runner.invoke(app, [*args, "--resume"])
    assert res.exit_code == 0, res.output
    assert not (out / PARTIAL_MARKER).exists()
    assert "6 of 6 records" in res.output


@pytest.mark.timeout(60)
@pytest.mark.parametrize("error", [RuntimeError("Nanny failed to start."), MemoryError(),
                                   OSError(24, "Too many open files")])
def test_a_local_cluster_that_does_not_start_ends_with_one_line(tmp_path: Path, monkeypatch,
                                                                error: Exception) -> None:
    """The machine, not the input: exit 1, one line (never "internal error"), no folder left."""
    import dask.distributed

    def broken(*_a, **_k):
        raise error
    monkeypatch.setattr(dask.distributed, "LocalCluster", broken)
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    out = tmp_path / "out"
    res = runner.invoke(app, ["sweep", str(sweep), "--dry-run", "--workers", "1", "--out", str(out)])
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 1, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "local Dask cluster" in errors[0], res.output
    assert "internal error" not in res.output and "Traceback" not in res.output
    assert not out.exists()


# -- a real external scheduler, killed -9 mid-sweep ---------------------------------------------
_exe = console_script


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
    for p in procs:
        p.wait(timeout=10)


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_an_external_scheduler_killed_mid_sweep_leaves_partial_and_resume_finishes(tmp_path: Path) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 1.0\n[grid]\nseed = ['
                     + ", ".join(str(i) for i in range(1, 31)) + "]\n")
    ids = {t.id for t in expand(load_sweep(sweep))}
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "COLUMNS": "200"}
    dask, tsmpc = _exe("dask"), _exe("tsmpc")
    procs: list[subprocess.Popen] = []
    logs = []

    def spawn(argv: list[str], log: str) -> subprocess.Popen:
        fh = open(tmp_path / log, "wb")
        logs.append(fh)
        p = subprocess.Popen(argv, stdout=fh, stderr=subprocess.PIPE if log == "sweep.log" else fh,
                             env=env, cwd=tmp_path, start_new_session=True)
        procs.append(p)
        return p

    try:
        sched_file = tmp_path / "scheduler.json"
        sched = spawn([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--scheduler-file",
                       str(sched_file), "--dashboard-address", "127.0.0.1:0", "--idle-timeout", "120"],
                      "scheduler.log")
        address, deadline = "", time.monotonic() + 60
        while not address:
            assert sched.poll() is None and time.monotonic() < deadline, "no scheduler"
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        assert address.startswith("tcp://127.0.0.1:")
        spawn([dask, "worker", address, "--nthreads", "1", "--no-nanny", "--dashboard-address",
               "127.0.0.1:0", "--local-directory", str(tmp_path / "w"), "--death-timeout", "30"],
              "worker.log")
        out = tmp_path / "out"
        proc = spawn([tsmpc, "sweep", str(sweep), "--dry-run", "--no-plots", "--scheduler", address,
                      "--out", str(out)], "sweep.log")
        deadline = time.monotonic() + 120
        while proc.poll() is None and len(list((out / "runs").glob("*.json"))
                                          if (out / "runs").is_dir() else []) < 3:
            assert time.monotonic() < deadline, "no record in time"
            time.sleep(0.05)
        sched.kill()  # -9: the scheduler is gone mid-sweep
        _, err = proc.communicate(timeout=90)
        text = err.decode(errors="replace")
        assert proc.returncode == 1, text
        assert "Traceback" not in text and "ERROR" not in text, text
        errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
        assert len(errors) == 1 and "scheduler-connection-lost" in errors[0], text
        marker = json.loads((out / PARTIAL_MARKER).read_text())
        recorded = {p.stem for p in (out / "runs").glob("*.json")}
        assert 3 <= len(recorded) < len(ids)
        assert set(marker["missing"]) == ids - recorded and not marker["failed"]

        # --resume on a new (local) cluster finishes it, as a local sweep would have
        res = subprocess.run([tsmpc, "sweep", str(sweep), "--dry-run", "--no-plots", "--workers", "1",
                              "--resume", "--out", str(out)], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=120)
        assert res.returncode == 0, res.stderr
        assert not (out / PARTIAL_MARKER).exists()
        local = tmp_path / "local"
        spec = load_sweep(sweep)
        run_sweep(spec, local, workers=1, run_fn=dry_run, plots=False)
        for rid in ids:
            a, b = read_record(out / "runs" / f"{rid}.json"), read_record(local / "runs" / f"{rid}.json")
            assert a is not None and b is not None
            assert (a["params"], a["status"], a["metrics"]) == (b["params"], b["status"], b["metrics"])
    finally:
        _stop(procs)
        for fh in logs:
            fh.close()


# -- signals while the local cluster starts or stops --------------------------------------------
DRIVER = """
import os, signal, sys, threading
import dask.distributed as dd

phase, sig, out, sweep = sys.argv[1], getattr(signal, sys.argv[2]), sys.argv[3], sys.argv[4]
Base = dd.LocalCluster

def hit(delay):
    threading.Timer(delay, os.kill, (os.getpid(), sig)).start()

class Cluster(Base):
    def __init__(self, *a, **k):
        if phase == "startup":
            hit(0.3)  # while the worker process starts (it takes seconds)
        super().__init__(*a, **k)

    def close(self, *a, **k):
        if phase == "shutdown":
            hit(0.05)
        return super().close(*a, **k)

dd.LocalCluster = Cluster
from tsmpc.cli import main
sys.argv = ["tsmpc", "sweep", sweep, "--dry-run", "--no-plots", "--workers", "1", "--out", out]
main()
"""


@pytest.mark.slow
@pytest.mark.timeout(120)
@pytest.mark.parametrize("phase", ["startup", "shutdown"])
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_while_the_local_cluster_starts_or_stops_prints_no_traceback(
        tmp_path: Path, phase: str, sig: str) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 1.0\n[grid]\nseed = [1, 2]\n')
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-c", DRIVER, phase, sig, str(out), str(sweep)],
                         capture_output=True, text=True, timeout=100, cwd=tmp_path)
    err = res.stderr
    assert res.returncode == 128 + getattr(signal, sig), err
    assert "Traceback" not in err and "AssertionError" not in err and "Status.init" not in err, err
    assert f"interrupted ({sig})" in err, err
    if phase == "startup":  # nothing ran: the folder the sweep made is gone
        assert not out.exists(), sorted(p.name for p in out.iterdir())
    else:  # every record was written before the cluster closed; PARTIAL says interrupted
        assert len(list((out / "runs").glob("*.json"))) == 2
        assert json.loads((out / PARTIAL_MARKER).read_text())["status"] == "interrupted"
