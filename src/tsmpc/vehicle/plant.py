"""Nonlinear single-track vehicle plant with linear or Pacejka tyres, RK4 (the plant model).

State ``x = [X, Y, θ, v, α, ω]`` (global position [m], heading [rad, unwrapped], CoG speed [m/s],
body slip angle [rad], yaw rate [rad/s]); input ``u = [F_xR, δ]`` (rear drive force [N], front
steering [rad]); exogenous ``μ(road)`` (longitudinal resistance coefficient, the plant model)::

    Ẋ = v cos(θ+α),  Ẏ = v sin(θ+α),  θ̇ = ω
    v̇ = [F_xR cos α − F_yF sin(δ−α) + F_yR sin α − ½ρC_dA_r v² − F_res] / M
    α̇ = [−F_xR sin α + F_yF cos(δ−α) + F_yR cos α] / (M v) − ω
    ω̇ = [a F_yF cos δ − b F_yR] / I

Low-speed regularisation (documented choice): the 1/v of the α equation and of the linear tyre
slips uses ``max(v, v_floor)`` (default 0.5 m/s), Pacejka slips use ``atan2`` with the same floor,
and the rolling resistance is ``F_res = μ M g tanh(v / v_eps)`` (v_eps = 0.05 m/s) so it does not
push a stopped car backwards. Above 2 m/s both are exact to machine precision, so the plant equals
the paper's model there. The implementation works on Python floats (no numpy per call) because a
1 ms RK4 step sits in the innermost loop of every simulation.

Combined slip (``tyre.combined_slip``, beyond the paper's plant; Pacejka tyres): the rear tyre's
longitudinal and lateral forces share its grip ``D_R = μ_t F_zR`` (a friction ellipse, here a
circle: the same μ in both directions). The road resistance of the paper, ``F_res``, is
taken to act at the driven wheel along the body axis, so the tyre transmits the *traction*
``F_t = F_xR − F_res`` (what accelerates the car against drag and turns its velocity)::

    F_t = clip(F_xR − F_res, −D_R, D_R)              (wheel spin / lock beyond the grip)
    F_yR = F_yR,pure(α_R) · sqrt(1 − (F_t / D_R)²)    (the ellipse: F_t² + F_yR² ≤ D_R²)
    F_xR cos α − F_res  →  F_t cos α    in v̇,     F_xR sin α  →  F_t sin α    in α̇

Within the grip and at α = 0 this is the paper's plant; the difference elsewhere is the term
F_res sin α of α̇ (the paper's resistance acts along the velocity and leaves the body-axis drive
force's normal component F_res sin α as lateral force: ≈ 0.4 m/s² at α = 0.05 on dry asphalt,
lateral grip that no tyre provides). μ_t is μ_tyre, or μ(road) μ_tyre / μ_dry with
``tyre.scale_grip_with_road``: on a μ = 0.3 road the car then holds at most ≈ 0.3 g.

One definition (issue 34): the right-hand side, the RK4 steps and the friction force are the
``@jitable`` blocks of :mod:`tsmpc.vehicle.single_track`, which :class:`Plant` and
:class:`VehiclePlant` call as Python and the compiled kernels compile
(:func:`tsmpc.kernels.plant.rk4_block`, the run engine); :func:`rk4_count` is the step count both
the plant and the engine use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import TyreParams, VehicleParams
from tsmpc.errors import ConfigError, NonFiniteError

__all__ = [
    "INPUT_NAMES",
    "STATE_NAMES",
    "Plant",
    "PlantConstants",
    "VehiclePlant",
    "rk4_count",
]

STATE_NAMES = ("X", "Y", "theta", "v", "alpha", "omega")
INPUT_NAMES = ("F_xR", "delta")

_isfinite = math.isfinite


@dataclass(frozen=True)
class PlantConstants:
    """Regularisation constants of the plant."""

    v_floor: float = 0.5  #: speed floor of every 1/v [m/s]
    v_eps: float = 0.05  #: speed scale of the resistance tanh [m/s]


def rk4_count(dt: float, h: float) -> int | None:
    """The number of RK4 steps of ``h`` in ``dt``; None when ``dt`` is no positive multiple of h."""
    n = round(dt / h)
    if n < 1 or abs(n * h - dt) > 1e-9 * max(1.0, dt):
        return None
    return n


class Plant:
    """Nonlinear single-track plant integrated with fixed-step RK4, inputs held over the step.

    Args:
        vehicle: vehicle parameters (paper Table 1).
        tyre: tyre model of the plant.
        h: RK4 step [s].
        constants: low-speed regularisation.
        jit: integrate :meth:`step` by the compiled block (:mod:`tsmpc.kernels.plant`, the same
            arithmetic); None = unless ``TSMPC_NO_JIT`` is set; False = the float closure only.
    """

    n_x = 6
    n_u = 2

    def __init__(
        self,
        vehicle: VehicleParams,
        tyre: TyreParams,
        h: float = 0.001,
        constants: PlantConstants = PlantConstants(),
        jit: bool | None = None,
    ) -> None:
        if not (h > 0 and math.isfinite(h)):
            raise ConfigError(f"h must be a positive finite step, got {h}")
        self.vehicle = vehicle
        self.tyre = tyre
        self.h = float(h)
        self.constants = constants
        # the model's blocks (numba is imported with them: by simulating code, not by this module)
        import tsmpc.vehicle.single_track as single_track

        self._blocks = single_track
        self.params = single_track.plant_params(vehicle, tyre, constants.v_floor, constants.v_eps)
        self._linear = self.params.linear
        self._kern: Any = None  # the compiled block (tsmpc.kernels.load("plant")), or None
        if jit is None or jit:
            from tsmpc import kernels

            self._kern = kernels.load("plant")
            if self._kern is not None:
                try:
                    self._cst = self._kern.pack(self)
                    agrees = self._kernel_agrees()
                except (AttributeError, TypeError, ValueError):  # parameters it does not know
                    agrees = False
                if not agrees:
                    self._kern = None  # the model changed without the kernel: numpy only

    # ------------------------------------------------------------------ model
    def _kernel_agrees(self) -> bool:
        """The compiled block reproduces :meth:`_step_floats` on two probe states (the same
        functions: this guards a subclass that changed the Python side only)."""
        for xp in ((0.0, 0.0, 0.3, 8.0, 0.02, 0.1), (1.0, -2.0, -1.0, 0.3, -0.05, -0.4)):
            x = np.array(xp)
            ref = self._step_floats(x, (1500.0, 0.05), 0.7, 3)  # not step(): callers may wrap it
            out, ok = self._kern.rk4_block(x, 1500.0, 0.05, 0.7, 3, self.h, self._cst)
            if not ok or np.abs(out - ref).max() > 1e-10 * (1.0 + np.abs(ref).max()):
                return False
        return True

    def derivatives(self, x: ArrayLike, u: ArrayLike, mu_road: float) -> NDArray[np.float64]:
        """ẋ (6,) at state x (6,), input u = [F_xR, δ] and road friction μ(road)."""
        xs, (F, d), mu = self._checked(x, u, mu_road)
        rhs = self._blocks.plant_rhs
        return np.array(rhs(self.params, xs[2], xs[3], xs[4], xs[5], F, d, mu, math.cos(d)))

    # ------------------------------------------------------------ integration
    def _checked(
        self, x: ArrayLike, u: ArrayLike, mu_road: float
    ) -> tuple[tuple[float, ...], tuple[float, float], float]:
        xs = tuple(np.asarray(x, dtype=float).reshape(-1).tolist())
        us = tuple(np.asarray(u, dtype=float).reshape(-1).tolist())
        if len(xs) != 6 or len(us) != 2:
            raise ConfigError(f"plant: state must have 6 entries and input 2, got {len(xs)}, {len(us)}")
        mu = float(mu_road)
        if not all(map(_isfinite, xs)):
            raise NonFiniteError(f"plant: non-finite state {xs}")
        if not all(map(_isfinite, us)) or not _isfinite(mu):
            raise NonFiniteError(f"plant: non-finite input u={us} or mu_road={mu}")
        return xs, (us[0], us[1]), mu

    def step(
        self, x: ArrayLike, u: ArrayLike, mu_road: float, n_steps: int = 1
    ) -> NDArray[np.float64]:
        """Advance ``n_steps`` RK4 steps of length h with u and μ(road) held; returns x (6,).

        Raises :class:`NonFiniteError` on NaN/inf state or input, or if the integration itself
        produces a non-finite state.
        """
        if self._kern is not None and type(x) is np.ndarray and x.shape == (6,) and x.dtype == np.float64:
            try:
                # (u: any array-like of two numbers; anything else is caught below)
                F, d = u  # type: ignore[misc, str-unpack]
                F, d, mu = float(F), float(d), float(mu_road)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                pass  # the checked path below names the problem
            else:
                out, ok = self._kern.rk4_block(x, F, d, mu, int(n_steps), self.h, self._cst)
                if ok:
                    return out
                # non-finite: the checked path below raises with the exact message
        return self._step_floats(x, u, mu_road, n_steps)

    def _step_floats(
        self, x: ArrayLike, u: ArrayLike, mu_road: float, n_steps: int
    ) -> NDArray[np.float64]:
        """:meth:`step` by :func:`rk4_steps` as Python (no compiled kernels)."""
        (X, Y, th, v, al, om), (F, d), mu = self._checked(x, u, mu_road)
        X, Y, th, v, al, om = self._blocks.rk4_steps(self.params, X, Y, th, v, al, om, F, d, mu, n_steps,
                                                     self.h)
        xs = (X, Y, th, v, al, om)
        if not all(map(_isfinite, xs)):
            raise NonFiniteError(f"plant: integration diverged to {xs}")
        return np.array(xs)

    def friction_force(self, mu_road: float) -> float:
        """Unknown friction disturbance F_fr = (μ(road) − μ_o) M g seen by the models [N]."""
        p = self.vehicle
        return (float(mu_road) - p.mu_nominal) * p.mass * p.g


class VehiclePlant:
    """tsmpc's nonlinear plant as a stateful vehicle (the :class:`tsmpc.sim.plant.Plant`
    protocol): owns the state, integrates :class:`Plant` with RK4 steps of h over each ``dt``.

    Args:
        vehicle: as for :class:`Plant`.
        tyre: as for :class:`Plant`.
        h: as for :class:`Plant`.
        constants: as for :class:`Plant`.
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        tyre: TyreParams,
        h: float = 0.001,
        constants: PlantConstants = PlantConstants(),
    ) -> None:
        self.model = Plant(vehicle, tyre, h, constants)
        self.vehicle = vehicle
        self._mg = self.model.params.mg
        self._x = np.zeros(6)
        self._u = np.zeros(2)
        self._f: float | None = None

    def reset(self, x0: ArrayLike) -> None:
        """State ``x0`` (6,), no input applied yet."""
        self._x = np.asarray(x0, dtype=float).reshape(6).copy()
        self._u = np.zeros(2)
        self._f = None

    @property
    def state(self) -> NDArray[np.float64]:
        """Current state (6,)."""
        return self._x.copy()

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        """Hold ``u`` for ``dt`` (a whole number of RK4 steps h); returns the new state.
        Raises :class:`NonFiniteError` on a non-finite input or state."""
        n = rk4_count(dt, self.model.h)
        if n is None:
            raise ValueError(f"VehiclePlant: dt = {dt} must be a positive multiple of h = {self.model.h}")
        self._u = np.asarray(u, dtype=float).reshape(2).copy()
        self._f = self.model._blocks.friction_force(self.vehicle.mu_nominal, self._mg, float(mu_road))
        self._x = self.model.step(self._x, self._u, mu_road, n)
        return self._x.copy()

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """The last input (no actuator dynamics: the command itself)."""
        return self._u.copy()

    @property
    def friction_force(self) -> float | None:
        """(μ(road) − μ_o) M g of the last step [N]."""
        return self._f
