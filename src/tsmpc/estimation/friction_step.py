"""Friction step: let the compensated friction estimate follow a sudden change of the road.

The MHE's friction force is constant over its window (:mod:`tsmpc.estimation.mhe_uio`), so after a
step of the road resistance — grip lost at once, μ 0.9 → 0.3 — the compensated F̂ follows only as
the window (N T_d = 0.3 s) fills with samples after the step. On a road that has just lost its grip
that is too slow: the force that was holding the speed against the old resistance becomes traction
the low-grip rear tyre cannot transmit, and the car spins within a few tenths of a second. The
paper's one-step UIO formula (P-disturb_estimation, ``F_fr_raw``) sees the step within one sample,
but carries the speed sensor's noise amplified by M / T_d (σ ≈ 340 N) into the force at every step.

:class:`FrictionStep` keeps the window fit and uses the one-step estimate as a change detector
(beyond the paper, switch ``lqr.friction_step``). In quiet operation it tracks the variance σ² of
the innovation d = F_raw − F̂_window (exponential memory; outliers beyond 3 σ left out) and runs a
two-sided CUSUM test on z = d / σ: g⁺ = max(0, g⁺ + z − k), g⁻ = max(0, g⁻ − z − k), drift k = 1.
When g⁺ or g⁻ exceeds ``threshold`` h (5 by default) the friction force has stepped: from then on
the one-step estimate itself is compensated (the paper's UIO formula, which follows a step within a
sample) until the window holds only samples after the step and its own fit takes over. A shift of
2.5 σ is declared on the fourth sample; after μ 0.9 → 0.3 mid-corner the first samples are only
about that far off, because the sliding rear tyre caps the acceleration the estimate sees. Under
Gaussian noise the test's
in-control run length is ≈ 5.7·10⁴ samples (Siegmund's approximation; ≈ 9 min at 100 Hz); a false
alarm costs one window (0.3 s) of the one-step estimate's noise on the force.

Measured in docs/mismatch.md (mu_step) and in the README's ablation (the paper scenario's ice
patch, μ = 0.1 for 0.1 s at 70 s, is such a step and its end another).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from tsmpc.kernels.jit import jitable

__all__ = ["FrictionStep", "FrictionStepParams", "FrictionStepState", "friction_step_update"]

#: Samples of innovation needed before the detector may fire (its variance is unknown before).
MIN_SAMPLES = 50
#: Memory of the innovation variance [samples] (exponential forgetting after the first ones).
VARIANCE_MEMORY = 500
#: CUSUM drift k per sample [innovation standard deviations]: shifts below k σ never accumulate.
DRIFT = 1.0
#: An innovation beyond this many σ that does not (yet) declare a step stays out of the variance.
OUTLIER = 3.0


class FrictionStepParams(NamedTuple):
    """Parameters of the detector.

    Attributes:
        window: the MHE's horizon N [samples]: after a detected step the one-step estimate is
            compensated for this many samples, then the window fit again.
        threshold: CUSUM decision threshold h [innovation standard deviations].
    """

    window: int
    threshold: float


class FrictionStepState(NamedTuple):
    """State of the detector (all zero at the start).

    Attributes:
        var: innovation variance σ² [N²].
        n_var: samples in it.
        g_plus: CUSUM statistic of an upward step.
        g_minus: CUSUM statistic of a downward step.
        since: samples since a declared step (0: no step in progress).
    """

    var: float = 0.0
    n_var: int = 0
    g_plus: float = 0.0
    g_minus: float = 0.0
    since: int = 0


@jitable
def friction_step_update(p: FrictionStepParams, s: FrictionStepState, F_window: float, F_raw: float,
                         ok: bool) -> tuple[float, FrictionStepState, bool]:
    """One sample: (the friction force to compensate [N], the new state, a step was declared).

    ``F_window``: the MHE's window fit; ``F_raw``: its one-step UIO estimate (paper eq.
    "disturb_estimation"); ``ok``: the sample was accepted (a rejected or warm-up sample neither
    detects nor is compensated)."""
    var, n_var, gp, gm, since = s.var, s.n_var, s.g_plus, s.g_minus, s.since
    ok = ok and math.isfinite(F_raw) and math.isfinite(F_window)
    if since > 0:  # a step in progress: the window still holds samples before it
        since += 1
        if since > p.window:  # the window holds only samples after the step: its fit again
            since = 0
            gp = 0.0
            gm = 0.0
        F = F_raw if ok and since > 0 else F_window
        return F, FrictionStepState(var, n_var, gp, gm, since), False
    if not ok:
        return F_window, s, False
    d = F_raw - F_window
    if n_var >= MIN_SAMPLES:
        z = d / math.sqrt(var) if var > 0.0 else 0.0
        gp = max(0.0, gp + z - DRIFT)
        gm = max(0.0, gm - z - DRIFT)
        if gp > p.threshold or gm > p.threshold:
            return F_raw, FrictionStepState(var, n_var, gp, gm, 1), True
        if abs(z) > OUTLIER:  # an outlier does not inflate the variance
            return F_window, FrictionStepState(var, n_var, gp, gm, since), False
    n_var += 1
    var += (d * d - var) / min(n_var, VARIANCE_MEMORY)
    return F_window, FrictionStepState(var, n_var, gp, gm, since), False


class FrictionStep:
    """Change detector on the one-step friction estimate, applied to the MHE window fit (the
    online wrapper of :func:`friction_step_update`).

    Args:
        window: the MHE's horizon N [samples]: after a detected step, the one-step estimate is
            compensated for this many samples, then the window fit again.
        threshold: CUSUM decision threshold h, in innovation standard deviations.
    """

    def __init__(self, window: int, threshold: float = 5.0) -> None:
        if window < 1 or not threshold > 0.0:
            raise ValueError("FrictionStep needs window >= 1 and threshold > 0")
        self.window, self.threshold = int(window), float(threshold)
        self.params = FrictionStepParams(self.window, self.threshold)
        self.reset()

    def reset(self) -> None:
        """Forget the innovation statistics and any step in progress."""
        self.state = FrictionStepState()
        self.n_steps = 0  #: steps detected since the last reset

    @property
    def active(self) -> bool:
        """True while the compensated estimate is the one-step estimate after a detected step."""
        return self.state.since > 0

    def step(self, F_window: float, F_raw: float, ok: bool) -> float:
        """The friction force to compensate this sample [N] (see :func:`friction_step_update`)."""
        F, self.state, declared = friction_step_update(self.params, self.state, F_window, F_raw, ok)
        self.n_steps += declared
        return F
