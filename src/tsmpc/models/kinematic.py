"""Kinematic error model and its exact TS form (paper eq. "kinematic error model").

State ``x_c = [e_x, e_y, e_θ]`` (vehicle-frame errors), input ``u_c = [v, ω]``, reference input
``r_c = [v_d cos e_θ, ω_d]``. Euler at ``T_c``::

    x_c(k+1) = A_c(ρ) x_c(k) + B_c u_c(k) − B_c r_c(k)
    A_c = [[1, ω T_c, 0], [−ω T_c, 1, v_d sinc(e_θ) T_c], [0, 0, 1]]
    B_c = T_c [[−1, 0], [0, 0], [0, −1]]

TS form: the premises are ``z = (ω, v_d, sinc e_θ)``. A_c is affine in ω and bilinear in
(v_d, sinc e_θ), hence multilinear in z, so the 8-vertex TS model equals A_c(ρ) to machine
precision everywhere in the box (see :mod:`tsmpc.models.polytope`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import KinematicBox
from tsmpc.models.polytope import SchedulingBox

__all__ = [
    "A_c",
    "B_c",
    "KinematicTS",
    "continuous_error_dynamics",
    "nonlinear_step",
    "pose_to_errors",
    "reference_input",
    "sinc",
    "wrap_angle",
]


def wrap_angle(a: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles to [−π, π)."""
    a = np.asarray(a, dtype=float)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def sinc(x: ArrayLike) -> NDArray[np.float64]:
    """Unnormalised sinc, sin(x)/x with sinc(0) = 1 (never divides by zero)."""
    return np.sinc(np.asarray(x, dtype=float) / np.pi)


def pose_to_errors(
    X: ArrayLike, Y: ArrayLike, theta: ArrayLike,
    x_d: ArrayLike, y_d: ArrayLike, theta_d: ArrayLike,
) -> NDArray[np.float64]:
    """Vehicle-frame tracking errors (..., 3) = [e_x, e_y, e_θ] of a pose against a reference.

    e_x = cos θ (x_d−X) + sin θ (y_d−Y), e_y = −sin θ (x_d−X) + cos θ (y_d−Y),
    e_θ = wrap(θ_d − θ).
    """
    th = np.asarray(theta, dtype=float)
    dx = np.asarray(x_d, dtype=float) - np.asarray(X, dtype=float)
    dy = np.asarray(y_d, dtype=float) - np.asarray(Y, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.stack(
        [c * dx + s * dy, -s * dx + c * dy, wrap_angle(np.asarray(theta_d) - th)], axis=-1
    )


def continuous_error_dynamics(
    x: ArrayLike, u: ArrayLike, v_d: ArrayLike, omega_d: ArrayLike
) -> NDArray[np.float64]:
    """ė = [ω e_y − v + v_d cos e_θ, −ω e_x + v_d sin e_θ, ω_d − ω] for x (..., 3), u (..., 2)."""
    x = np.asarray(x, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    ex, ey, et = x[..., 0], x[..., 1], x[..., 2]
    v, w = u[..., 0], u[..., 1]
    vd, wd = np.asarray(v_d, dtype=np.float64), np.asarray(omega_d, dtype=np.float64)
    return np.stack(
        [w * ey - v + vd * np.cos(et), -w * ex + vd * np.sin(et), wd - w], axis=-1
    )


def nonlinear_step(
    x: ArrayLike, u: ArrayLike, v_d: ArrayLike, omega_d: ArrayLike, Tc: float
) -> NDArray[np.float64]:
    """One Euler step of the nonlinear error model (the discretisation of the paper)."""
    x = np.asarray(x, dtype=float)
    return x + Tc * continuous_error_dynamics(x, u, v_d, omega_d)


def A_c(omega: ArrayLike, v_d: ArrayLike, e_theta: ArrayLike, Tc: float) -> NDArray[np.float64]:
    """A_c(ρ) (..., 3, 3) evaluated directly."""
    w = np.asarray(omega, dtype=float)
    vs = np.asarray(v_d, dtype=float) * sinc(e_theta)
    w, vs = np.broadcast_arrays(w, vs)
    A = np.zeros((*w.shape, 3, 3))
    A[..., 0, 0] = A[..., 1, 1] = A[..., 2, 2] = 1.0
    A[..., 0, 1] = w * Tc
    A[..., 1, 0] = -w * Tc
    A[..., 1, 2] = vs * Tc
    return A


def B_c(Tc: float) -> NDArray[np.float64]:
    """B_c (3, 2) = T_c [[−1, 0], [0, 0], [0, −1]]."""
    return Tc * np.array([[-1.0, 0.0], [0.0, 0.0], [0.0, -1.0]])


def reference_input(v_d: ArrayLike, omega_d: ArrayLike, e_theta: ArrayLike) -> NDArray[np.float64]:
    """r_c (..., 2) = [v_d cos e_θ, ω_d]."""
    v_d, omega_d, e_theta = np.broadcast_arrays(
        np.asarray(v_d, float), np.asarray(omega_d, float), np.asarray(e_theta, float)
    )
    return np.stack([v_d * np.cos(e_theta), omega_d], axis=-1)


def _sinc_range(lo: float, hi: float) -> tuple[float, float]:
    s_lo, s_hi = float(sinc(lo)), float(sinc(hi))
    top = 1.0 if lo <= 0.0 <= hi else max(s_lo, s_hi)
    return min(s_lo, s_hi), top


class KinematicTS:
    """Exact 8-vertex TS form of the kinematic error model.

    Args:
        box: scheduling box of (ω, v_d, e_θ).
        Tc: sample time [s].
    """

    def __init__(self, box: KinematicBox, Tc: float) -> None:
        self.box = box
        self.Tc = float(Tc)
        s_lo, s_hi = _sinc_range(*box.e_theta)
        self.premise_box = SchedulingBox(
            ("omega", "v_d", "sinc_e_theta"),
            (box.omega[0], box.v_d[0], s_lo),
            (box.omega[1], box.v_d[1], s_hi),
        )
        z = self.premise_box.vertices()
        # Vertex matrices A_i: A_c at the vertex premises (sinc premise enters linearly).
        self.A_vertices = A_c(z[:, 0], z[:, 1] * z[:, 2], 0.0, self.Tc)  # (8, 3, 3)
        self.B = B_c(self.Tc)

    @property
    def n_vertices(self) -> int:
        """8."""
        return self.premise_box.n_vertices

    def premises(
        self, omega: ArrayLike, v_d: ArrayLike, e_theta: ArrayLike
    ) -> NDArray[np.float64]:
        """Premise values z (..., 3) = (ω, v_d, sinc e_θ); not clipped."""
        omega, v_d, s = np.broadcast_arrays(
            np.asarray(omega, float), np.asarray(v_d, float), sinc(e_theta)
        )
        return np.stack([omega, v_d, s], axis=-1)

    def clip(self, z: ArrayLike) -> tuple[NDArray[np.float64], int]:
        """Clip premises into the box; returns (clipped z, number of points that were out)."""
        return self.premise_box.clip(z)

    def memberships(self, z: ArrayLike) -> NDArray[np.float64]:
        """μ (..., 8) of premises z (..., 3) (clipped into the box)."""
        return self.premise_box.memberships(z)

    def A(self, z: ArrayLike) -> NDArray[np.float64]:
        """TS matrix Σ μ_i(z) A_i (..., 3, 3)."""
        return self.premise_box.blend(self.memberships(z), self.A_vertices)

    def predict(
        self, x: ArrayLike, u: ArrayLike, z: ArrayLike, r: ArrayLike
    ) -> NDArray[np.float64]:
        """One step of the TS model: A(z) x + B u − B r."""
        x = np.asarray(x, float)
        Az = self.A(z)
        return (
            np.einsum("...ij,...j->...i", Az, x)
            + np.asarray(u, float) @ self.B.T
            - np.asarray(r, float) @ self.B.T
        )
