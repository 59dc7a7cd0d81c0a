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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import TyreModel, TyreParams, VehicleParams
from tsmpc.errors import ConfigError, NonFiniteError

__all__ = ["INPUT_NAMES", "STATE_NAMES", "Plant", "PlantConstants", "VehiclePlant"]

STATE_NAMES = ("X", "Y", "theta", "v", "alpha", "omega")
INPUT_NAMES = ("F_xR", "delta")

_isfinite = math.isfinite


@dataclass(frozen=True)
class PlantConstants:
    """Regularisation constants of the plant."""

    v_floor: float = 0.5  #: speed floor of every 1/v [m/s]
    v_eps: float = 0.05  #: speed scale of the resistance tanh [m/s]


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
        fzf, fzr = vehicle.static_loads
        self._fz = (fzf, fzr)
        self._linear = tyre.model == TyreModel.LINEAR
        self._rhs = self._make_rhs()
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
    def _make_rhs(self):
        """Build ẋ = f(x, u, μ) as a closure over local float constants (no attribute look-ups:
        this function is evaluated 4 times per 1 ms step)."""
        p, t, k = self.vehicle, self.tyre, self.constants
        M, I, g, a, b = p.mass, p.inertia, p.g, p.a, p.b
        Cf, Cr, kd = p.C_f, p.C_r, p.drag_factor
        v_floor, v_eps = k.v_floor, k.v_eps
        Mg = M * g
        fzf, fzr = self._fz
        cc, ee = t.shape_c, t.curvature_e
        mu_t0 = t.mu_tyre
        scale = mu_t0 / t.mu_dry if t.scale_grip_with_road else 0.0
        linear = self._linear
        combined = t.combined_slip and not linear
        sin, cos, atan, atan2, tanh, sqrt = math.sin, math.cos, math.atan, math.atan2, math.tanh, math.sqrt

        def rhs(th, v, al, om, F, d, mu):
            ve = v if v > v_floor else v_floor
            sa, ca = sin(al), cos(al)
            f_res = mu * Mg * tanh(v / v_eps)
            if linear:
                fyf = Cf * (d - al - a * om / ve)
                fyr = Cr * (b * om / ve - al)
            else:
                vx, vy = ve * ca, ve * sa
                mu_t = mu * scale if scale else mu_t0
                Df, Dr = mu_t * fzf, mu_t * fzr
                if Df > 0.0:
                    bs = Cf / (cc * Df) * (atan2(vy + a * om, vx) - d)
                    fyf = -Df * sin(cc * atan(bs - ee * (bs - atan(bs))))
                    bs = Cr / (cc * Dr) * atan2(vy - b * om, vx)
                    fyr = -Dr * sin(cc * atan(bs - ee * (bs - atan(bs))))
                else:
                    fyf = fyr = 0.0
                if combined:  # friction ellipse of the driven (rear) tyre; see the module docstring
                    ft = F - f_res
                    if Dr > 0.0:
                        ft = -Dr if ft < -Dr else (Dr if ft > Dr else ft)
                        rr = ft / Dr
                        fyr *= sqrt(1.0 - rr * rr)
                    else:
                        ft = 0.0
                    F = ft  # the body sees the traction; the resistance is inside it
                    f_res = 0.0
            sda, cda = sin(d - al), cos(d - al)
            vdot = (F * ca - fyf * sda + fyr * sa - kd * v * v - f_res) / M
            adot = (-F * sa + fyf * cda + fyr * ca) / (M * ve) - om
            wdot = (a * fyf * cos(d) - b * fyr) / I
            return v * cos(th + al), v * sin(th + al), om, vdot, adot, wdot

        return rhs

    def _kernel_agrees(self) -> bool:
        """The compiled block reproduces the float closure on two probe states (guards against a
        model edited on one side only)."""
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
        return np.array(self._rhs(xs[2], xs[3], xs[4], xs[5], F, d, mu))

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
        """The float-closure RK4 of :meth:`step` (the kernel's oracle)."""
        (X, Y, th, v, al, om), (F, d), mu = self._checked(x, u, mu_road)
        h = self.h
        h2 = 0.5 * h
        h6 = h / 6.0
        f = self._rhs
        for _ in range(n_steps):
            # Classical RK4, unrolled on floats (the position does not feed back into f).
            a1, b1, c1, d1, e1, g1 = f(th, v, al, om, F, d, mu)
            a2, b2, c2, d2, e2, g2 = f(th + h2 * c1, v + h2 * d1, al + h2 * e1, om + h2 * g1, F, d, mu)
            a3, b3, c3, d3, e3, g3 = f(th + h2 * c2, v + h2 * d2, al + h2 * e2, om + h2 * g2, F, d, mu)
            a4, b4, c4, d4, e4, g4 = f(th + h * c3, v + h * d3, al + h * e3, om + h * g3, F, d, mu)
            X += h6 * (a1 + 2.0 * (a2 + a3) + a4)
            Y += h6 * (b1 + 2.0 * (b2 + b3) + b4)
            th += h6 * (c1 + 2.0 * (c2 + c3) + c4)
            v += h6 * (d1 + 2.0 * (d2 + d3) + d4)
            al += h6 * (e1 + 2.0 * (e2 + e3) + e4)
            om += h6 * (g1 + 2.0 * (g2 + g3) + g4)
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
        self._mg = vehicle.mass * vehicle.g
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
        n = round(dt / self.model.h)
        if n < 1 or abs(n * self.model.h - dt) > 1e-9 * max(1.0, dt):
            raise ValueError(f"VehiclePlant: dt = {dt} must be a positive multiple of h = {self.model.h}")
        self._u = np.asarray(u, dtype=float).reshape(2).copy()
        self._f = (float(mu_road) - self.vehicle.mu_nominal) * self._mg
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
