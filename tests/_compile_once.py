"""Compile once per test run, beside the first tests (issue 37: the README's test command within
10 minutes on 2 cores from a cold cache).

The kernels, the run engine and the batch kernel take minutes of CPU from a cold cache (measured
cold at load 1-4: 29, 47 and 48 s), most of it numba's type inference on one core. Compiled before any test
(as this suite first did), the machine's second core idles for that time; compiled inside the
tests, each worker compiles the same kernels. So the pytest controller starts this script as one
background process, which compiles the three in the order they build on each other and marks
each one done in a folder; meanwhile the workers run the tests that need no compiled code (the
suite is ordered so those come first on every worker, conftest.py), and a test that needs a step
waits for its mark before its time limits start. The product's own locks (``compile_lock``) make
a process that gets there first compile and the others wait, so nothing is compiled twice
whatever the order.

Usage: ``python _compile_once.py FOLDER`` (the starter writes its pid to ``FOLDER/pid``): writes
``FOLDER/<step>.done`` holding the step's seconds after each step, or ``FOLDER/failed`` naming the
step and the error.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

#: The steps, in the order they build on each other (the engine calls the kernels; the batch
#: kernel calls the engine's compiled run with two of its blocks deferred).
STAGES = ("kernels", "engine", "batch")

_CODE = {"kernels": "from tsmpc import kernels; assert kernels.warmup()[0], 'kernels off'",
         "engine": "from tsmpc.sim import engine; assert engine.warmup(), 'run engine off'",
         "batch": "from tsmpc.sim import batch; batch.warmup()"}


def wait_for(folder: Path, stage: str, limit_s: float = 1800.0) -> str | None:
    """Block until ``stage`` (and the steps before it) is compiled; None when it is, else why not
    (a step failed, the process died, or ``limit_s`` passed): the test then runs anyway and
    compiles what it needs itself, as it would without this script."""
    done, failed, pid_file = folder / f"{stage}.done", folder / "failed", folder / "pid"
    t0 = time.monotonic()
    while not done.exists():
        if failed.exists():
            return failed.read_text(encoding="utf-8")
        try:
            os.kill(int(pid_file.read_text(encoding="utf-8")), 0)
        except (OSError, ValueError):  # the process is gone (or never started) without a mark
            if not done.exists():
                return "the compile process ended without finishing"
        if time.monotonic() - t0 > limit_s:
            return f"not done after {limit_s:.0f} s"
        time.sleep(0.2)
    return None


def main(folder: Path) -> int:
    for stage in STAGES:
        t0 = time.perf_counter()
        try:
            exec(_CODE[stage], {})
        except BaseException as err:
            (folder / "failed").write_text(f"{stage}: {type(err).__name__}: {err}", encoding="utf-8")
            return 1
        tmp = folder / f".{stage}.tmp"  # written whole, then renamed: a reader never sees half
        tmp.write_text(f"{time.perf_counter() - t0:.0f}", encoding="utf-8")
        tmp.replace(folder / f"{stage}.done")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
