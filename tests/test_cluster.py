"""A real cluster, exercised (issue 25, item 3).

A Dask scheduler and three single-threaded workers are started as separate processes
(``dask scheduler`` / ``dask worker``, as on a real cluster), ``tsmpc sweep --scheduler`` runs a
small simulated sweep on them, and one worker is SIGKILLed mid-sweep — after some runs are
recorded, while others are pending and one is running on it. Then:

* the sweep exits 0 and every run has exactly one record, never rewritten (nothing lost);
* nothing was recomputed: the scheduler's own transition log shows every task (a batch of runs,
  tsmpc.sim.batch) completing exactly once, and the batches recorded before the kill started
  exactly once (the killed worker produced some of them: had their results still been held on
  it, Dask would have re-run them);
* the records equal those of the same sweep run locally (no ``--scheduler``), timings aside.

Every process is started by the fixture and torn down by it (TERM, then KILL), pass or fail;
every wait has a deadline.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pytest

from _paths import console_script
from tsmpc.sweep import expand, load_sweep, read_record

# 12 runs of 15 simulated seconds in 6 batches of 2 (tsmpc.sim.batch; every method has 4 runs,
# two batches): ~0.2–0.6 s a run once a worker has loaded its kernels, so the sweep lasts seconds
# and a kill after the first batch's records lands while most batches are pending (each of the 3
# workers has a batch in hand and 2 more wait). Half the runs of the first version (24 in 6
# batches of 4: ~55 s of CPU with the local reference sweep) with the same story.
SWEEP = """
name = "cluster"
duration_s = 15.0
batch = 2
[grid]
method = ["ref", "fzn", "iter"]
scenario = ["nominal", "noise_x10"]
seed = [1, 2]
"""
N_RUNS = 12
N_WORKERS = 3
KILL_AFTER = 2  # records on disk before a worker is killed: one batch
#: Metrics that measure the machine, not the run (they differ between any two executions).
TIMING_METRICS = frozenset({"mpc_ms", "mhe_ms", "lqr_ms", "wall_s", "realtime_factor"})


_exe = console_script


def _tail(path: Path, n: int = 30) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


@dataclass
class Cluster:
    """Processes started for one test; the fixture stops all of them."""

    tmp: Path
    env: dict[str, str]
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)
    logs: list[IO[bytes]] = field(default_factory=list)
    address: str = ""
    workers: dict[int, subprocess.Popen[bytes]] = field(default_factory=dict)  #: pid -> process

    def spawn(self, argv: list[str], log: str) -> subprocess.Popen[bytes]:
        fh = open(self.tmp / log, "wb")  # a file, not a pipe: a chatty process never blocks
        self.logs.append(fh)
        # Its own session: a Ctrl-C in the terminal reaches pytest only, and teardown stays ours.
        p = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, env=self.env,
                             cwd=self.tmp, start_new_session=True)
        self.procs.append(p)
        return p

    def wait_for_workers(self, n: int, timeout: float = 60.0) -> dict[str, int]:
        """Block until ``n`` workers are registered; {worker address: pid}."""
        from dask.distributed import Client

        with Client(self.address, timeout=timeout) as client:
            client.wait_for_workers(n, timeout=timeout)
            return client.run(os.getpid)

    def transitions(self) -> list[tuple[str, str, str, float]]:
        """The scheduler's transition log: (key, start, finish, timestamp) of every task."""
        from dask.distributed import Client

        def log(dask_scheduler: Any) -> list[tuple[str, str, str, float]]:
            return [(str(t.key), t.start, t.finish, t.timestamp)
                    for t in dask_scheduler.transition_log]

        with Client(self.address, timeout=30) as client:
            return client.run_on_scheduler(log)

    def stop(self) -> None:
        for p in reversed(self.procs):  # the sweep first, the scheduler last
            if p.poll() is None:
                p.terminate()
        for p in reversed(self.procs):
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=10)
        for fh in self.logs:
            fh.close()


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[Cluster]:
    """A scheduler on a free loopback port and three ``--nthreads 1`` workers, all separate
    processes. ``--no-nanny``: the process killed is the worker itself and nothing restarts it,
    as when a node is lost."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "COLUMNS": "200",
           # Keep the whole story of the sweep's tasks (the default keeps 1000 transitions).
           "DASK_DISTRIBUTED__ADMIN__LOW_LEVEL_LOG_LENGTH": "100000"}
    c = Cluster(tmp_path, env)
    try:
        dask = _exe("dask")
        sched_file = tmp_path / "scheduler.json"
        # --port 0: the OS picks a free port, published in the scheduler file (no race with
        # other tests or engineers). The idle timeout and the workers' death timeout end the
        # processes on their own should this test's teardown never run (pytest SIGKILLed).
        sched = c.spawn([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                         "--scheduler-file", str(sched_file), "--dashboard-address", "127.0.0.1:0",
                         "--idle-timeout", "300"], "scheduler.log")
        deadline = time.monotonic() + 60
        while not c.address:
            if sched.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"the scheduler did not start:\n{_tail(tmp_path / 'scheduler.log')}")
            try:
                c.address = json.loads(sched_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        assert c.address.startswith("tcp://127.0.0.1:")
        for i in range(N_WORKERS):
            p = c.spawn([dask, "worker", c.address, "--nthreads", "1", "--no-nanny",
                         "--name", f"w{i}", "--dashboard-address", "127.0.0.1:0",
                         "--local-directory", str(tmp_path / f"w{i}"), "--death-timeout", "60"],
                        f"worker{i}.log")
            c.workers[p.pid] = p
        yield c
    finally:
        c.stop()


def _same(a: Any, b: Any) -> bool:
    """Exact equality of JSON values, NaN equal to NaN."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def _comparable(rec: dict[str, Any]) -> dict[str, Any]:
    """A record without what depends on where and how fast it ran."""
    return {"params": rec["params"], "status": rec["status"], "reason": rec["reason"],
            "metrics": {k: v for k, v in rec["metrics"].items() if k not in TIMING_METRICS}}


def _records(runs: Path) -> dict[str, dict[str, Any]]:
    out = {}
    for p in runs.glob("*.json"):
        rec = read_record(p)
        assert rec is not None, f"{p} is not a valid run record"
        out[p.stem] = rec
    return out


@pytest.mark.slow
@pytest.mark.timeout(300)  # a last resort: every wait below has its own, shorter deadline
def test_a_worker_killed_mid_sweep_on_a_separate_cluster_loses_and_recomputes_nothing(
        tmp_path: Path, dask_cluster: Cluster) -> None:
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(SWEEP)
    ids = {t.id for t in expand(load_sweep(sweep))}
    assert len(ids) == N_RUNS
    tsmpc = _exe("tsmpc")

    # The reference: the same sweep on a LocalCluster (it also fills this machine's kernel cache,
    # which the workers below share through TSMPC_CACHE_DIR, while they start up). One worker
    # process: one fewer to start and load the kernels in; a run's record does not depend on the
    # number of workers (tsmpc.sweep.batches).
    local = subprocess.run([tsmpc, "sweep", str(sweep), "--out", str(tmp_path / "local"),
                            "--workers", "1", "--no-plots"], env=dask_cluster.env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=150)
    assert local.returncode == 0, local.stdout + local.stderr
    expected = _records(tmp_path / "local" / "runs")
    assert set(expected) == ids

    pids = dask_cluster.wait_for_workers(N_WORKERS)
    assert set(pids.values()) == set(dask_cluster.workers)  # the workers are our processes

    out = tmp_path / "cluster"
    runs = out / "runs"
    proc = dask_cluster.spawn([tsmpc, "sweep", str(sweep), "--scheduler", dask_cluster.address,
                               "--out", str(out), "--no-plots"], "sweep.log")
    first_seen: dict[str, tuple[int, int]] = {}  # id -> (inode, mtime) when its record appeared
    order: list[str] = []
    victim: int | None = None
    at_kill: set[str] = set()
    deadline = time.monotonic() + 150
    while proc.poll() is None:
        if time.monotonic() > deadline:
            pytest.fail(f"the sweep did not finish in time:\n{_tail(tmp_path / 'sweep.log')}")
        for p in runs.glob("*.json") if runs.is_dir() else ():
            if p.stem not in first_seen:
                st = p.stat()
                first_seen[p.stem] = (st.st_ino, st.st_mtime_ns)
                order.append(p.stem)
        if victim is None and len(order) >= KILL_AFTER:
            # The worker that produced the newest record: it has just taken its next task, so
            # it dies mid-run, and results it computed earlier have been recorded.
            rec = read_record(runs / f"{order[-1]}.json")
            assert rec is not None
            victim = int(rec["worker_pid"])
            assert victim in dask_cluster.workers, (victim, list(dask_cluster.workers))
            at_kill = set(order)
            os.kill(victim, signal.SIGKILL)
            dask_cluster.workers[victim].wait(timeout=10)
        time.sleep(0.02)
    log = (tmp_path / "sweep.log").read_text(errors="replace")
    assert proc.returncode == 0, log[-3000:]
    assert victim is not None, "the sweep ended before a worker could be killed"
    assert len(at_kill) < N_RUNS, "every run was recorded before the kill: nothing was pending"

    # Nothing lost: one valid record per run, and none rewritten after it first appeared.
    got = _records(runs)
    assert set(got) == ids
    assert not (runs / ".unreadable").exists()
    for rid, (ino, mtime) in first_seen.items():
        st = (runs / f"{rid}.json").stat()
        assert (st.st_ino, st.st_mtime_ns) == (ino, mtime), f"record {rid} was rewritten"
    assert f"{N_RUNS} runs ({N_RUNS} run now, 0 resumed)" in log, log[-3000:]

    # Nothing recomputed, from the scheduler's own record of what ran. The sweep sends batches
    # of runs (tsmpc.sim.batch): each record names the Dask task (batch) that produced it.
    batch_of = {rid: rec["batch"] for rid, rec in got.items()}
    keys = set(batch_of.values())
    assert 1 < len(keys) < N_RUNS, keys  # batches of several runs, several batches
    started = dict.fromkeys(keys, 0)
    completed = dict.fromkeys(keys, 0)
    for key, start, finish, _ in dask_cluster.transitions():
        if key in keys and finish == "processing":
            started[key] += 1
        if key in keys and (start, finish) == ("processing", "memory"):
            completed[key] += 1
    assert all(n == 1 for n in completed.values()), {k: n for k, n in completed.items() if n != 1}
    assert all(started[batch_of[rid]] == 1 for rid in at_kill), \
        {k: started[batch_of[k]] for k in at_kill}
    # The kill did interrupt work: the batch the dead worker held was started again elsewhere.
    rerun = sum(started.values()) - len(keys)
    assert rerun >= 1, "no task was running on the killed worker"

    # Identical results: the same statuses and metrics as the local sweep (timings aside).
    differ = [rid for rid in ids if not _same(_comparable(got[rid]), _comparable(expected[rid]))]
    assert not differ, [(got[r]["metrics"].get("rmse"), expected[r]["metrics"].get("rmse"))
                        for r in differ[:3]]
    print(f"\n{N_RUNS} runs recorded once each; worker {victim} killed after {len(at_kill)} "
          f"records; {rerun} interrupted batch(es) of {len(keys)} re-run elsewhere; 0 recomputed; "
          f"{N_RUNS} identical to the local sweep")
