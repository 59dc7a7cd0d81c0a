"""The kernels' runtime contract: numba only in simulating code, a cache next to the design cache,
the first-compile status line, ``tsmpc warmup``, the TSMPC_NO_JIT switch."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

from tsmpc import kernels
from tsmpc.cli import app

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    full = {**os.environ, "PYTHONPATH": SRC, **env}
    return subprocess.run([sys.executable, "-c", code], env=full, capture_output=True, text=True,
                          check=True)


def test_numba_is_not_imported_by_import_tsmpc_or_the_cli() -> None:
    out = _run("import sys, tsmpc, tsmpc.cli, tsmpc.control.ts_mpc, tsmpc.estimation.mhe_uio, "
               "tsmpc.vehicle.plant, tsmpc.envelope, tsmpc.models.dynamic; print('numba' in sys.modules)")
    assert out.stdout.strip() == "False"


def test_cache_directory_is_next_to_the_design_cache(monkeypatch, tmp_path) -> None:
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path))
    assert kernels.numba_cache_dir() == tmp_path / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))  # the user's choice wins
    assert kernels.numba_cache_dir() == tmp_path / "elsewhere"


def test_cold_cache_is_detected(tmp_path) -> None:
    assert kernels._cold(tmp_path)  # empty: the first run compiles and says so
    assert kernels.load("mpc") is not None
    assert not kernels._cold(kernels.numba_cache_dir())  # this process's cache is complete


def test_warmup_command_and_the_switch(monkeypatch) -> None:
    res = CliRunner().invoke(app, ["warmup"])
    assert res.exit_code == 0 and "kernels and run engine ready" in res.output
    monkeypatch.setenv("TSMPC_NO_JIT", "1")
    assert not kernels.enabled() and kernels.load("mhe") is None
    res = CliRunner().invoke(app, ["warmup"])
    assert res.exit_code == 0 and "switched off" in res.output


_TAKE = "from tsmpc import kernels\nwith kernels.compile_lock('{}'): pass"
_HOLDER = """
import sys, time
from tsmpc import kernels
with kernels.compile_lock("batch"):
    print("holding", flush=True)
    time.sleep(float(sys.argv[1]))
"""


def test_a_second_process_waits_for_the_one_compiling(tmp_path: Path) -> None:
    """``compile_lock``: while one process holds a kernel's lock (compiling it), another that
    needs the same kernel waits for it, then goes on (loading what the first cached); a
    different kernel's lock does not wait; a process that dies releases it."""
    import time

    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path)}
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, "8"], env=env, stdout=subprocess.PIPE,
                              text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "holding"
    t0 = time.perf_counter()
    _run(_TAKE.format("engine"), NUMBA_CACHE_DIR=str(tmp_path))
    other = time.perf_counter() - t0
    _run(_TAKE.format("batch"), NUMBA_CACHE_DIR=str(tmp_path))
    waited = time.perf_counter() - t0
    holder.wait(timeout=30)
    assert other < 6.0 and waited > 7.0, (other, waited)  # (held 8 s from "holding" on)
    killed = subprocess.Popen([sys.executable, "-c", _HOLDER, "60"], env=env, stdout=subprocess.PIPE,
                              text=True)
    assert killed.stdout is not None and killed.stdout.readline().strip() == "holding"
    killed.kill()
    killed.wait(timeout=30)
    t0 = time.perf_counter()
    _run(_TAKE.format("batch"), NUMBA_CACHE_DIR=str(tmp_path))
    assert time.perf_counter() - t0 < 5.0


def test_the_compile_lock_is_no_lock_where_the_cache_cannot_hold_one(tmp_path: Path, monkeypatch) -> None:
    """A cache folder that cannot be created (a file in the way): the lock is a no-op, not an error
    (the kernels then compile in each process, as numba alone does)."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker / "sub"))
    with kernels.compile_lock("batch"):
        pass


def test_a_fifo_or_a_link_in_place_of_the_lock_file_is_no_lock(tmp_path: Path, monkeypatch) -> None:
    """The lock file is a regular file of the cache or nothing: a FIFO at its path neither blocks
    nor is used, a symbolic link is not followed (its target is not created)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernels._tree_folder(tmp_path)
    folder.mkdir(parents=True)
    os.mkfifo(folder / "batch.lock")
    (folder / "engine.lock").symlink_to(tmp_path / "elsewhere")
    with kernels.compile_lock("batch"), kernels.compile_lock("engine"):
        pass
    assert not (tmp_path / "elsewhere").exists()
