"""The outer-loop baselines users pick instead of TS-MPC (issue 26), in the same cascade: same
inner loop (TS-LQR), same MHE-UIO, same plant, same errors — only the guidance law differs.

==============  ==========================================  ======================================
method          module                                      what
==============  ==========================================  ======================================
PURE_PURSUIT    :mod:`tsmpc.control.pure_pursuit`           arc to a look-ahead point, L_d ∝ v
STANLEY         :mod:`tsmpc.control.stanley`                front-axle heading + cross-track law
LQR             :mod:`tsmpc.control.kinematic_lqr`          u = r + Σ μ_i K_i x, the kinematic
                                                            LMI design's gains, no constraints
LTV             :mod:`tsmpc.control.ltv_mpc`                the TS-MPC's QP with the model
                                                            linearised along the reference
==============  ==========================================  ======================================

Every baseline speaks the outer MPC's protocol: ``dt``, ``reset()`` and
``step(errors, u_prev, window) -> MPCResult`` with ``u = [v_ref, ω_ref]``; non-finite inputs
give the shared fallback (:func:`tsmpc.control.ts_mpc.shifted_plan`), nothing raises.
A law (no optimisation) reports status OPTIMAL (the law was evaluated), cost NaN, and no
prediction: ``x_pred[0]`` is the current errors and rows 1…N are NaN; ``u_pred`` holds u
(:func:`tsmpc.control.law.law_result`).

This module is the registry: it imports the laws, the laws never import it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, Method
from tsmpc.control.law import law_result  # (re-exported: its home is below the laws)

__all__ = ["BASELINES", "build_baseline", "law_result"]

#: The baseline methods (each a :class:`~tsmpc.config.Method`).
BASELINES = (Method.PURE_PURSUIT, Method.STANLEY, Method.LQR, Method.LTV)


def build_baseline(
    cfg: Config, method: Method, P: NDArray[np.float64], S: NDArray[np.float64],
    K: NDArray[np.float64] | None,
) -> Any:
    """The outer controller of baseline ``method`` for ``cfg`` (P, S, K: the kinematic design's
    terminal cost, terminal set and vertex gains)."""
    from tsmpc.models.kinematic import KinematicTS

    model = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    if method == Method.PURE_PURSUIT:
        from tsmpc.control.pure_pursuit import PurePursuit

        return PurePursuit(cfg.baselines.pure_pursuit, cfg.mpc, cfg.rates.Tc,
                           along_track_gain=cfg.baselines.along_track_gain)
    if method == Method.STANLEY:
        from tsmpc.control.stanley import Stanley

        return Stanley(cfg.baselines.stanley, cfg.mpc, cfg.rates.Tc, cfg.vehicle,
                       delta_max=cfg.lqr.delta_max, along_track_gain=cfg.baselines.along_track_gain)
    if method == Method.LQR:
        if K is None:
            from tsmpc.errors import ConfigError

            raise ConfigError("the kinematic LQR needs the kinematic design's vertex gains K")
        from tsmpc.control.kinematic_lqr import KinematicLQR

        return KinematicLQR(cfg.mpc, model, K)
    if method == Method.LTV:
        from tsmpc.control.ltv_mpc import LTVMPC

        return LTVMPC(cfg.mpc, model, P, S)
    from tsmpc.errors import ConfigError

    raise ConfigError(f"{method} is not a baseline; baselines: "
                      f"{', '.join(m.value.lower() for m in BASELINES)}")
