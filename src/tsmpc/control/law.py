"""What a guidance law returns (issue 26): the outer loop's :class:`~tsmpc.control.ts_mpc.MPCResult`
of a law that evaluates a formula instead of solving an optimisation — pure pursuit, Stanley, the
kinematic LQR (:mod:`tsmpc.control.baselines` lists them).

A law reports status OPTIMAL (the law was evaluated), cost NaN and no prediction: ``x_pred[0]`` is
the current errors and rows 1…N are NaN; ``u_pred`` holds u over the horizon.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from tsmpc.control.ts_mpc import MPCResult, MPCStatus

__all__ = ["law_result"]


def law_result(
    x0: NDArray[np.float64], u: NDArray[np.float64], u_prev: NDArray[np.float64], N: int, t0: float,
    n_clipped: int = 0,
) -> MPCResult:
    """The :class:`MPCResult` of a guidance law evaluated at errors ``x0``: first move ``u``, held
    over the horizon, no prediction (rows 1…N of ``x_pred`` NaN); ``t0`` is the step's start
    (perf_counter)."""
    x_pred = np.full((N + 1, 3), np.nan)
    x_pred[0] = x0
    u_pred = np.tile(u, (N, 1))
    du = np.zeros((N, 2))
    du[0] = u - u_prev
    return MPCResult(u=np.array(u, dtype=float), x_pred=x_pred, u_pred=u_pred, du=du,
                     cost=float("nan"), status=MPCStatus.OPTIMAL, iterations=0, qp_iterations=0,
                     solve_time_s=time.perf_counter() - t0, n_clipped=n_clipped)
