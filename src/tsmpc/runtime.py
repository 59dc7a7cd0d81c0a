"""The stepping protocol every online block speaks (blocks do not log): a sample time ``dt`` [s] and
``reset()``, and a ``step(...)`` that returns a typed, frozen result and never raises on bad
data (failures are statuses in the result, counted by the caller).

=====================================  =========  ==================================================
block                                  ``dt``     ``step`` → result
=====================================  =========  ==================================================
:class:`tsmpc.control.ts_mpc.TSMPC`     T_c        ``step(errors, u_prev, reference)`` → ``MPCResult``
:class:`tsmpc.control.nl_mpc.NLMPC`     T_c        same signature → ``MPCResult``
:class:`tsmpc.estimation.mhe_uio.MHEUIO`  T_d      ``step(y, u)`` → ``Estimate``
:class:`tsmpc.control.ts_lqr.TSLQR`     T_d        ``step(estimate, v_ref, ω_ref)`` → ``InnerCommand``
:class:`tsmpc.control.cascade.Cascade`  T_d        ``step(t, Measurement)`` → ``Command``
=====================================  =========  ==================================================

Plants are driven, not sampled: :class:`tsmpc.sim.plant.Plant` takes the step length as an
argument (``step(u, dt, mu_road)``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["RuntimeBlock"]


@runtime_checkable
class RuntimeBlock(Protocol):
    """An online block: its sample time and a reset (``step`` signatures are per block)."""

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        ...

    def reset(self) -> None:
        """Back to the initial state (no history)."""
        ...
