"""Built-in paper-like circuit (SPEC §10): the geometry facts of the paper's run."""

from __future__ import annotations

import time

import numpy as np

from tsmpc.planning.circuit import RUN_STEPS, builtin_circuit


def test_circuit_facts() -> None:
    t0 = time.perf_counter()
    ref = builtin_circuit()
    assert time.perf_counter() - t0 < 1.0  # ≈ 0.05 s; generous for a loaded CI machine
    assert ref.dt == 0.1 and not ref.closed
    run = ref.slice(0, RUN_STEPS)
    length = float(np.sum(np.hypot(np.diff(run.x), np.diff(run.y))))
    assert 1200 <= length <= 1350
    assert len(ref) >= RUN_STEPS + 45
    assert ref.v.max() <= 14.7 + 1e-6 and np.abs(ref.omega).max() <= 0.23
    assert abs(ref.theta[0]) < 0.01 and ref.x[0] == 0 and ref.y[0] == 0
    assert run.v[50] > 11.5 and run.v[:80].max() >= 12.7  # strong initial acceleration
    # Westbound at the end of the run, near (797…850, 408).
    assert abs(np.mod(run.theta[-1], 2 * np.pi) - np.pi) < 0.3
    assert 780 < run.x[-1] < 880 and abs(run.y[-1] - 408) < 15
    # A northbound segment near x ≈ 420 m, east again near y ≈ 300 m.
    north = np.abs(np.mod(run.theta, 2 * np.pi) - np.pi / 2) < 0.1
    assert np.any(north & (np.abs(run.x - 420) < 8) & (run.y > 100) & (run.y < 250))
    east = np.abs(np.mod(run.theta + np.pi, 2 * np.pi) - np.pi) < 0.1
    assert np.any(east & (np.abs(run.y - 300) < 10) & (run.x > 500))
