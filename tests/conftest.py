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


#: The compile-once steps: the kernels first (the other two call them), then the run engine and
#: the batch kernel side by side (measured cold at load 7: 26, 42 and 114 s of CPU).
_WARM_STEPS = ("from tsmpc import kernels; assert kernels.warmup()[0]",
               ("from tsmpc.sim import engine; assert engine.warmup()",
                "from tsmpc.sim import batch; batch.warmup()"))


def _warm(codes: tuple[str, ...]) -> list[str]:
    """Run the compile steps ``codes`` side by side; what failed (empty: all compiled)."""
    procs = [subprocess.Popen([sys.executable, "-c", c], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for c in codes]
    failed = []
    for c, p in zip(codes, procs, strict=True):
        try:
            _, err = p.communicate(timeout=1800)
        except subprocess.TimeoutExpired:
            p.kill()
            err = "timed out"
        if p.returncode != 0:
            failed.append(f"{c.split(';')[0]}: {(err.strip().splitlines() or ['?'])[-1]}")
    return failed


def pytest_configure(config: pytest.Config) -> None:
    """Compile once per test run (issue 37): the kernels, the run engine and the batch kernel —
    minutes from a cold cache — fill the kernel cache before any test starts. Without it the
    first tests to need a kernel compile it inside their own time limits, and with ``-n auto``
    (pytest-xdist, the README's command) the workers would compile the same kernels at once.
    The xdist controller does it; its workers find the cache full."""
    if hasattr(config, "workerinput") or os.environ.get("TSMPC_NO_JIT"):
        return
    t0 = time.perf_counter()
    try:
        failed = _warm((_WARM_STEPS[0],))
        if not failed:
            failed = _warm(_WARM_STEPS[1])
    except OSError as err:  # the tests then compile as they go
        failed = [f"{type(err).__name__}: {err}"]
    _WARMUP.append(f"compile once: kernels, run engine and batch kernel in "
                   f"{time.perf_counter() - t0:.0f} s" + (f"; failed: {failed}" if failed else ""))


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


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Print the ``terminal_summary`` properties tests recorded (``record_property``; e.g. the
    blocks' branch coverage, tests/test_block_coverage.py) in the session's summary, so CI's log
    shows them: pytest captures a test's output, and pytest-xdist carries user properties from its
    workers to the controller with each report."""
    for key in ("passed", "failed"):
        for rep in terminalreporter.stats.get(key, ()):
            for name, text in getattr(rep, "user_properties", ()):
                if name == "terminal_summary" and getattr(rep, "when", "call") == "call":
                    terminalreporter.write_sep("-", rep.nodeid)
                    terminalreporter.write_line(str(text))
