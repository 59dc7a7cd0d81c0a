"""Shared fixtures: the paper config and the data the tests read.

The paper's reference and the race tracks are never bundled: :func:`_paths.need_data` finds them
with tsmpc's resolver (``$TSMPC_DATA_DIR``, the cache filled by ``tsmpc data fetch``, then
``../shared/data`` beside the checkout). A test whose data is missing SKIPS, its reason naming the
fetch command; with ``TSMPC_REQUIRE_DATA=1`` (CI, which has ../shared) it FAILS instead, so CI
cannot go green by skipping.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from _blocks import way  # noqa: F401  (fixture: a block test runs Python and compiled)
from _compile_once import STAGES, wait_for
from _paths import need_data, tooling_on_path
from tsmpc.config import Config

tooling_on_path()  # the docs generator and the Table 5 study (docs/generator) for the tests

#: The compile-once process (controller only) and its folder of marks (tests/_compile_once.py).
_COMPILE: dict[str, object] = {}
_WARM_ENV = "TSMPC_TEST_COMPILE_DIR"

#: The last compile step each test module needs, recorded by a run that logged, for every test,
#: each load of the kernels, the run engine and the batch kernel (in the test's process and in
#: the processes it starts). A module not listed needs none. The table orders and paces the
#: tests only: a module listed wrongly or not at all still gets what it needs (the product's
#: compile locks make a process wait for the one compiling), it may only wait inside its own
#: time limits. A module that copies the whole cache (test_hostile_env) waits for all of it.
_NEEDS: dict[str, str] = {
    **dict.fromkeys(
        ("test_blocks", "test_cascade_garbage", "test_dynamic", "test_fusion_blocks", "test_inner_loop",
         "test_install", "test_ltv_mpc", "test_mhe_robustness", "test_nl_mpc", "test_paper_as_run",
         "test_plant", "test_recovery", "test_resources", "test_signals", "test_ts_mpc",
         "test_vehicle_params"), "kernels"),
    **dict.fromkeys(
        ("test_actuators", "test_architecture", "test_baselines", "test_blas", "test_cascade",
         "test_comfort", "test_commonroad", "test_compare", "test_degraded", "test_divergence",
         "test_docs", "test_docs_generated", "test_engine", "test_experiment", "test_first_run",
         "test_friction_step", "test_fusion", "test_gyro_bias", "test_hostile_inputs",
         "test_hostile_results", "test_hostile_round3", "test_kernels", "test_lqr_block",
         "test_low_speed_resistance",
         "test_mismatch_acceptance", "test_newcomer", "test_outputs", "test_paper_acceptance",
         "test_paper_preset", "test_plan_feasibility", "test_race_envelope", "test_report",
         "test_robustness", "test_sensors", "test_slip_aware", "test_time_base"), "engine"),
    **dict.fromkeys(
        ("test_batch", "test_cluster", "test_cluster_lifecycle", "test_examples", "test_governor",
         "test_hostile_env", "test_hostile_outputs", "test_kernels_runtime", "test_mutation_guards",
         "test_sweep"), "batch"),
}
_RANK = {None: 0, **{s: i + 1 for i, s in enumerate(STAGES)}}


def _need(item: pytest.Item) -> str | None:
    return _NEEDS.get(Path(str(item.fspath)).stem)


def pytest_configure(config: pytest.Config) -> None:
    """Compile once per test run, beside the first tests (tests/_compile_once.py): the xdist
    controller (or a run without xdist) starts the compile process and goes on; its workers find
    the marks' folder in the environment they inherit."""
    if os.environ.get("TSMPC_NO_JIT"):
        return
    if hasattr(config, "workerinput"):  # an xdist worker: the controller started the compile
        if os.environ.get(_WARM_ENV):
            _yield_to_the_compile()
        return
    if _WARM_ENV in os.environ:  # a test run started by a test: its parent's compile serves it
        return
    folder = Path(tempfile.mkdtemp(prefix="tsmpc-compile-"))
    try:
        proc = subprocess.Popen([sys.executable, str(Path(__file__).with_name("_compile_once.py")),
                                 str(folder)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True)
    except OSError:  # the tests then compile as they go
        return
    (folder / "pid").write_text(str(proc.pid), encoding="utf-8")
    os.environ[_WARM_ENV] = str(folder)
    _COMPILE.update(proc=proc, folder=folder)
    if not config.getoption("numprocesses", None):  # no workers: this process runs the tests
        _yield_to_the_compile()


def _yield_to_the_compile() -> None:
    """Run the tests (this process and what it starts) at a lower priority than the compile
    process: it is the run's critical path (every test that needs compiled code waits for it), and
    beside two workers at equal priority it got a third of two cores (measured: 390 s instead of
    165 s for the three steps). At ``nice`` +5 against its 0 the scheduler gives it a core of its
    own; the workers share the other one until it is done, then both. Only raising our own
    niceness (allowed to any user; it cannot be lowered back), and by 5 only: on a machine busy
    with other jobs the tests still get a fair share."""
    with contextlib.suppress(OSError, AttributeError):
        os.nice(5)


def pytest_unconfigure(config: pytest.Config) -> None:
    proc = _COMPILE.get("proc")
    if isinstance(proc, subprocess.Popen) and proc.poll() is None:
        proc.kill()  # a run that needed no compiled code (e.g. -k): nothing left to wait for
    if isinstance(proc, subprocess.Popen):
        proc.communicate()
    folder = _COMPILE.get("folder")
    if isinstance(folder, Path):
        shutil.rmtree(folder, ignore_errors=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order the tests so that every worker starts with those that need no compiled code, then
    those that need the kernels, the engine, the batch kernel (pytest-xdist's worksteal gives each
    worker a contiguous share of this order). Every worker collects alike: the order depends only
    on the collection and the worker count."""
    if os.environ.get("TSMPC_NO_JIT"):
        return
    n = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    groups: list[list[pytest.Item]] = [[] for _ in _RANK]
    for it in items:
        groups[_RANK[_need(it)]].append(it)
    shares: list[list[pytest.Item]] = [[] for _ in range(n)]
    for g in groups:
        for i in range(n):
            shares[i].extend(g[i * len(g) // n:(i + 1) * len(g) // n])
    items[:] = [it for share in shares for it in share]


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """A test that needs a compile step waits for it here, outside its time limits (outermost:
    before pytest-timeout's timer starts)."""
    folder, stage = os.environ.get(_WARM_ENV), _need(item)
    if folder and stage and not os.environ.get("TSMPC_NO_JIT"):
        why = wait_for(Path(folder), stage)
        if why and not _COMPILE.get("said"):
            _COMPILE["said"] = True
            sys.stderr.write(f"compile once: {why}; the tests compile what they need\n")
    yield


def pytest_report_header(config: pytest.Config) -> list[str]:
    if "folder" in _COMPILE:
        return ["compile once: the kernels, the run engine and the batch kernel, beside the tests "
                "that need no compiled code (tests/_compile_once.py)"]
    return []


def _compile_summary() -> str | None:
    folder = _COMPILE.get("folder")
    if not isinstance(folder, Path):
        return None
    parts = [f"{s} {(folder / f'{s}.done').read_text(encoding='utf-8')} s" for s in STAGES
             if (folder / f"{s}.done").exists()]
    failed = folder / "failed"
    tail = f"; failed: {failed.read_text(encoding='utf-8')}" if failed.exists() else ""
    return "compile once (beside the first tests): " + (", ".join(parts) or "nothing") + tail


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
    line = _compile_summary()
    if line:
        terminalreporter.write_line(line)
    for key in ("passed", "failed"):
        for rep in terminalreporter.stats.get(key, ()):
            for name, text in getattr(rep, "user_properties", ()):
                if name == "terminal_summary" and getattr(rep, "when", "call") == "call":
                    terminalreporter.write_sep("-", rep.nodeid)
                    terminalreporter.write_line(str(text))
