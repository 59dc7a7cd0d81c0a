"""The built-in "paper-like circuit" (SPEC §10), so the main job runs on a fresh machine.

Our own waypoints, shaped after the facts the paper reports about its run (not its data): a long
eastbound straight with a strong initial acceleration, an S-bend to a northbound segment near
x ≈ 420 m, east again near y ≈ 300 m, and a left loop ending westbound near (797, 408); ≈ 1.27 km
in ≈ 127 s, then enough straight to give the MPC its N-step look-ahead at the end.
"""

from __future__ import annotations

import numpy as np

from tsmpc.config import PlannerSettings
from tsmpc.planning.planner import plan_path
from tsmpc.planning.reference import Reference

__all__ = ["CIRCUIT_SETTINGS", "CIRCUIT_WAYPOINTS", "builtin_circuit"]

#: Waypoints [m] of the paper-like circuit, in driving order.
CIRCUIT_WAYPOINTS = np.array([
    [0.0, 0.0], [60.0, 0.0], [140.0, 0.0], [220.0, 0.0], [290.0, 0.0], [340.0, 5.0],
    [378.0, 25.0], [403.0, 58.0], [416.0, 98.0], [421.0, 140.0], [422.0, 190.0], [424.0, 230.0],
    [434.0, 266.0], [458.0, 291.0], [495.0, 300.0], [550.0, 300.0], [610.0, 300.0],
    [670.0, 300.0], [720.0, 303.0], [768.0, 318.0], [806.0, 346.0], [822.0, 380.0],
    [812.0, 402.0], [797.0, 408.0], [770.0, 410.0], [730.0, 410.0], [690.0, 410.0], [650.0, 410.0],
])

#: Limits of the built-in circuit: gentler corners and top speed than the planner defaults, so the
#: lap lasts ≈ 127 s like the paper's run and |ω_d| stays ≤ 0.23 rad/s.
CIRCUIT_SETTINGS = PlannerSettings(v_max=11.5, a_lat_max=1.0)

#: Look-ahead appended after the run [s] (N = 40 steps at T_c = 0.1 s, plus margin).
TAIL_S = 5.0


def builtin_circuit(settings: PlannerSettings | None = None, dt: float = 0.1) -> Reference:
    """Plan the paper-like circuit with ``settings`` (default :data:`CIRCUIT_SETTINGS`)."""
    return plan_path(CIRCUIT_WAYPOINTS, settings or CIRCUIT_SETTINGS, dt=dt, tail_s=TAIL_S)
