"""Sweep resume repairs and sweeps that write nothing before they are valid (issue 24).

* ``--resume`` re-reads every record on disk (``tsmpc.sweep.read_record``): one that is not a
  valid record of this sweep — empty, garbage, ``[]``, a folder, a FIFO, another run's id, too
  deeply nested, too large — is set aside under ``runs/.unreadable/`` and re-run, so aggregation
  never crashes on it;
* records of runs lost to worker failures (status ``failed``) are re-run with ``--resume``
  (``retry_failed``; ``--no-retry-failed`` keeps them);
* a sweep whose base config has no LMI design exits 2 before ``sweep.json`` or ``runs/`` exist;
* the scheduler handshake is bounded: a port that accepts but never speaks is given up after
  ``--connect-timeout`` (it held the client for a minute).
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from tsmpc.errors import ConfigError
from tsmpc.sweep import dry_run, expand, load_sweep, read_record, run_sweep

SWEEP = 'name = "t"\nduration_s = 2.0\n[grid]\nmethod = ["ref", "fzn"]\nseed = [1, 2]\n'


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as c:
        yield c


@pytest.fixture(scope="module")
def done(tmp_path_factory: pytest.TempPathFactory, cluster) -> tuple[Path, list[str]]:
    """A finished 4-run dry sweep (copied by each test)."""
    d = tmp_path_factory.mktemp("sweep")
    (d / "s.toml").write_text(SWEEP)
    spec = load_sweep(d / "s.toml")
    run_sweep(spec, d / "out", scheduler=cluster.scheduler_address, run_fn=dry_run, plots=False)
    return d, [t.id for t in expand(spec)]


def _copy(done: tuple[Path, list[str]], tmp_path: Path) -> Path:
    import shutil

    src, _ = done
    shutil.copy(src / "s.toml", tmp_path / "s.toml")
    shutil.copytree(src / "out", tmp_path / "out")
    return tmp_path / "out"


#: Records that parse but make no sense (issue 38): (how, dotted field, value). A number of the
#: aggregate table out of range or of the wrong type, or the params of another run.
SEMANTIC = [
    ("rmse-y-minus-1e300", "metrics.rmse.y", -1e300),
    ("rmse-y-oops", "metrics.rmse.y", "oops"),  # pyarrow's ArrowInvalid: "internal error"
    ("rmse-y-inf", "metrics.rmse.y", math.inf),
    ("rmse-x-true", "metrics.rmse.x", True),
    ("rmse-y-list", "metrics.rmse.y", [1.0]),
    ("rmse-extra-key", "metrics.rmse.zz", 0.1),
    ("lateral-negative", "metrics.max_abs_lateral_m", -1.0),
    ("mpc-median-oops", "metrics.mpc_ms.median", "oops"),
    ("wall-inf", "metrics.wall_s", math.inf),
    ("events-negative", "metrics.events.mpc_fallback", -3),
    ("events-float", "metrics.events.mpc_fallback", 1.5),
    ("elapsed-oops", "elapsed_s", "oops"),
    ("elapsed-negative", "elapsed_s", -1.0),
    ("reason-number", "reason", 7),
    ("params-seed-other-run", "params.seed", 99),
    ("params-method-number", "params.method", 7),
    ("params-unknown-field", "params.colour", "red"),
]


def _set(rec: dict, dotted: str, value: object) -> None:
    *path, last = dotted.split(".")
    for k in path:
        rec = rec.setdefault(k, {})
    rec[last] = value


def _spoil(path: Path, how: str, rid: str) -> None:
    semantic = {h: (f, v) for h, f, v in SEMANTIC}
    if how in semantic:
        rec = json.loads(path.read_text())
        _set(rec, *semantic[how])
        path.write_text(json.dumps(rec))
        return
    path.unlink()
    if how == "empty":
        path.write_text("")
    elif how == "garbage":
        path.write_text("{\"id\": \"" + rid + "\", \"status\": \"comp")
    elif how == "list":
        path.write_text("[]")
    elif how == "object-without-fields":
        path.write_text("{}")
    elif how == "other-id":
        path.write_text(json.dumps({"id": "0" * 16, "status": "completed", "params": {}, "metrics": {}}))
    elif how == "unknown-status":
        path.write_text(json.dumps({"id": rid, "status": "great", "params": {}, "metrics": {}}))
    elif how == "metrics-not-object":
        path.write_text(json.dumps({"id": rid, "status": "completed", "params": {}, "metrics": [1]}))
    elif how == "nested":
        path.write_text("[" * 100_000 + "]" * 100_000)
    elif how == "binary":
        path.write_bytes(bytes(range(256)))
    elif how == "folder":
        path.mkdir()
    elif how == "fifo":
        os.mkfifo(path)
    elif how == "huge":
        with open(path, "wb") as fh:
            fh.truncate(20 * 1024 * 1024)
    else:  # pragma: no cover
        raise AssertionError(how)


SPOILS = ["empty", "garbage", "list", "object-without-fields", "other-id", "unknown-status",
          "metrics-not-object", "nested", "binary", "folder", "fifo", "huge",
          *(how for how, _, _ in SEMANTIC)]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("how", SPOILS)
def test_resume_sets_an_unreadable_record_aside_and_runs_it_again(done, tmp_path: Path, cluster,
                                                                  how: str) -> None:
    out = _copy(done, tmp_path)
    ids = done[1]
    victim = out / "runs" / f"{ids[1]}.json"
    _spoil(victim, how, ids[1])
    spec = load_sweep(tmp_path / "s.toml")
    params = {t.id: t.params.model_dump(mode="json") for t in expand(spec)}
    assert read_record(victim, params=params[ids[1]]) is None
    res = run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=dry_run, resume=True,
                    plots=False)
    assert (res.skipped, res.executed) == (3, 1)
    assert read_record(victim) is not None  # a fresh, valid record in its place
    assert len(list((out / "runs" / ".unreadable").iterdir())) == 1  # kept for inspection
    table = pd.read_csv(out / "aggregate.csv")
    assert sorted(table["id"]) == sorted(ids)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("retry", [True, False, None])
def test_failed_records_are_retried_on_resume_unless_told_not_to(done, tmp_path: Path, cluster,
                                                                 retry: bool | None) -> None:
    out = _copy(done, tmp_path)
    ids = done[1]
    path = out / "runs" / f"{ids[0]}.json"
    rec = json.loads(path.read_text())
    rec.update(status="failed", reason="KilledWorker: the task died on 3 workers", metrics={})
    path.write_text(json.dumps(rec))
    spec = load_sweep(tmp_path / "s.toml")
    res = run_sweep(spec, out, scheduler=cluster.scheduler_address, run_fn=dry_run, resume=True,
                    plots=False, retry_failed=retry)
    again = json.loads(path.read_text())
    if retry is False:
        assert res.executed == 0 and again["status"] == "failed"
    else:  # None: on by default with resume
        assert res.executed == 1 and again["status"] == "completed"


@pytest.mark.timeout(60)
@pytest.mark.parametrize("how", [how for how, _, _ in SEMANTIC])
def test_a_record_that_makes_no_sense_is_never_aggregated(done, tmp_path: Path, how: str) -> None:
    from tsmpc.sweep import aggregate

    out = _copy(done, tmp_path)
    victim = done[1][1]
    _spoil(out / "runs" / f"{victim}.json", how, victim)
    params = {t.id: t.params.model_dump(mode="json") for t in expand(load_sweep(tmp_path / "s.toml"))}
    table = aggregate(out, {i: params[i] for i in done[1]})
    assert victim not in set(table["id"]) and len(table) == 3
    table.to_parquet(tmp_path / "t.parquet")  # the types stay uniform


@pytest.mark.timeout(120)
def test_without_resume_a_folder_with_records_is_refused_even_if_they_are_unreadable(
        done, tmp_path: Path, cluster) -> None:
    out = _copy(done, tmp_path)
    _spoil(out / "runs" / f"{done[1][0]}.json", "garbage", done[1][0])
    with pytest.raises(ConfigError, match="--resume"):
        run_sweep(load_sweep(tmp_path / "s.toml"), out, scheduler=cluster.scheduler_address,
                  run_fn=dry_run, plots=False)


@pytest.mark.timeout(60)
def test_aggregation_skips_an_unreadable_record_instead_of_crashing(done, tmp_path: Path) -> None:
    from tsmpc.sweep import aggregate

    out = _copy(done, tmp_path)
    _spoil(out / "runs" / f"{done[1][2]}.json", "list", done[1][2])
    assert len(aggregate(out, done[1])) == 3


@pytest.mark.timeout(120)
def test_a_base_config_without_a_design_writes_nothing(tmp_path: Path) -> None:
    """The base config's designs are solved before any file: an infeasible one exits 2 naming
    the field, and neither sweep.json nor runs/ nor the folder exists."""
    from typer.testing import CliRunner

    from tsmpc.cli import app

    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP + "[config.kinematic_lmi]\nR = [1e8, 1e8]\n")
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sweep", str(sweep), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "kinematic_lmi.R" in res.output and "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.timeout(60)
def test_run_sweep_writes_nothing_when_the_design_fails(tmp_path: Path, cluster) -> None:
    spec = load_sweep(_write(tmp_path, SWEEP))

    def broken(_cfg):
        raise ConfigError("base config: no certified kinematic LMI design (test)")

    with pytest.raises(ConfigError, match="no certified"):
        run_sweep(spec, tmp_path / "out", scheduler=cluster.scheduler_address, plots=False,
                  design_fn=broken)
    assert not (tmp_path / "out" / "sweep.json").exists()
    assert not (tmp_path / "out" / "runs").exists()


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


@pytest.mark.timeout(60)
def test_a_scheduler_that_accepts_but_never_speaks_is_given_up_in_time() -> None:
    from tsmpc.sweep import connect

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(srv.accept()[0])  # accept, then say nothing
            except TimeoutError:
                continue
            except OSError:
                return

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    port = srv.getsockname()[1]
    t0 = time.monotonic()
    try:
        with pytest.raises(ConfigError, match="no scheduler answered"):
            connect(f"tcp://127.0.0.1:{port}", 1, timeout=2.0)
    finally:
        stop.set()
        srv.close()
        for c in held:
            c.close()
    assert time.monotonic() - t0 < 10.0  # it held the client for ~60 s


# -- the outputs of a sweep: written together or not at all (issue 38) ------------------------
def _plotter(table, folder: Path, axes) -> list[Path]:
    files = []
    for name in ("by_seed.png", "solve_times.png"):
        (folder / name).write_bytes(b"png of %d rows" % len(table))
        files.append(folder / name)
    return files


def _failing(what: str):
    def fail(*_a, **_k):
        raise OSError(28, f"No space left on device ({what})")
    return fail


#: (how the second write goes wrong, the outputs left: "old" = the first write's, intact;
#: "none" = no output at all; "new" = the second write's, complete)
OUTPUT_FAILURES = [
    ("plotter-raises", "old"),
    ("parquet-refuses-the-table", "old"),
    ("csv-write-fails", "old"),
    ("move-fails-half-way", "none"),
    ("no-plots-this-time", "new"),
]


@pytest.mark.parametrize(("how", "left"), OUTPUT_FAILURES)
def test_a_sweeps_outputs_are_written_together_or_not_at_all(tmp_path: Path, monkeypatch,
                                                             how: str, left: str) -> None:
    import tsmpc.sweep as sw

    out = tmp_path / "out"
    out.mkdir()
    first = pd.DataFrame({"id": ["a", "b"], "rmse_y": [0.1, 0.2]})
    sw.write_outputs(first, out, plotter=_plotter)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"aggregate.csv", "aggregate.parquet", "by_seed.png", "solve_times.png"}
    second = pd.DataFrame({"id": ["a", "b", "c"], "rmse_y": [0.1, 0.2, 0.3]})
    plots, plotter = True, _plotter
    if how == "plotter-raises":
        plotter = _failing("plot")
    elif how == "parquet-refuses-the-table":
        second["rmse_y"] = [0.1, "oops", 0.3]
    elif how == "csv-write-fails":
        monkeypatch.setattr(sw, "atomic_write_text", _failing("csv"))
    elif how == "move-fails-half-way":
        real, calls = os.replace, []

        def replace(a, b):
            if Path(b).parent == out:  # a move into the folder (not a write into the stage)
                calls.append(b)
            if len(calls) == 2:
                raise OSError(28, "No space left on device")
            real(a, b)
        monkeypatch.setattr(sw.os, "replace", replace)
    elif how == "no-plots-this-time":
        plots = False
    if left == "new":
        files = sw.write_outputs(second, out, plots=plots, plotter=plotter)
        assert sorted(f.name for f in files) == ["aggregate.csv", "aggregate.parquet"]
    else:
        with pytest.raises(Exception):  # noqa: B017 -- whatever the failure, the outputs hold
            sw.write_outputs(second, out, plots=plots, plotter=plotter)
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    if left == "old":
        assert after == before
    elif left == "none":
        assert after == {}
    else:  # the plots of the first write are gone with it: nothing stale next to the new table
        assert set(after) == {"aggregate.csv", "aggregate.parquet"}
        assert pd.read_parquet(out / "aggregate.parquet").equals(second)
        assert pd.read_csv(out / "aggregate.csv").equals(second)
