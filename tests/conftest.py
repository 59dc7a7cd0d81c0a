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
#: the batch kernel side by side (measured cold at load 7: 26, 42 and 114 s of CPU). The tests
#: start once the engine is compiled; the batch kernel goes on compiling beside them (a test that
#: needs it before it is cached waits on its compile lock, tsmpc.kernels.compile_lock).
_WARM_KERNELS = "from tsmpc import kernels; assert kernels.warmup()[0]"
_WARM_ENGINE = "from tsmpc.sim import engine; assert engine.warmup()"
_WARM_BATCH = "from tsmpc.sim import batch; batch.warmup()"
#: The batch kernel's compile, running beside the tests: (process, start time), and how it ended.
_BACKGROUND: list[tuple[subprocess.Popen[str], float]] = []
_BATCH_NOTE: list[str] = []


def _start(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _failed(code: str, p: subprocess.Popen[str], timeout: float | None = 1800) -> str | None:
    """What failed (None: compiled) once ``p``, running ``code``, has ended."""
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        err = "timed out"
    if p.returncode != 0:
        return f"{code.split(';')[0]}: {(err.strip().splitlines() or ['?'])[-1]}"
    return None


def pytest_configure(config: pytest.Config) -> None:
    """Compile once per test run (issue 37): the kernels, the run engine and the batch kernel —
    minutes from a cold cache — fill the kernel cache before the tests that need them. Without it
    the first tests to need a kernel compile it inside their own time limits, and with ``-n auto``
    (pytest-xdist, the README's command) the workers would compile the same kernels at once.
    The xdist controller does it; its workers find the cache full (the batch kernel: full, or
    being filled by the process holding its compile lock)."""
    if hasattr(config, "workerinput") or os.environ.get("TSMPC_NO_JIT"):
        return
    t0 = time.perf_counter()
    try:
        failed = [f for f in [_failed(_WARM_KERNELS, _start(_WARM_KERNELS))] if f]
        if not failed:
            batch = _start(_WARM_BATCH)
            _BACKGROUND.append((batch, t0))
            failed = [f for f in [_failed(_WARM_ENGINE, _start(_WARM_ENGINE))] if f]
    except OSError as err:  # the tests then compile as they go
        failed = [f"{type(err).__name__}: {err}"]
    _WARMUP.append(f"compile once: kernels and run engine in {time.perf_counter() - t0:.0f} s"
                   + (f"; failed: {failed}" if failed else "; the batch kernel compiles beside the tests"))


def pytest_unconfigure(config: pytest.Config) -> None:
    """The batch kernel's compile: waited for when the session is over (a short selection of tests
    ends before it: it is stopped, and the next session compiles it; numba writes its cache
    entries whole, so none is left half-written)."""
    for p, _t0 in _BACKGROUND:
        if p.poll() is None:
            p.terminate()
        p.communicate()


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Say how the batch kernel's compile ended (in the session's last lines)."""
    for p, _t0 in _BACKGROUND:
        if p.poll() is None:
            _BATCH_NOTE.append("compile once: the batch kernel was still compiling at the end: stopped")
        else:
            msg = _failed(_WARM_BATCH, p, timeout=None)
            _BATCH_NOTE.append("compile once: the batch kernel compiled beside the tests" if msg is None
                               else f"compile once: the batch kernel failed: {msg}")


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
    workers to the controller with each report. Then how the batch kernel's compile ended."""
    for line in _BATCH_NOTE:
        terminalreporter.write_line(line)
    for key in ("passed", "failed"):
        for rep in terminalreporter.stats.get(key, ()):
            for name, text in getattr(rep, "user_properties", ()):
                if name == "terminal_summary" and getattr(rep, "when", "call") == "call":
                    terminalreporter.write_sep("-", rep.nodeid)
                    terminalreporter.write_line(str(text))
