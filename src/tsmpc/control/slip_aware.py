"""Slip-aware outer loop (beyond the paper; issue 15): the kinematic error model in the frame of
the velocity, not of the body.

The paper's kinematic error model takes the body heading θ as the direction of travel,
but the car moves along θ + α (the plant: Ẋ = v cos(θ+α), Ẏ = v sin(θ+α)). Differentiating the
body-frame lateral error gives ė_y = −ω e_x + v_d sin e_θ − v sin α: the term −v sin α is missing
from the model, so in a long corner the MPC needs a steady heading error e_θ ≈ α to hold e_y,
and its heavy e_θ weight trades it for a lateral offset to the outside (0.5 m at 14.7 m/s).

Here the same model is fed the errors of the *velocity* pose (X, Y, θ + α̂), with α̂ the MHE's
body-slip estimate: with heading θ_v = θ + α the model's equations hold exactly, its "ω" being
θ̇_v = ω + α̇ (= ω in a steady corner). This is a transformation of the measured state that
reaches the MPC — the TS model, its scheduling box and the LMI certificates are unchanged
(e_θ,v stays inside the box's e_θ range as long as the body-frame one did plus |α|).

α̂ comes from a model (the MHE's dynamic model); with a plant the model does not describe (a
foreign or kinematic vehicle) it can be biased by 0.1 rad, and through the MPC's light e_y weight
every milliradian of heading bias costs ≈ 14 mm of lateral offset. :class:`SlipGate` therefore
bounds α̂ by a model-free measurement, the course over ground of the measured positions over a
few MPC steps: the chord's direction is the mean velocity heading along it, so
α ≈ atan2(ΔY, ΔX) − (θ_first + θ_last)/2 (no model, no yaw rate: robust to a chattering input).
On the nominal plant α̂ is far more accurate than that course and lies inside the band around
it, so the gate only acts on a model mismatch.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tsmpc.kernels.jit import exact_hypot, jitable
from tsmpc.models.kinematic import pose_to_errors

__all__ = ["SlipGate", "outer_loop_errors", "slip_gate_update", "velocity_frame_errors"]

#: Half-width of the band around the course-based slip that α̂ must lie in [rad], plus the
#: course's own noise (4 σ from the position noise over the chord). The course lags α in fast
#: transients: 0.004 rad cost 0.06 m of max |e_y| on Monza at 25 m/s, 0.01 rad costs none there
#: and still cuts a 0.1 rad model-mismatch bias to a 0.12 m offset (kinematic test car).
GATE_RAD = 0.01
#: Shortest chord [m] the course is measured on (below: α̂ is used unbounded).
MIN_CHORD_M = 0.3
#: MPC steps spanned by the chord.
BASELINE = 5


def velocity_frame_errors(
    pose: NDArray[np.float64], ref_pose: NDArray[np.float64], alpha_hat: float
) -> NDArray[np.float64]:
    """[e_x, e_y, e_θ] of the velocity pose (X, Y, θ + α̂) against (x_d, y_d, θ_d).

    A non-finite α̂ (estimator failure) falls back to the body frame (α̂ = 0)."""
    a = alpha_hat if math.isfinite(alpha_hat) else 0.0
    return pose_to_errors(pose[0], pose[1], pose[2] + a, ref_pose[0], ref_pose[1], ref_pose[2])


def outer_loop_errors(
    pose: NDArray[np.float64], ref_pose: NDArray[np.float64], alpha_hat: float, dtheta_next: float = 0.0
) -> NDArray[np.float64]:
    """The errors the MPC receives: of the velocity pose (``alpha_hat``, 0 = body frame) against
    the reference pose ``ref_pose`` (x_d, y_d, heading), its heading moved by half of
    ``dtheta_next`` (0: as given). The cascade's outer block computes the same errors
    (:func:`tsmpc.control.outer_block.outer_errors`, against the path's tangent heading at the
    sample, :meth:`~tsmpc.planning.reference.Reference.tangent_heading`).

    Why the tangent: under the planners' convention x(k) = x(k−1) + v(k) cos θ(k) T
    θ_d(k) is the heading of the step *into* sample k; the path's tangent at (x_d, y_d)(k)
    lies halfway to the next step's heading, θ_d(k) + ω_d(k+1) T / 2 with T the reference's *own*
    sample period. The kinematic model takes θ_d as the direction the reference point moves, so
    the raw heading is a bias of ω_d T / 2 on e_θ (0.011 rad at 0.22 rad/s and T = 0.1 s) that the
    MPC holds against with a lateral offset in every corner. The tangent is taken from the
    geometry, so a reference sampled at 20 ms, 50 ms or 100 ms (and resampled to T_c) gets the
    correction of its own period.
    """
    r = np.array([ref_pose[0], ref_pose[1], ref_pose[2] + 0.5 * dtheta_next])
    return velocity_frame_errors(pose, r, alpha_hat)


@jitable
def slip_gate_update(sigma: float, poses: NDArray[np.float64], n: int, px: float, py: float, pth: float,
                     alpha_hat: float) -> tuple[float, int]:
    """One MPC step of the gate (the block's one definition, :mod:`tsmpc.kernels.jit`): (the slip
    to use, the new number of poses held). ``poses`` (``BASELINE`` + 1, 3) holds the last ``n`` MPC
    poses, oldest first, and takes (px, py, pth) in place; ``sigma``: the position noise σ [m]."""
    a = alpha_hat if math.isfinite(alpha_hat) else 0.0
    if n == BASELINE + 1:  # the oldest pose leaves the chord
        for r in range(n - 1):
            poses[r, 0], poses[r, 1], poses[r, 2] = poses[r + 1, 0], poses[r + 1, 1], poses[r + 1, 2]
        n -= 1
    poses[n, 0], poses[n, 1], poses[n, 2] = px, py, pth
    n += 1
    if n < 2:
        return a, n
    dx, dy = px - poses[0, 0], py - poses[0, 1]
    chord = exact_hypot(dx, dy)
    if not chord >= MIN_CHORD_M:  # standing, slow, or held poses: no course to compare
        return a, n
    d_th = (pth - poses[0, 2] + math.pi) % (2 * math.pi) - math.pi
    mean_th = poses[0, 2] + 0.5 * d_th
    a_course = (math.atan2(dy, dx) - mean_th + math.pi) % (2 * math.pi) - math.pi
    band = GATE_RAD + 4.0 * math.sqrt(2.0) * sigma / chord
    return min(max(a, a_course - band), a_course + band), n


class SlipGate:
    """α̂ bounded by the course over ground of the MPC poses (see the module docstring; a standalone
    online wrapper of :func:`slip_gate_update`, which the cascade runs inside its outer block,
    :func:`tsmpc.control.outer_block.outer_errors`).

    The course is the direction of the chord over the last ``BASELINE`` MPC steps (a longer chord
    divides the position noise); the slip it measures is that minus the mean body heading at the
    chord's ends.

    Args:
        Tc: time between two calls [s] (kept for the record).
        position_sigma: standard deviation of the measured X, Y [m] (sets the band's noise part).
    """

    def __init__(self, Tc: float, position_sigma: float = 0.0) -> None:
        self.Tc = float(Tc)
        self.sigma = float(position_sigma)
        self.reset()

    def reset(self) -> None:
        """Forget the previous poses."""
        self.poses = np.zeros((BASELINE + 1, 3))  #: the last MPC poses, oldest first
        self.n_poses = 0  #: rows of ``poses`` held
        self.n_gated = 0

    def __call__(self, pose: NDArray[np.float64], alpha_hat: float) -> float:
        """The slip to use at this MPC step, from the measured pose (X, Y, θ) and α̂."""
        out, self.n_poses = slip_gate_update(self.sigma, self.poses, self.n_poses, float(pose[0]),
                                             float(pose[1]), float(pose[2]), alpha_hat)
        self.n_gated += out != (alpha_hat if math.isfinite(alpha_hat) else 0.0)
        return out
