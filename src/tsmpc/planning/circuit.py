"""The built-in "paper-like circuit" (the paper's scenario), so the main job runs on a fresh machine.

Our own waypoints and speed caps, shaped after the facts the paper reports about its run (not its
data): an eastbound straight with a strong initial acceleration, an S-bend to a northbound segment
near x ≈ 420 m, east again near y ≈ 300 m (fast, up to 14.7 m/s), a slight right dip and a left
loop ending westbound near (797, 408). With the default :class:`~tsmpc.config.PlannerSettings`
the first 1272 samples (127.2 s at 0.1 s) cover ≈ 1.27 km and end westbound near (837, 408); the
path then continues west so that ≥ 4.5 s more remain for the MPC's N = 40 look-ahead.

The start reaches ≈ 11.9 m/s at 5 s and 12.8 m/s at ≈ 6 s: with a_lon = 2.6 m/s² from the
planner's v_start = 1 m/s and the jerk bound, 12.8 m/s in exactly 5 s is out of reach (the paper's
planner accelerates harder); raise ``a_lon_max`` to get closer.
"""

from __future__ import annotations

import numpy as np

from tsmpc.config import PlannerSettings
from tsmpc.planning.planner import plan_path
from tsmpc.planning.reference import Reference

__all__ = ["CIRCUIT_OMEGA_MAX", "CIRCUIT_WAYPOINTS", "RUN_STEPS", "builtin_circuit"]

#: (x [m], y [m], speed cap [m/s] on the stretch to the next point), in driving order. The caps
#: shape the speed like the paper's run (fast straights, slower S-bend and loop) so that the run
#: lasts ≈ 127 s; the planner's limits still apply on top of them.
CIRCUIT_WAYPOINTS = np.array([
    (0, 0, 12.8), (100, 0, 10.3), (200, 0, 10.3), (300, 0, 11.8), (345, 8, 11.8), (385, 32, 11.8),
    (410, 68, 11.4), (420, 110, 8.1), (422, 150, 8.1), (422, 190, 8.5), (426, 226, 10.3),
    (442, 256, 14.7), (470, 278, 14.7), (510, 292, 14.7), (560, 298, 13.0), (620, 299, 9.3),
    (680, 297, 8.9), (720, 290, 8.9), (760, 276, 8.9), (795, 264, 8.7), (830, 259, 8.7),
    (865, 267, 9.3), (893, 290, 9.3), (906, 328, 9.3), (900, 368, 9.3), (876, 397, 9.3),
    (840, 408, 10.3), (797, 410, 11.4), (740, 410, 11.4),
], dtype=float)

#: Yaw-rate limit of the circuit [rad/s] (the paper's run stays within 0.23 rad/s).
CIRCUIT_OMEGA_MAX = 0.22

#: MPC steps of the paper's run (127.2 s at T_c = 0.1 s).
RUN_STEPS = 1272

#: Look-ahead appended after the end of the path [s], on top of the path's westbound run-out.
TAIL_S = 2.0


def builtin_circuit(settings: PlannerSettings | None = None, dt: float = 0.1) -> Reference:
    """Plan the paper-like circuit (the paper's scenario) with ``settings`` (default ``PlannerSettings()``).

    Returns an open :class:`Reference` sampled at ``dt``; at dt = 0.1 s it has ≥ RUN_STEPS + 45
    samples. Cheap (≈ 0.05 s).
    """
    return plan_path(CIRCUIT_WAYPOINTS[:, :2], settings or PlannerSettings(), dt=dt, tail_s=TAIL_S,
                     omega_max=CIRCUIT_OMEGA_MAX, v_cap=CIRCUIT_WAYPOINTS[:, 2])
