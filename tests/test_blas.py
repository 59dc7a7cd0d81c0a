"""One BLAS thread for simulating processes (tsmpc.blas), overridable by TSMPC_BLAS_THREADS."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tsmpc.blas import blas_threads_setting

threadpoolctl = pytest.importorskip("threadpoolctl")


def test_setting_parses_the_environment(monkeypatch) -> None:
    monkeypatch.setattr("tsmpc.blas.cores", lambda: 8)  # the cap at the core count: tested elsewhere
    monkeypatch.delenv("TSMPC_BLAS_THREADS", raising=False)
    assert blas_threads_setting() == 1
    monkeypatch.setenv("TSMPC_BLAS_THREADS", "3")
    assert blas_threads_setting() == 3
    monkeypatch.setenv("TSMPC_BLAS_THREADS", "default")
    assert blas_threads_setting() is None
    monkeypatch.setenv("TSMPC_BLAS_THREADS", "many")  # unreadable: the safe default
    assert blas_threads_setting() == 1


_PROBE = """
import numpy, threadpoolctl
from tsmpc.blas import limit_blas_threads
limit_blas_threads()
print(max([i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"] or [0]))
"""


@pytest.mark.parametrize(("env", "expected"), [({}, "1"), ({"TSMPC_BLAS_THREADS": "2"}, "2")])
def test_a_simulating_process_gets_one_blas_thread(env: dict, expected: str, monkeypatch) -> None:
    import os

    base = {k: v for k, v in os.environ.items()
            if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    base["OPENBLAS_NUM_THREADS"] = "2"  # as if the library had started with 2 threads
    out = subprocess.run([sys.executable, "-c", _PROBE], env={**base, **env}, capture_output=True,
                         text=True, check=True)
    if out.stdout.strip() == "0":
        pytest.skip("no BLAS library visible to threadpoolctl")
    assert out.stdout.strip() == expected


def test_simulate_limits_blas_to_one_thread(cfg, monkeypatch) -> None:
    from tsmpc import blas
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.simulator import simulate

    monkeypatch.delenv("TSMPC_BLAS_THREADS", raising=False)
    monkeypatch.setattr(blas, "_APPLIED", None)  # as in a fresh process
    calls = []
    real = blas.limit_blas_threads
    monkeypatch.setattr(blas, "limit_blas_threads", lambda *a: calls.append(a) or real(*a))
    simulate(cfg, "REF", load_scenario(cfg), max_steps=2)
    assert calls and blas._APPLIED == 1
    info = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    assert all(i["num_threads"] == 1 for i in info)
