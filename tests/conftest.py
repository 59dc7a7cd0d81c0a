"""Shared fixtures: the paper config and the data the tests read.

The paper's reference and the race tracks are never bundled: :func:`_paths.need_data` finds them
with tsmpc's resolver (``$TSMPC_DATA_DIR``, the cache filled by ``tsmpc data fetch``, then
``../shared/data`` beside the checkout). A test whose data is missing SKIPS, its reason naming the
fetch command; with ``TSMPC_REQUIRE_DATA=1`` (CI, which has ../shared) it FAILS instead, so CI
cannot go green by skipping.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _paths import need_data, tooling_on_path
from tsmpc.config import Config

tooling_on_path()  # the docs generator and the Table 5 study (docs/generator) for the tests

#: What the compile-once step said (the session header prints it).
_WARMUP: list[str] = []


def pytest_configure(config: pytest.Config) -> None:
    """Compile once per test run (issue 37): ``tsmpc warmup`` fills the kernel cache — the
    kernels, the run engine and the batch kernel, minutes from a cold cache — before any test
    starts. Without it the first tests to need a kernel compile it inside their own time limits,
    and with ``-n 2`` (pytest-xdist, the README's command) both workers would compile the same
    kernels at once. The xdist controller does it; its workers find the cache full."""
    if hasattr(config, "workerinput") or os.environ.get("TSMPC_NO_JIT"):
        return
    t0 = time.perf_counter()
    try:
        res = subprocess.run([sys.executable, "-m", "tsmpc", "warmup"], capture_output=True, text=True,
                             timeout=1800)
        said = (res.stdout.strip() or res.stderr.strip()).splitlines()[-1:] or ["(nothing)"]
        _WARMUP.append(f"compile once: `tsmpc warmup` exit {res.returncode} in "
                       f"{time.perf_counter() - t0:.0f} s: {said[0]}")
    except (OSError, subprocess.TimeoutExpired) as err:  # the tests then compile as they go
        _WARMUP.append(f"compile once: `tsmpc warmup` failed ({type(err).__name__})")


def pytest_report_header(config: pytest.Config) -> list[str]:
    return list(_WARMUP)


@pytest.fixture(scope="session")
def cfg() -> Config:
    return Config()


@pytest.fixture(scope="session")
def paper_reference_path() -> Path:
    return need_data("paper")


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    return need_data("tracks")
