"""Two processes that need the same design at once solve it once (tsmpc.synthesis.cache's entry
lock): the second waits for the first and loads its cache entry (a sweep's workers starting
together; the test run's compile-once beside a test that needs the default designs)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: One process: wait for the go file, then load-or-solve the kinematic design of the default
#: config; each solve appends a line to the log and lasts at least 1 s (so that two processes
#: without the lock would both be inside it).
_PROCESS = """
import sys, time
from pathlib import Path
from tsmpc.config import Config
from tsmpc.synthesis import cache
folder = Path(sys.argv[1])
solve = cache.design_kinematic
def logged(*args, **kwargs):
    with open(folder / "solves.log", "a") as f:
        f.write("solve\\n")
    time.sleep(1.0)
    return solve(*args, **kwargs)
cache.design_kinematic = logged
(folder / f"ready-{sys.argv[2]}").touch()
while not (folder / "go").exists():
    time.sleep(0.01)
d = cache.load_or_design_kinematic(Config(), folder / "cache")
print(repr(d.K.tolist()))
"""


@pytest.mark.timeout(300)
def test_two_processes_needing_the_same_design_solve_it_once(tmp_path: Path) -> None:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    procs = [subprocess.Popen([sys.executable, "-c", _PROCESS, str(tmp_path), str(i)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    deadline = time.monotonic() + 120
    while not all((tmp_path / f"ready-{i}").exists() for i in range(2)):
        assert time.monotonic() < deadline and all(p.poll() is None for p in procs), \
            [p.communicate() for p in procs if p.poll() is not None]
        time.sleep(0.01)
    (tmp_path / "go").touch()  # both start to load-or-solve now
    outs = [p.communicate(timeout=240) for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    assert (tmp_path / "solves.log").read_text().count("solve") == 1
    assert outs[0][0] == outs[1][0]  # the second process loaded the first one's design
