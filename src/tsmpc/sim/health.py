"""Is a completed run's result trustworthy? (issue 24: no successful-looking wrong results.)

A run can reach its end (no divergence) while its controller did not work: every MPC step fell
back to the shifted previous plan, or the estimator failed at nearly every step. Such a result is
not a result; :func:`health_problem` says so from the run's metrics (the ``events`` counters of
:mod:`tsmpc.control.cascade` and the step counts), and the CLI and the sweeps report the run as
failed instead of completed.
"""

from __future__ import annotations

from typing import Any

__all__ = ["MAX_FALLBACK_SHARE", "MAX_MHE_FAILED_SHARE", "MAX_SOFT_SHARE", "health_problem"]

#: Largest share of MPC steps that may return the shifted previous plan.
MAX_FALLBACK_SHARE = 0.2
#: Largest share of MPC steps that may solve only the softened problem (start-up transients and
#: ice patches soften a few per cent).
MAX_SOFT_SHARE = 0.5
#: Largest share of inner steps whose MHE solve may fail.
MAX_MHE_FAILED_SHARE = 0.2


def health_problem(metrics: dict[str, Any]) -> str | None:
    """None when the run's controller worked; else one line saying what did not (for the
    metrics of one method, :func:`tsmpc.sim.metrics.compute_metrics`)."""
    ev = metrics.get("events") or {}
    outer = int(metrics.get("outer_steps") or 0)
    inner = int(metrics.get("inner_steps") or 0)
    checks = (("mpc_fallback", outer, MAX_FALLBACK_SHARE, "MPC steps fell back to the previous plan"),
              ("mpc_soft", outer, MAX_SOFT_SHARE, "MPC steps solved only the softened problem"),
              ("mhe_failed", inner, MAX_MHE_FAILED_SHARE, "estimator (MHE) solves failed"))
    for key, total, share, what in checks:
        n = int(ev.get(key, 0) or 0)
        if total >= 10 and n > share * total:
            return (f"{n} of {total} {what} (more than {share:.0%}): the result is not "
                    "trustworthy; check the weights, bounds and noise levels of the config")
    return None
