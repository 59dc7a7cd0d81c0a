"""CommonRoad's vehicle models as tsmpc plants (optional extra: ``pip install -e ".[commonroad]"``,
package ``commonroad-vehicle-models``, imported as ``vehiclemodels``).

:class:`CommonRoadPlant` implements the :class:`~tsmpc.sim.plant.Plant` protocol on CommonRoad's
single-track model (``vehicle_dynamics_st``: linear tyres with load transfer, states
``[x, y, δ, v, ψ, ψ̇, β]``, inputs steering rate and longitudinal acceleration), integrated with
RK4 steps of h. The adapter supplies what the CommonRoad model takes as inputs:

- **steering servo**: CommonRoad's input is the steering *rate*; the commanded angle δ_c is
  tracked by ``δ̇ = k (δ_c − δ)`` (k = 20 1/s, a 50 ms lag) inside the model's own rate limit
  (vehicle 2: ±0.4 rad/s) and angle limits;
- **longitudinal force balance**: ``a = (F_xR − μ(road) M g tanh(v / v_eps)) / M`` — the road
  resistance of the scenario, as tsmpc's plant applies it (CommonRoad has none), so runs on both
  plants face the same road; CommonRoad then applies its acceleration limits.

States map one to one: X = x, Y = y, θ = ψ, v = v, α = β, ω = ψ̇. The equivalent
:class:`~tsmpc.config.VehicleParams` (for the controllers) is :meth:`CommonRoadPlant.vehicle`,
from :meth:`VehicleParams.from_commonroad`.
"""

from __future__ import annotations

import importlib
import math
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import Config, VehicleParams, replace
from tsmpc.errors import ConfigError, NonFiniteError
from tsmpc.extras import missing_message

__all__ = ["COMMONROAD_MODELS", "CommonRoadPlant", "commonroad_config", "commonroad_parameters"]

#: Supported CommonRoad models (CLI ``--plant`` names → model): the single-track model and the
#: multi-body model (29 states: roll, pitch, suspension, wheel spin, Pacejka tyres; ≈ 0.5 s of
#: computation per simulated second at h = 1 ms, converged: h = 0.5 ms changes v by 1e-5 m/s).
COMMONROAD_MODELS = {"commonroad-st": "st", "commonroad-mb": "mb"}

_INSTALL = missing_message("vehiclemodels", "the CommonRoad plant")


def _vehiclemodels(module: str) -> Any:
    try:
        return importlib.import_module(f"vehiclemodels.{module}")
    except ImportError as err:
        raise ConfigError(f"{_INSTALL} ({err})") from None


def _plain(obj: Any) -> Any:
    """A parameter set as nested SimpleNamespaces: CommonRoad's omegaconf objects cost
    microseconds per attribute read, and the model reads about 20 per evaluation."""
    try:
        from omegaconf import DictConfig, OmegaConf

        if isinstance(obj, DictConfig):
            obj = OmegaConf.to_container(obj, resolve=True)
    except ImportError:  # pragma: no cover - omegaconf comes with vehiclemodels
        pass
    if isinstance(obj, dict):
        return SimpleNamespace(**{k: _plain(v) for k, v in obj.items()})
    if hasattr(obj, "__dict__") and not isinstance(obj, type):
        return SimpleNamespace(**{k: _plain(v) for k, v in vars(obj).items()})
    return obj


def commonroad_parameters(vehicle_id: int) -> Any:
    """CommonRoad's parameter set ``parameters_vehicle<id>()`` (1: Ford Escort, 2: BMW 320i,
    3: VW Vanagon, 4: semi-trailer truck)."""
    if vehicle_id not in (1, 2, 3):
        raise ConfigError(f"CommonRoad vehicle {vehicle_id} is not supported; allowed: 1, 2, 3")
    mod = _vehiclemodels(f"parameters_vehicle{vehicle_id}")
    return getattr(mod, f"parameters_vehicle{vehicle_id}")()


def commonroad_config(cfg: Config, vehicle_id: int = 2) -> Config:
    """``cfg`` set up to drive CommonRoad vehicle ``vehicle_id``: its single-track parameters
    for the controllers, the force limits of ``cfg`` kept *per kg* (the same acceleration margin
    for a heavier car; in newtons a 1093 kg car would barely overcome its road resistance). The
    scheduling boxes are ``cfg``'s: the designs certify vehicles 1–3 on the paper's full ±25°
    steering box with the margins of :mod:`tsmpc.synthesis.sdp`.
    """
    vehicle = VehicleParams.from_commonroad(_plain(commonroad_parameters(vehicle_id)),
                                            mu_nominal=cfg.vehicle.mu_nominal)
    lo, hi = cfg.lqr.force_limits(cfg.vehicle)
    m = cfg.vehicle.mass
    lqr = replace(cfg.lqr, force_min=None, force_max=None, force_min_per_kg=lo / m, force_max_per_kg=hi / m)
    return replace(cfg, vehicle=vehicle, lqr=lqr)


class CommonRoadPlant:
    """CommonRoad's single-track (``model="st"``) or multi-body (``"mb"``) model behind a
    steering servo (the Plant protocol).

    Args:
        vehicle_id: CommonRoad parameter set (1, 2 or 3); ignored when ``params`` is given.
        model: "st" (single-track) or "mb" (multi-body).
        params: a CommonRoad parameter object (``parameters_vehicleN()``) instead.
        h: RK4 step [s].
        servo_gain: steering servo gain k [1/s] (the rate limit is the model's own).
        road_resistance: apply μ(road) M g as tsmpc's plant does (False: none, as CommonRoad).
        v_eps: speed scale of the resistance's tanh [m/s] (as tsmpc's plant).
    """

    def __init__(
        self, vehicle_id: int = 2, *, model: str = "st", params: Any = None, h: float = 0.001,
        servo_gain: float = 20.0, road_resistance: bool = True, v_eps: float = 0.05,
    ) -> None:
        if not (h > 0 and math.isfinite(h)):
            raise ConfigError(f"CommonRoadPlant: h must be a positive finite step, got {h}")
        if model not in ("st", "mb"):
            raise ConfigError(f"CommonRoadPlant: unknown model {model!r}; allowed: st, mb")
        raw = params if params is not None else commonroad_parameters(vehicle_id)
        self.model = model
        self.params = _plain(raw)
        self.vehicle = VehicleParams.from_commonroad(self.params)
        self._f_st = getattr(_vehiclemodels(f"vehicle_dynamics_{model}"), f"vehicle_dynamics_{model}")
        self._init_mb = _vehiclemodels("init_mb").init_mb if model == "mb" else None
        self._acc = _vehiclemodels("utils.acceleration_constraints").acceleration_constraints
        self.h = float(h)
        self.servo_gain = float(servo_gain)
        self.road_resistance = bool(road_resistance)
        self.v_eps = float(v_eps)
        self._s = [0.0] * 7
        self._started = False
        self._u = np.zeros(2)
        self._f: float | None = None

    # -- Plant protocol ----------------------------------------------------------------------
    def reset(self, x0: ArrayLike) -> None:
        """tsmpc state [X, Y, θ, v, α, ω] → CommonRoad's; the steering starts at the first command."""
        X, Y, th, v, al, om = (float(c) for c in np.asarray(x0, dtype=float).reshape(6))
        core = [X, Y, 0.0, v, th, om, al]
        # multi-body: CommonRoad's own initialisation (body velocity components, wheel speeds, ...)
        self._s = list(self._init_mb(core, self.params)) if self._init_mb else core
        self._started = False
        self._u = np.zeros(2)
        self._f = None

    def step(self, u: ArrayLike, dt: float, mu_road: float) -> NDArray[np.float64]:
        """Hold the command [F_xR, δ_c] for ``dt`` (a whole number of steps h)."""
        F, dc = (float(c) for c in np.asarray(u, dtype=float).reshape(2))
        mu = float(mu_road)
        if not (math.isfinite(F) and math.isfinite(dc) and math.isfinite(mu)):
            raise NonFiniteError(f"CommonRoadPlant: non-finite input u=({F}, {dc}) or mu_road={mu}")
        n = round(dt / self.h)
        if n < 1 or abs(n * self.h - dt) > 1e-9 * max(1.0, dt):
            raise ConfigError(f"CommonRoadPlant: dt = {dt} must be a multiple of h = {self.h}")
        p = self.params
        if not self._started:  # the servo already holds the first commanded angle
            d0 = min(max(dc, p.steering.min), p.steering.max)
            if self._init_mb is not None:  # re-initialise so the wheels agree with the angle
                s0 = self._s
                v0, b0 = math.hypot(s0[3], s0[10]), math.atan2(s0[10], s0[3])
                self._s = list(self._init_mb([s0[0], s0[1], d0, v0, s0[4], s0[5], b0], p))
            self._s[2] = d0
            self._started = True
        M, g = p.m, 9.81
        res_scale = mu * M * g if self.road_resistance else 0.0
        k, eps, f = self.servo_gain, self.v_eps, self._f_st
        h, h2, h6 = self.h, 0.5 * self.h, self.h / 6.0

        def rhs(s: list[float]) -> list[float]:
            a = (F - res_scale * math.tanh(s[3] / eps)) / M
            return f(s, [k * (dc - s[2]), a], p)

        s = self._s
        acc_F = acc_d = 0.0
        for _ in range(n):
            a_cmd = (F - res_scale * math.tanh(s[3] / eps)) / M
            acc_F += self._acc(s[3], a_cmd, p.longitudinal) * M + res_scale * math.tanh(s[3] / eps)
            acc_d += s[2]
            k1 = rhs(s)
            k2 = rhs([a + h2 * b for a, b in zip(s, k1, strict=True)])
            k3 = rhs([a + h2 * b for a, b in zip(s, k2, strict=True)])
            k4 = rhs([a + h * b for a, b in zip(s, k3, strict=True)])
            s = [a + h6 * (b1 + 2.0 * (b2 + b3) + b4)
                 for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4, strict=True)]
        self._s = s
        self._u = np.array([acc_F / n, acc_d / n])
        self._f = (mu - self.vehicle.mu_nominal) * M * g if self.road_resistance \
            else -self.vehicle.mu_nominal * M * g
        x = self.state
        if not np.all(np.isfinite(x)):
            raise NonFiniteError(f"CommonRoadPlant: integration diverged to {s}")
        return x

    @property
    def state(self) -> NDArray[np.float64]:
        """Current state in tsmpc's convention [X, Y, θ, v, α, ω] (multi-body: the body's
        velocity components give v and α)."""
        s = self._s
        if self.model == "mb":
            return np.array([s[0], s[1], s[4], math.hypot(s[3], s[10]), math.atan2(s[10], s[3]), s[5]])
        return np.array([s[0], s[1], s[4], s[3], s[6], s[5]])

    @property
    def steering_angle(self) -> float:
        """Current front steering angle δ [rad] (the servo's output)."""
        return float(self._s[2])

    @property
    def applied_input(self) -> NDArray[np.float64]:
        """Mean [F_xR, δ] the vehicle received over the last step (after the servo and
        CommonRoad's acceleration limits)."""
        return self._u.copy()

    @property
    def friction_force(self) -> float | None:
        """(μ(road) − μ_o) M g of the last step [N] (−μ_o M g without road resistance)."""
        return self._f
