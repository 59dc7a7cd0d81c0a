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
               "tsmpc.vehicle.plant, tsmpc.control.ts_lqr; print('numba' in sys.modules)")
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
