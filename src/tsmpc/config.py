"""Parameters and settings: vehicle (paper Table 1), rates, tyres, scheduling boxes (the paper's TS models),
controller, estimator, planner and noise settings; TOML loading and validation.

Every object here is a frozen pydantic model that rejects unknown fields, so a typo in a TOML
file is an error naming the field, never a silently ignored value. Variants are made with
``model_copy(update=...)`` or :func:`replace`.

Units are SI throughout (m, s, kg, N, rad) unless a field name says otherwise (``*_deg``).
"""

from __future__ import annotations

import math
import re
import sys
import tomllib
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from tsmpc.errors import ConfigError

__all__ = [
    "DEFAULT_FORCE_MAX_PER_KG",
    "DEFAULT_FORCE_MIN_PER_KG",
    "PRESETS",
    "BaselineSettings",
    "Config",
    "DynamicBox",
    "DynamicLMIFormulation",
    "DynamicLMISettings",
    "FeasiblePoint",
    "FrictionEstimate",
    "FrictionEvent",
    "FusionSettings",
    "InnerLaw",
    "KinematicBox",
    "KinematicLMISettings",
    "KnownPart",
    "LQRSettings",
    "MHEForm",
    "MHESettings",
    "MPCSettings",
    "Method",
    "MetricsSettings",
    "NoiseSettings",
    "PlannerSettings",
    "PlantScales",
    "PurePursuitSettings",
    "Rates",
    "RecoverySettings",
    "ScenarioActuators",
    "ScenarioSettings",
    "SchedulingMode",
    "SensorFaults",
    "StanleySettings",
    "StrictBool",
    "StrictInt",
    "TyreModel",
    "TyreParams",
    "VehicleParams",
    "apply_overrides",
    "format_validation_error",
    "load_config",
    "replace",
    "resolve_preset",
]

# Strict types (issue 24): a number field takes a number (an int or a float) and nothing else —
# never a bool (``mass = true`` is not 1 kg) nor a string; an int field never a float, bool or
# string; a bool field only true/false (never "yes" or 1). Every field of every model here (and of
# the sweep schema) is built from these.
PositiveFloat = Annotated[float, Strict(), Field(gt=0.0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Strict(), Field(ge=0.0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Strict(), Field(allow_inf_nan=False)]
StrictInt = Annotated[int, Strict()]
StrictBool = Annotated[bool, Strict()]

#: Plausible range of every LMI / MPC / MHE weight entry (diagonal of Q, R, P): beyond it the
#: problems are numerically meaningless (the solvers return NaN/inf or fail).
WEIGHT_RANGE = (1e-8, 1e8)
#: Largest speed any box, bound or limit may name [m/s] (720 km/h: beyond any road vehicle).
V_LIMIT = 200.0
#: Largest yaw rate any box or bound may name [rad/s].
OMEGA_LIMIT = 20.0
#: Most problems listed in one error message (the rest are counted).
MAX_PROBLEMS = 20


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)


def _interval(lo: float, hi: float, name: str) -> None:
    if not lo < hi:
        raise ConfigError(f"{name}: lower bound {lo} must be < upper bound {hi}")


def _diag(values: tuple[float, ...], name: str, n: int, *, strict: bool = True) -> None:
    if len(values) != n:
        raise ConfigError(f"{name}: expected {n} diagonal entries, got {len(values)}")
    bad = [v for v in values if (v <= 0 if strict else v < 0)]
    if bad:
        kind = "positive" if strict else "non-negative"
        raise ConfigError(f"{name}: entries must be {kind}, got {values}")
    lo, hi = WEIGHT_RANGE
    bad = [v for v in values if v > hi or 0 < v < lo]
    if bad:
        raise ConfigError(f"{name}: entries must lie in [{lo:g}, {hi:g}] (a plausible weight), "
                          f"got {bad[0]!r}")


def _within(values: tuple[float, ...], name: str, lo: float, hi: float, unit: str) -> None:
    for v in values:
        if not lo <= v <= hi:
            raise ConfigError(f"{name}: {v!r} is outside the plausible range [{lo:g}, {hi:g}] {unit}")


class TyreModel(StrEnum):
    """Lateral tyre model of the plant."""

    LINEAR = "linear"  #: F_y = C_x · slip (small-angle slips): the plant equals the control model
    PACEJKA = "pacejka"  #: magic formula with small-slip stiffness C_x and peak μ_tyre F_z


class Method(StrEnum):
    """The outer loop's method: the TS-MPC with one of its scheduling modes (the paper's TS-MPC), the
    NL-MPC baseline, or one of the guidance laws users pick instead (issue 26: pure pursuit,
    Stanley, kinematic LQR, LTV-MPC; :mod:`tsmpc.control.baselines`). One concept for runs
    (``tsmpc compare --methods``, logs, metrics keys) and for the TS-MPC's scheduling
    (``mpc.mode``). Parsing is case-insensitive ("ref" = "REF", "pure_pursuit" = "PURE_PURSUIT")."""

    FZN = "FZN"  #: TS-MPC, frozen: current scheduling values for the whole horizon
    REF = "REF"  #: TS-MPC, planner references along the horizon (the paper's choice)
    ITER = "ITER"  #: TS-MPC, previous optimal prediction, re-solved until the schedule converges
    NL = "NL"  #: nonlinear MPC baseline (CasADi + IPOPT)
    PURE_PURSUIT = "PURE_PURSUIT"  #: pure pursuit with a speed-scheduled look-ahead (geometric)
    STANLEY = "STANLEY"  #: Stanley's front-axle law (geometric)
    LQR = "LQR"  #: kinematic LQR: the TS-scheduled gains of the kinematic LMI design, no constraints
    LTV = "LTV"  #: linear time-varying MPC, the error model linearised along the reference

    @classmethod
    def _missing_(cls, value: object) -> Method | None:
        if isinstance(value, str):
            up = value.strip().upper()
            for m in cls:
                if m.value == up:
                    return m
        return None

    @classmethod
    def parse(cls, text: str) -> Method:
        """Case-insensitive parse; the error lists the allowed values."""
        try:
            return cls(text)
        except ValueError:
            allowed = ", ".join(m.value.lower() for m in cls)
            raise ConfigError(f"unknown method {text!r}; allowed: {allowed}") from None

    @property
    def is_ts_mpc(self) -> bool:
        """True for the TS-MPC scheduling modes (FZN, REF, ITER); False for NL and the baselines."""
        return self in (Method.FZN, Method.REF, Method.ITER)


#: The TS-MPC's scheduling modes are the methods FZN, REF and ITER (former name, kept).
SchedulingMode = Method


class FrictionEstimate(StrEnum):
    """Which friction-force estimate the inner loop compensates (the paper's TS-MHE-UIO)."""

    WINDOW = "window"  #: window-constant unknown input of the MHE (ours: low noise)
    UIO = "uio"  #: the paper's one-step UIO formula F̂ = Θ(y − C(Ax̂ + Bu)) (σ ≈ 340 N)


class InnerLaw(StrEnum):
    """Which inner-loop law runs (the paper's inner loop; the published run)."""

    STATIC_GAIN = "static-gain"  #: ours: TS-LQR + static reference gain N̄, exact filter, anti-windup
    #: a quirk of the published run, not a recommendation: the law as it ran (Euler filter at T_d,
    #: fed back the previous clipped force, no anti-windup; :mod:`tsmpc.control.paper_as_run`)
    AS_RUN = "as-run"


class DynamicLMIFormulation(StrEnum):
    """Formulation of the dynamic TS-LMI-LQR (the paper's LMI designs; the published run)."""

    #: ours: guaranteed cost, interpolated gains imposed on a (δ, v) grid, ZOH, grid-certified
    GUARANTEED_COST = "guaranteed-cost"
    #: a quirk of the published run, not a recommendation: a feasibility problem (no objective),
    #: one common Lyapunov matrix over the 8 vertices, Euler at T_d
    #: (:mod:`tsmpc.synthesis.paper_as_run`)
    FEASIBILITY_EULER = "feasibility-euler"


class FeasiblePoint(StrEnum):
    """Which point of the feasibility LMI's solution set the design keeps (``feasibility-euler``
    only: a problem without objective has no unique answer)."""

    #: the analytic centre of the LMIs (:mod:`tsmpc.synthesis.analytic_center`): what an
    #: interior-point solver converges to without objective, the same in any units or scaling
    ANALYTIC_CENTER = "analytic-center"
    #: Clarabel's answer in the scaled coordinates of :mod:`tsmpc.synthesis.dynamic` (where the
    #: solver stopped: depends on that scaling)
    SOLVER = "solver"


class MHEForm(StrEnum):
    """How the MHE-UIO treats the unknown friction force (the paper's TS-MHE-UIO)."""

    #: ours: a window-constant unknown input fitted inside the MHE (compiled fast path)
    WINDOW = "window"
    #: the paper's UIO form: F eliminated through E_d (A_o = (I − E_dΘC_d)A_d, B_o likewise, the
    #: transition adds E_dΘy), F̂ = Θ(y − C_d(A_d x̂ + B_d u)) after each solve; numpy path only
    UIO = "uio"


class VehicleParams(_Frozen):
    """Vehicle parameters, paper Table 1."""

    a: PositiveFloat = Field(default=0.758, ge=0.05, le=20.0, description="CoG to front axle [m], 0.05 to 20")
    b: PositiveFloat = Field(default=1.036, ge=0.05, le=20.0, description="CoG to rear axle [m], 0.05 to 20")
    mass: PositiveFloat = Field(default=683.0, ge=1.0, le=1e5,
                                description="vehicle mass M [kg], 1 (a model car) to 1e5 (a truck)")
    inertia: PositiveFloat = Field(
        default=560.94, ge=0.01, le=1e7, description="yaw inertia I [kg m^2], 0.01 to 1e7; its radius of "
        "gyration sqrt(I/M) must lie in [0.05, 10] m")
    cornering_stiffness: PositiveFloat = Field(
        default=25000.0, ge=1.0, le=1e7,
        description="cornering stiffness C_x of each axle [N/rad] (paper: both axles), 1 to 1e7"
    )
    cornering_stiffness_front: PositiveFloat | None = Field(
        default=None, ge=1.0, le=1e7,
        description="front-axle cornering stiffness C_f [N/rad], 1 to 1e7; None = cornering_stiffness"
    )
    cornering_stiffness_rear: PositiveFloat | None = Field(
        default=None, ge=1.0, le=1e7,
        description="rear-axle cornering stiffness C_r [N/rad], 1 to 1e7; None = cornering_stiffness"
    )
    frontal_area: PositiveFloat = Field(default=1.91, ge=0.01, le=100.0,
                                        description="frontal area A_r [m^2], 0.01 to 100")
    air_density: PositiveFloat = Field(default=1.184, ge=1e-3, le=5.0,
                                       description="air density rho [kg/m^3], 0.001 to 5")
    drag_coefficient: NonNegFloat = Field(default=0.36, le=3.0,
                                          description="drag coefficient C_d [-], 0 to 3")
    mu_nominal: NonNegFloat = Field(default=0.5, le=3.0,
                                    description="nominal friction mu_o of the models [-], 0 to 3")
    g: PositiveFloat = Field(default=9.81, ge=1.0, le=30.0, description="gravity [m/s^2], 1 to 30")

    @model_validator(mode="after")
    def _gyration(self) -> VehicleParams:
        k = math.sqrt(self.inertia / self.mass)
        if not 0.05 <= k <= 10.0:
            raise ConfigError(f"inertia/mass: radius of gyration sqrt(I/M) = {k:.3g} m is outside "
                              "the plausible [0.05, 10] m (check inertia and mass)")
        return self

    @property
    def wheelbase(self) -> float:
        """a + b [m]."""
        return self.a + self.b

    @property
    def C_f(self) -> float:
        """Front-axle cornering stiffness [N/rad]."""
        c = self.cornering_stiffness_front
        return self.cornering_stiffness if c is None else c

    @property
    def C_r(self) -> float:
        """Rear-axle cornering stiffness [N/rad]."""
        c = self.cornering_stiffness_rear
        return self.cornering_stiffness if c is None else c

    def with_stiffness_scaled(self, factor: float) -> VehicleParams:
        """A copy with every cornering stiffness (both axles) multiplied by ``factor``."""
        def sc(c: float | None) -> float | None:
            return None if c is None else c * factor

        return replace(self, cornering_stiffness=self.cornering_stiffness * factor,
                       cornering_stiffness_front=sc(self.cornering_stiffness_front),
                       cornering_stiffness_rear=sc(self.cornering_stiffness_rear))

    def with_lateral_model(self, C_f: float, C_r: float, inertia: float | None = None,
                           a: float | None = None, b: float | None = None) -> VehicleParams:
        """A copy with the axle stiffnesses C_f, C_r [N/rad] and, given, the yaw inertia [kg m²] and
        the CoG's distances a, b [m] (the lateral model an online fit hands the estimators)."""
        return replace(self, cornering_stiffness_front=float(C_f), cornering_stiffness_rear=float(C_r),
                       inertia=float(self.inertia if inertia is None else inertia),
                       a=float(self.a if a is None else a), b=float(self.b if b is None else b))

    @classmethod
    def from_commonroad(cls, params: Any, *, mu_nominal: float = 0.5) -> VehicleParams:
        """The single-track equivalent of a CommonRoad parameter set (``vehiclemodels``'
        ``parameters_vehicleN()``, or any object with the same attributes).

        CommonRoad's single-track model writes each lateral force as μ C_S F_z × slip with the
        normalised stiffness C_S = −p_ky1 / p_dy1 and μ = p_dy1 (its ``vehicle_dynamics_st``), so
        the axle stiffnesses at the static loads are C_f = −p_ky1 M g b / (a + b) and
        C_r = −p_ky1 M g a / (a + b). CommonRoad has no aerodynamic drag (C_d = 0); μ_o is the
        control models' nominal resistance, as for tsmpc's own plant.
        """
        a, b, m, g = float(params.a), float(params.b), float(params.m), 9.81
        mu_cs = -float(params.tire.p_ky1)  # μ C_S, the same for both axles in CommonRoad's ST
        return cls(a=a, b=b, mass=m, inertia=float(params.I_z), g=g,
                   cornering_stiffness=0.5 * mu_cs * m * g,
                   cornering_stiffness_front=mu_cs * m * g * b / (a + b),
                   cornering_stiffness_rear=mu_cs * m * g * a / (a + b),
                   drag_coefficient=0.0, mu_nominal=mu_nominal)

    @property
    def drag_factor(self) -> float:
        """½ ρ C_d A_r [kg/m]: aerodynamic drag is drag_factor · v²."""
        return 0.5 * self.air_density * self.drag_coefficient * self.frontal_area

    @property
    def static_loads(self) -> tuple[float, float]:
        """(F_zF, F_zR) static axle loads [N]."""
        w = self.mass * self.g / self.wheelbase
        return w * self.b, w * self.a


class TyreParams(_Frozen):
    """Plant tyre model. Pacejka: f = D sin(C atan(Bα − E(Bα − atan Bα))),
    D = μ_tyre F_z and B = C_x / (C D) so that the small-slip stiffness equals C_x."""

    model: TyreModel = Field(default=TyreModel.PACEJKA, description="lateral tyre model of the plant")
    mu_tyre: PositiveFloat = Field(default=0.9, le=3.0, description="peak lateral grip coefficient [-], "
                                   "(0, 3]")
    shape_c: FiniteFloat = Field(default=1.3, gt=1.0, lt=2.0,
                                 description="Pacejka shape factor C [-], (1, 2)")
    curvature_e: FiniteFloat = Field(
        default=-0.5, ge=-5.0, lt=1.0, description="Pacejka curvature factor E [-], [-5, 1)"
    )
    scale_grip_with_road: StrictBool = Field(
        default=False, description="beyond the paper: mu_tyre scales with mu(road)/mu_dry"
    )
    mu_dry: PositiveFloat = Field(default=0.9, le=3.0, description="road mu at which the tyre has mu_tyre "
                                  "[-], (0, 3]")
    combined_slip: StrictBool = Field(
        default=False, description="beyond the paper's plant (issue 21): the rear tyre's traction force and "
        "its lateral force share its grip D = mu F_zR (friction ellipse); the traction saturates at "
        "+-D and the lateral force shrinks by sqrt(1 - (F_t/D)^2). Pacejka tyres only "
        "(tsmpc.vehicle.plant)")

    @model_validator(mode="after")
    def _combined_needs_pacejka(self) -> TyreParams:
        if self.combined_slip and self.model != TyreModel.PACEJKA:
            raise ConfigError("tyre.combined_slip: needs tyre.model = \"pacejka\" (the linear tyre "
                              "is the control model's, without a grip limit)")
        return self


class Rates(_Frozen):
    """Sample times (the paper's cascade). T_c / T_d and T_d / h must be integers."""

    Tc: PositiveFloat = Field(default=0.1, ge=1e-3, le=1.0,
                              description="outer loop (MPC) sample time [s], 0.001 to 1")
    Td: PositiveFloat = Field(default=0.01, ge=1e-4, le=0.1,
                              description="inner loop (LQR, MHE) sample time [s], 1e-4 to 0.1, < Tc")
    h: PositiveFloat = Field(default=0.001, ge=1e-5, le=0.01,
                             description="plant RK4 integration step [s], 1e-5 to 0.01, <= Td")
    inner_steps_per_outer: StrictInt | None = Field(
        default=None, ge=1, le=100000,
        description="inner steps run per outer step, 1 to 100000; None = T_c/T_d. A quirk of the "
        "published run, not a recommendation: it ran 101 steps of 1 ms per 0.1 s outer step (the "
        "plant advances 0.101 s while the reference advances 0.1 s: a 1 % time-base drift)")

    @model_validator(mode="after")
    def _integer_ratios(self) -> Rates:
        for num, den, name in ((self.Tc, self.Td, "Tc/Td"), (self.Td, self.h, "Td/h")):
            ratio = num / den
            if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
                raise ConfigError(f"{name} = {ratio:.6g} must be a positive integer")
        if self.Tc <= self.Td * (1.0 + 1e-9):
            # The cascade is two loops: an outer step of one inner step has no inner loop.
            raise ConfigError(f"Tc/Td: Tc = {self.Tc:g} s must be greater than Td = {self.Td:g} s "
                              "(an integer multiple >= 2)")
        return self

    @property
    def inner_per_outer(self) -> int:
        """Number of inner steps per outer step (``inner_steps_per_outer`` when set)."""
        if self.inner_steps_per_outer is not None:
            return self.inner_steps_per_outer
        return round(self.Tc / self.Td)

    @property
    def plant_per_inner(self) -> int:
        """Number of plant RK4 steps per inner step."""
        return round(self.Td / self.h)


class KinematicBox(_Frozen):
    """Scheduling box of the kinematic TS model (the paper's kinematic model): ω, v_d, e_θ.

    The default is the box that reproduces the paper's published terminal set S; the paper's
    text box is :meth:`paper_text`.
    """

    omega: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(-1.42, 1.42), description="ω range [rad/s], within [-20, 20]")
    v_d: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(1.0, 18.0), description="v_d range [m/s], within (0, 200]")
    e_theta: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(-math.radians(5.0), math.radians(5.0)), description="e_θ range [rad], within (-π, π)"
    )

    @model_validator(mode="after")
    def _check(self) -> KinematicBox:
        _interval(*self.omega, "omega")
        _interval(*self.v_d, "v_d")
        _within(self.omega, "omega", -OMEGA_LIMIT, OMEGA_LIMIT, "rad/s")
        _within(self.v_d, "v_d", 0.0, V_LIMIT, "m/s")
        _interval(*self.e_theta, "e_theta")
        if max(abs(self.e_theta[0]), abs(self.e_theta[1])) >= math.pi:
            raise ConfigError("e_theta: bounds must lie inside (-pi, pi)")
        return self

    @classmethod
    def paper_text(cls) -> KinematicBox:
        """The box stated in the paper's text: v_d ∈ [0.1, 20], e_θ ∈ [−0.05, 0.05]."""
        return cls(v_d=(0.1, 20.0), e_theta=(-0.05, 0.05))


class DynamicBox(_Frozen):
    """Scheduling box of the dynamic TS model (the paper's dynamic model): δ, v, α."""

    delta: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(-math.radians(25.0), math.radians(25.0)), description="steering δ range [rad], within "
        "[-π/2, π/2]"
    )
    v: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(2.0, 20.0), description="speed range [m/s], within (0, 200]")
    alpha: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(-0.1, 0.1), description="slip α range [rad], within [-1, 1]")

    @model_validator(mode="after")
    def _check(self) -> DynamicBox:
        _interval(*self.delta, "delta")
        _interval(*self.v, "v")
        _interval(*self.alpha, "alpha")
        _within(self.delta, "delta", -math.pi / 2, math.pi / 2, "rad")
        _within(self.v, "v", 0.0, V_LIMIT, "m/s")
        _within(self.alpha, "alpha", -1.0, 1.0, "rad")
        return self


class KinematicLMISettings(_Frozen):
    """Kinematic LQR-LMI and terminal set (the paper's LMI designs)."""

    Q: tuple[FiniteFloat, ...] = Field(default=(1.0, 1.5, 3.0),
                                       description="diag Q_TS, entries in [1e-8, 1e8]")
    R: tuple[FiniteFloat, ...] = Field(default=(1.0, 3.0), description="diag R_TS, entries in [1e-8, 1e8]")
    u_bar: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(18.0, 1.4), description="input bound of the terminal-set LMI [m/s, rad/s], "
        "within (0, 200] and (0, 20]"
    )

    @model_validator(mode="after")
    def _check(self) -> KinematicLMISettings:
        _diag(self.Q, "Q", 3)
        _diag(self.R, "R", 2)
        _within(self.u_bar[:1], "u_bar[v]", 0.0, V_LIMIT, "m/s")
        _within(self.u_bar[1:], "u_bar[ω]", 0.0, OMEGA_LIMIT, "rad/s")
        return self


class DynamicLMISettings(_Frozen):
    """Dynamic TS-LMI-LQR on the Apkarian-augmented model (the paper's LMI designs)."""

    Q: tuple[FiniteFloat, ...] = Field(
        default=(2500.0, 0.1, 0.1, 0.1, 1e5, 9e4),
        description="diag Q on [v, α, ω, F_f, δ_f, ζ], entries in [1e-8, 1e8]"
    )
    R: tuple[FiniteFloat, ...] = Field(default=(0.001, 9.0), description="diag R on [F_xR, δ], entries in "
                                       "[1e-8, 1e8]")
    filter_bandwidth: PositiveFloat = Field(default=10.0, ge=0.1, le=1000.0,
                                            description="Apkarian filter λ [rad/s], 0.1 to 1000")
    grid_points: StrictInt = Field(default=15, ge=3, le=101, description="certificate grid points per axis, "
                                   "3 to 101")
    formulation: DynamicLMIFormulation = Field(
        default=DynamicLMIFormulation.GUARANTEED_COST,
        description="'guaranteed-cost' (ours) or 'feasibility-euler' (a quirk of the published run, "
        "not a recommendation: no objective, 8 vertex LMIs, Euler at T_d)")
    feasible_point: FeasiblePoint = Field(
        default=FeasiblePoint.SOLVER, description="feasibility-euler only: which point of the solution "
        "set the design keeps: 'solver' (Clarabel's answer in the scaled coordinates) or "
        "'analytic-center' (the LMIs' analytic centre, the same in any units)")

    @model_validator(mode="after")
    def _check(self) -> DynamicLMISettings:
        _diag(self.Q, "Q", 6)
        _diag(self.R, "R", 2)
        if (self.feasible_point != FeasiblePoint.SOLVER
                and self.formulation != DynamicLMIFormulation.FEASIBILITY_EULER):
            raise ValueError("feasible_point: only for the 'feasibility-euler' formulation (the "
                             "guaranteed-cost design has an objective)")
        return self


class MPCSettings(_Frozen):
    """Kinematic TS-MPC and NL-MPC (the paper's TS-MPC, paper Table 2)."""

    N: StrictInt = Field(default=40, ge=2, le=400, description="prediction horizon [steps], 2 to 400 "
                         "(N·Tc <= 60 s)")
    Q: tuple[FiniteFloat, ...] = Field(default=(1.133, 0.067, 13.333), description="diag state weight, "
                                       "entries 0 or in [1e-8, 1e8]")
    R: tuple[FiniteFloat, ...] = Field(default=(0.000005, 5.5), description="diag input-rate weight, "
                                       "entries in [1e-8, 1e8]")
    u_min: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(0.0, -1.4), description="[v, ω] lower, within [-200, 200] m/s and [-20, 20] rad/s")
    u_max: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(18.0, 1.4), description="[v, ω] upper, within [-200, 200] m/s and [-20, 20] rad/s")
    du_max: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(5.0, 0.3), description="|Δv|, |Δω| per step, within [0.001, 100] m/s and [1e-4, 20] rad/s"
    )
    mode: Method = Field(default=Method.REF, description="TS-MPC scheduling mode: fzn, ref or iter")
    iter_tol: PositiveFloat = Field(default=1e-3, le=1.0, description="ITER: schedule change tolerance, "
                                    "(0, 1]")
    iter_max: StrictInt = Field(default=5, ge=1, le=50, description="ITER: maximum QPs per step, 1 to 50")
    soft_penalty: PositiveFloat = Field(default=1e4, ge=1e-3, le=1e9,
                                        description="exact penalty of soft constraints, 1e-3 to 1e9")
    terminal_constraint: StrictBool = Field(default=True, description="impose x_N' S x_N <= 1")
    slip_aware: StrictBool = Field(
        default=True, description="beyond the paper: errors of the velocity pose θ + α̂ (MHE) feed the MPC"
    )
    tangent_heading: StrictBool = Field(
        default=True, description="beyond the paper: the measured e_θ against the path's tangent at the "
        "sample (θ_d moved forward by its measured lag, half the reference's own period)"
    )
    offset_free_s: NonNegFloat = Field(
        default=0.0, le=600.0, description="beyond the paper: time constant τ [s] of the offset-free "
        "outer loop's course-offset estimate (control/offset_free.py), 0 = off (the default), else 1 to "
        "600 s (10 s is the setting measured in docs/design-decisions.md)"
    )
    step_average_reference: StrictBool = Field(
        default=True, description="beyond the paper: the reference inputs of each T_c step are that step's "
        "averages from the path geometry, ω_d = Δθ_tangent / T_c and v_d = chord / T_c (the "
        "paper's are the planner's samples, which describe the step *into* the sample)"
    )

    @field_validator("mode")
    @classmethod
    def _ts_mode(cls, v: Method) -> Method:
        if not v.is_ts_mpc:
            raise ValueError("the TS-MPC scheduling mode is fzn, ref or iter (nl is a method)")
        return v

    @model_validator(mode="after")
    def _check(self) -> MPCSettings:
        _diag(self.Q, "Q", 3, strict=False)
        _diag(self.R, "R", 2)
        for i in range(2):
            _interval(self.u_min[i], self.u_max[i], f"u_min/u_max[{i}]")
        _within((self.u_min[0], self.u_max[0]), "u_min/u_max[v]", -V_LIMIT, V_LIMIT, "m/s")
        _within((self.u_min[1], self.u_max[1]), "u_min/u_max[ω]", -OMEGA_LIMIT, OMEGA_LIMIT, "rad/s")
        _within(self.du_max[:1], "du_max[v]", 1e-3, 100.0, "m/s per step")
        _within(self.du_max[1:], "du_max[ω]", 1e-4, OMEGA_LIMIT, "rad/s per step")
        return self

    @field_validator("offset_free_s")
    @classmethod
    def _offset_free(cls, v: float) -> float:
        if 0.0 < v < 1.0:
            raise ValueError(f"{v} s: 0 (off) or 1 to 600 s")
        return v


#: The force limits per kg by default: the paper's [-2000, 10000] N at its 683 kg (× 683 gives them
#: back exactly in floating point, so a run at the nominal mass is bit-identical to the absolute ones).
DEFAULT_FORCE_MIN_PER_KG = -2000.0 / 683.0
DEFAULT_FORCE_MAX_PER_KG = 10000.0 / 683.0


def _force_bound(absolute: float | None, per_kg: float | None, default_per_kg: float, mass: float) -> float:
    """One force bound [N]: per kg × mass where given, else absolute, else the default per kg × mass."""
    if per_kg is not None:
        return per_kg * mass
    return absolute if absolute is not None else default_per_kg * mass


class LQRSettings(_Frozen):
    """Inner-loop TS-LQR (the paper's inner loop)."""

    # Each force bound is given absolute [N] or per kg [N/kg]; neither: the per-kg default (the
    # paper's limits at its 683 kg, so a heavier car keeps the same acceleration margin); both:
    # they must agree at the vehicle's mass (Config refuses an inconsistent pair before the run).
    force_min: FiniteFloat | None = Field(
        default=None, ge=-1e6, le=1e6,
        description="F_xR lower saturation [N], within [-1e6, 1e6], absolute (does not follow the mass); "
        "None = force_min_per_kg x mass (the paper presets: the published -2000 N)")
    force_max: FiniteFloat | None = Field(
        default=None, ge=-1e6, le=1e6,
        description="F_xR upper saturation [N], within [-1e6, 1e6], absolute (does not follow the mass); "
        "None = force_max_per_kg x mass (the paper presets: the published 10000 N)")
    delta_max: PositiveFloat = Field(default=math.radians(25.0), le=math.pi / 2,
                                     description="|δ| saturation [rad], (0, π/2]")
    force_min_per_kg: FiniteFloat | None = Field(
        default=None, ge=-100.0, le=0.0,
        description="F_xR lower saturation per kg of vehicle mass [N/kg = m/s^2], [-100, 0]; None "
        "(and no force_min) = -2000 N / 683 kg = -2.928 N/kg (the paper's limit at its mass, "
        "following the mass); with force_min too, both must agree at vehicle.mass")
    force_max_per_kg: FiniteFloat | None = Field(
        default=None, gt=0.0, le=100.0,
        description="F_xR upper saturation per kg of vehicle mass [N/kg], (0, 100]; None (and no "
        "force_max) = 10000 N / 683 kg = 14.64 N/kg (the paper's limit at its mass, following the "
        "mass); with force_max too, both must agree at vehicle.mass")
    friction_compensation: StrictBool = Field(default=True, description="add F̂_fr to the force command")
    friction_estimate: FrictionEstimate = Field(
        default=FrictionEstimate.WINDOW,
        description="compensated F̂_fr: MHE window fit or the paper's UIO formula"
    )
    oracle: StrictBool = Field(
        default=False, description="deprecated (old config files): same as simulate(oracle=True), the "
        "simulation's ablation with the true state and no compensation"
    )
    # Beyond the paper: proportional *feedback* on the speed error, not a feed-forward.
    speed_feedback: StrictBool = Field(
        default=True, description="speed-error feedback M (v_ref − v̂)/τ added to the force (beyond the paper)"
    )
    speed_time_constant: PositiveFloat = Field(
        default=0.3, ge=0.01, le=100.0,
        description="time constant τ [s] of the speed-error feedback M (v_ref − v̂)/τ, 0.01 to 100"
    )
    low_speed_resistance: StrictBool = Field(
        default=True, description="below the dynamic box's speed floor, add the model's road resistance the "
        "clipped premise leaves out, mu_o M g (1 - v/v_min), to the force and remove it from the "
        "force the MHE sees (beyond the paper: a launch from rest)")
    friction_step: StrictBool = Field(
        default=True,
        description="let the compensated friction follow a step of the road within the MHE window: "
        "a CUSUM test on the one-step UIO estimate's innovation against the window fit declares a "
        "step, and the one-step estimate is compensated until the window holds only later samples "
        "(beyond the paper: a sudden loss of grip; tsmpc.estimation.friction_step)")
    friction_step_threshold: FiniteFloat = Field(
        default=5.0, ge=2.0, le=50.0,
        description="friction_step's CUSUM decision threshold, in standard deviations of the "
        "innovation, 2 to 50 (higher: fewer false alarms, later detection)")
    # Quirks of the published run, not recommendations: the ``paper-as-run`` preset.
    true_state_feedback: StrictBool = Field(
        default=False, description="the inner law runs on the true plant state [v, α, ω] while the MHE is "
        "computed but unused; the compensation stays as configured (a quirk of the published run, "
        "not a recommendation; unlike the oracle ablation, which also drops the compensation)")
    law: InnerLaw = Field(
        default=InnerLaw.STATIC_GAIN, description="inner law: 'static-gain' (ours) or 'as-run' (a quirk of "
        "the published run, not a recommendation: Euler filter, previous clipped force fed back, "
        "no anti-windup)")
    steering_bias_rad: FiniteFloat = Field(
        default=0.0, ge=-math.pi, le=math.pi,
        description="as-run law: σ = δ + bias [rad] is fed back where the design expects δ, within "
        "[-π, π] (the published run: 30° = 0.5236 rad; a quirk, not a recommendation)")
    scheduling_speed_shift: FiniteFloat = Field(
        default=0.0, ge=-50.0, le=50.0,
        description="as-run law: the gains are scheduled on v + shift [m/s], within [-50, 50] (the "
        "published run: +2 m/s over the design interval [2, 18] m/s; a quirk, not a recommendation)")
    extrapolate_memberships: StrictBool = Field(
        default=False, description="as-run law: memberships are not clipped into the box, so scheduling "
        "values outside it extrapolate the vertex gains (a quirk of the published run, not a "
        "recommendation)")
    initial_filter_state: tuple[FiniteFloat, FiniteFloat] | None = Field(
        default=None, description="as-run law: Apkarian filter states (F₁(0) [N], σ₁(0) [rad]) at the "
        "start, σ₁ in the fed-back coordinate δ + steering_bias_rad (the published run: "
        "(4355.15, 0.52466)), within [-1e6, 1e6] N and [-π, π] rad; None = bumpless start at the "
        "steady state of the first reference")

    @model_validator(mode="after")
    def _check(self) -> LQRSettings:
        if self.force_min is not None and self.force_max is not None:
            _interval(self.force_min, self.force_max, "force_min/force_max")
        if self.initial_filter_state is not None:
            _within(self.initial_filter_state[:1], "initial_filter_state[F]", -1e6, 1e6, "N")
            _within(self.initial_filter_state[1:], "initial_filter_state[σ]", -math.pi, math.pi, "rad")
        if self.law != InnerLaw.AS_RUN:
            bad = [name for name, on in (
                ("steering_bias_rad", self.steering_bias_rad != 0.0),
                ("scheduling_speed_shift", self.scheduling_speed_shift != 0.0),
                ("extrapolate_memberships", self.extrapolate_memberships),
                ("initial_filter_state", self.initial_filter_state is not None)) if on]
            if bad:
                raise ConfigError(f"lqr: {', '.join(bad)}: only for the as-run law (set "
                                  "lqr.law = \"as-run\" or leave at the default)")
        return self

    def force_limits(self, vehicle: VehicleParams) -> tuple[float, float]:
        """(F_min, F_max) [N] for ``vehicle``: the per-kg limits × its mass where set, else the
        absolute ones where set, else the per-kg defaults × its mass (at the paper's 683 kg exactly
        the published -2000 N and 10000 N)."""
        lo = _force_bound(self.force_min, self.force_min_per_kg, DEFAULT_FORCE_MIN_PER_KG, vehicle.mass)
        hi = _force_bound(self.force_max, self.force_max_per_kg, DEFAULT_FORCE_MAX_PER_KG, vehicle.mass)
        if not lo < hi:
            raise ConfigError(f"lqr: force limits for a {vehicle.mass:g} kg vehicle give "
                              f"F_min = {lo:g} N >= F_max = {hi:g} N")
        return lo, hi


class MHESettings(_Frozen):
    """TS-MHE-UIO (the paper's TS-MHE-UIO)."""

    N: StrictInt = Field(default=30, ge=2, le=300, description="estimation horizon [inner steps], 2 to 300 "
                         "(N·Td <= 10 s)")
    Q: tuple[FiniteFloat, ...] = Field(default=(10.0, 10.0, 2.0), description="diag process weight, entries "
                                       "in [1e-8, 1e8]")
    R: tuple[FiniteFloat, ...] = Field(default=(0.033, 0.033), description="diag measurement weight, "
                                       "entries in [1e-8, 1e8]")
    P: tuple[FiniteFloat, ...] = Field(default=(2.0, 2.0, 2.0), description="diag arrival-cost weight, "
                                       "entries in [1e-8, 1e8]")
    x_min: tuple[FiniteFloat, FiniteFloat, FiniteFloat] = Field(
        default=(0.0, -0.1, -1.4), description="[v, α, ω] lower bounds, each within [-1000, 1000] (a "
        "bound that wide is no bound: allowed, unlike 1e300)")
    x_max: tuple[FiniteFloat, FiniteFloat, FiniteFloat] = Field(
        default=(18.0, 0.1, 1.4), description="[v, α, ω] upper bounds, each within [-1000, 1000]")
    form: MHEForm = Field(
        default=MHEForm.WINDOW, description="'window' (ours: window-constant friction force, compiled) or "
        "'uio' (the paper's form: friction eliminated through E_d; numpy path, slower)")
    # beyond the paper: the yaw-model margin (issue 35; tsmpc.estimation.mhe_margin)
    margin_slip_rate: NonNegFloat = Field(
        default=0.01, le=10.0, description="yaw-model margin: RMS of the window's slip-equation residual "
        "[rad/s] at which Q_omega starts to grow (the model's slip dynamics do not fit the car), 0 to 10; "
        "0 = off (the paper)")
    margin_max: FiniteFloat = Field(
        default=15.0, ge=1.0, le=1e4, description="yaw-model margin: largest factor on Q_omega, 1 to 1e4")
    margin_rise_s: PositiveFloat = Field(
        default=1.0, le=1e4, description="yaw-model margin: time constant of a growing margin [s], "
        "up to 1e4")
    margin_decay_s: PositiveFloat = Field(
        default=20.0, le=1e4, description="yaw-model margin: time constant of a shrinking margin [s] "
        "(a wrong model stays wrong), up to 1e4")
    margin_linear_share: NonNegFloat = Field(
        default=0.5, le=1.0, description="yaw-model margin: only windows whose axle slips stay within this "
        "share of the model's saturation slip mu F_z / C count (the linear tyre the model has), 0 to 1; "
        "0 = every window")

    @model_validator(mode="after")
    def _check(self) -> MHESettings:
        _diag(self.Q, "Q", 3)
        _diag(self.R, "R", 2)
        _diag(self.P, "P", 3)
        for i in range(3):
            _interval(self.x_min[i], self.x_max[i], f"x_min/x_max[{i}]")
        for i, unit in enumerate(("m/s", "rad", "rad/s")):
            _within((self.x_min[i], self.x_max[i]), f"x_min/x_max[{i}]", -1000.0, 1000.0, unit)
        return self


class NoiseSettings(_Frozen):
    """Zero-mean Gaussian sensor noise (the paper's scenario), standard deviations before ``scale``."""

    v: NonNegFloat = Field(default=0.005, le=10.0, description="σ of v [m/s], 0 to 10 (also after scale)")
    omega: NonNegFloat = Field(default=1e-4, le=1.0, description="σ of ω [rad/s], 0 to 1 (also after scale)")
    position: NonNegFloat = Field(default=0.001, le=10.0, description="σ of X and Y [m], 0 to 10 (also "
                                  "after scale)")
    theta: NonNegFloat = Field(default=1e-4, le=1.0, description="σ of θ [rad], 0 to 1 (also after scale)")
    scale: NonNegFloat = Field(default=1.0, le=1e4, description="multiplies every σ, 0 to 1e4")

    @model_validator(mode="after")
    def _scaled(self) -> NoiseSettings:
        for name, cap, unit in (("v", 10.0, "m/s"), ("omega", 1.0, "rad/s"), ("position", 10.0, "m"),
                                ("theta", 1.0, "rad")):
            sigma = getattr(self, name) * self.scale
            if sigma > cap:
                raise ConfigError(f"{name} * scale = {sigma:.3g} {unit}: a sensor noise beyond "
                                  f"{cap:g} {unit} is not a sensor (lower {name} or scale)")
        return self


class PlannerSettings(_Frozen):
    """Speed-profile limits of the planner (the paper's scenario)."""

    v_max: PositiveFloat = Field(default=14.7, le=150.0, description="maximum speed [m/s], (0, 150]")
    a_lat_max: PositiveFloat = Field(default=3.0, le=50.0, description="lateral acceleration limit [m/s^2], "
                                     "(0, 50]")
    a_lon_max: PositiveFloat = Field(default=2.6, le=50.0, description="longitudinal acceleration limit "
                                     "[m/s^2], (0, 50]")
    a_brake_max: PositiveFloat = Field(default=3.0, le=50.0, description="braking deceleration limit "
                                       "[m/s^2], (0, 50]")
    v_start: NonNegFloat = Field(default=1.0, le=150.0, description="speed at the start of an open path "
                                 "[m/s], 0 to 150")


class MetricsSettings(_Frozen):
    """What the tables of a comparison show (Table 5; the published run). metrics.json always holds both RMSE
    conventions."""

    paper_run_rmse: StrictBool = Field(
        default=False, description="also show each method's RMSE under the published run's convention "
        "(the published run: pose errors at the start of each outer step, first K − 10 steps; v, ω at its "
        "end, K + 20 entries with 20 zeros) beside ours in the tables")


class PurePursuitSettings(_Frozen):
    """Pure pursuit (:mod:`tsmpc.control.pure_pursuit`): look-ahead distance
    L_d = clip(lookahead_time_s · v, lookahead_min_m, lookahead_max_m) with v the commanded speed.
    Defaults from the documented search on the built-in circuit (examples/tune_baselines.py)."""

    lookahead_time_s: NonNegFloat = Field(default=0.45, le=10.0, description="look-ahead time: L_d grows "
                                           "with the speed as lookahead_time_s · v [s], 0 to 10")
    lookahead_min_m: PositiveFloat = Field(default=5.0, le=1000.0, description="shortest look-ahead "
                                           "distance [m], above 0 to 1000")
    lookahead_max_m: PositiveFloat = Field(default=40.0, le=1000.0, description="longest look-ahead "
                                           "distance [m], above 0 to 1000")

    @model_validator(mode="after")
    def _check(self) -> PurePursuitSettings:
        _interval(self.lookahead_min_m, self.lookahead_max_m, "lookahead_min_m/lookahead_max_m")
        return self


class StanleySettings(_Frozen):
    """Stanley's law (:mod:`tsmpc.control.stanley`):
    δ = k_ψ ψ_e + atan(k e_fa / (k_soft + v)) (+ the curvature feed-forward when switched on).
    Defaults from the documented search on the built-in circuit (examples/tune_baselines.py)."""

    heading_gain: PositiveFloat = Field(
        default=0.3, le=2.0, description="k_ψ on the heading error, above 0 to 2 (1 = the classic law; at "
        "T_c the heading term's per-step loop gain is k_ψ v T_c / L)")

    gain: PositiveFloat = Field(default=2.0, le=100.0, description="cross-track gain k [1/s], above 0 to 100")
    softening_speed: NonNegFloat = Field(
        default=4.0, le=100.0, description="k_soft added to v in atan(k e / (k_soft + v)) [m/s], 0 to 100")
    curvature_feedforward: StrictBool = Field(
        default=True, description="feed-forward atan(L κ_d) − k_ψ atan(a κ_d): zero steady-state error on a "
        "circle for a CoG-referenced path (False = the classic law)")


class BaselineSettings(_Frozen):
    """The outer-loop baselines users pick instead of TS-MPC (issue 26). The kinematic LQR uses the
    kinematic LMI design's gains and the LTV-MPC the TS-MPC's weights and constraints (``mpc``):
    only the geometric laws have settings of their own."""

    pure_pursuit: PurePursuitSettings = PurePursuitSettings()
    stanley: StanleySettings = StanleySettings()
    along_track_gain: NonNegFloat = Field(
        default=8.0, le=20.0, description="speed channel of the geometric laws: v_ref = v_d cos e_θ + "
        "gain · e_x, proportional feedback on the along-track error [1/s], 0 to 20")


# -- the vehicle the controllers meet (issue 21): scenario vocabulary and the fusion switches -----
#: Strict field types of this section: a number is a number (never a bool or a string), a flag is
#: true or false (never "yes" or 1).
_Num = Annotated[float, Strict()]
_Flag = Annotated[bool, Strict()]
_Count = Annotated[int, Strict()]

class PlantScales(_Frozen):
    """The plant's parameters as scales of the config's vehicle (the controllers keep the config's
    unless ``scenario.oracle_tuned``): 1 = as the controllers assume. Plausible ranges: a car
    loaded or emptied (mass ×0.5–2), tyres of another make or pressure (stiffness ×0.3–3)."""

    mass_scale: _Num = Field(default=1.0, ge=0.5, le=2.0, allow_inf_nan=False,
                              description="plant mass = scale × vehicle.mass [-], 0.5 to 2")
    inertia_scale: _Num = Field(default=1.0, ge=0.5, le=2.0, allow_inf_nan=False,
                                 description="plant yaw inertia = scale × vehicle.inertia [-], 0.5 to 2")
    cornering_front_scale: _Num = Field(
        default=1.0, ge=0.3, le=3.0, allow_inf_nan=False,
        description="plant front cornering stiffness = scale × vehicle C_f [-], 0.3 to 3")
    cornering_rear_scale: _Num = Field(
        default=1.0, ge=0.3, le=3.0, allow_inf_nan=False,
        description="plant rear cornering stiffness = scale × vehicle C_r [-], 0.3 to 3")
    cog_to_front_scale: _Num = Field(
        default=1.0, ge=0.5, le=1.5, allow_inf_nan=False,
        description="plant CoG-to-front-axle distance a = scale × vehicle.a, the wheelbase kept "
        "(b = a + b − scale a: the CoG moves, e.g. with the load) [-], 0.5 to 1.5")
    mu_tyre: _Num | None = Field(default=None, ge=0.1, le=2.0, allow_inf_nan=False,
                                  description="peak grip of the plant's tyres [-], 0.1 to 2; None = "
                                  "tyre.mu_tyre")
    combined_slip: _Flag = Field(default=False, description="the plant's rear tyre has a friction ellipse "
                                "(tyre.combined_slip)")
    grip_scales_with_road: _Flag = Field(default=False, description="the plant's tyre grip scales with "
                                        "mu(road) (tyre.scale_grip_with_road)")
    steering_offset_rad: _Num = Field(
        default=0.0, ge=-0.05, le=0.05, allow_inf_nan=False,
        description="the plant's wheels steer this much more than commanded (a misaligned steering; the "
        "steering the plant applies = commanded + offset; a measured steering angle does not include it) "
        "[rad], -0.05 to 0.05")


class SensorFaults(_Frozen):
    """What the sensors deliver instead of the truth (issue 21), on top of the seeded noise of
    ``noise``. Biases and drifts add to [v, ω, θ]; drifts grow linearly from t = 0."""

    dropout_probability: _Num = Field(
        default=0.0, ge=0.0, le=0.5, allow_inf_nan=False,
        description="each T_d sample is lost with this probability (seeded from the run's seed) "
        "[-], 0 to 0.5: delivered as NaN, or as the previous sample with dropout_hold")
    dropout_hold: _Flag = Field(default=False, description="a lost sample repeats the previous one (a "
                               "stalled bus) instead of arriving as NaN")
    v_bias: _Num = Field(default=0.0, ge=-2.0, le=2.0, allow_inf_nan=False,
                          description="speed-sensor offset [m/s], -2 to 2")
    omega_bias: _Num = Field(default=0.0, ge=-0.2, le=0.2, allow_inf_nan=False,
                              description="yaw-rate sensor offset [rad/s], -0.2 to 0.2")
    theta_bias: _Num = Field(default=0.0, ge=-0.2, le=0.2, allow_inf_nan=False,
                              description="heading sensor offset [rad], -0.2 to 0.2")
    v_drift: _Num = Field(default=0.0, ge=-0.05, le=0.05, allow_inf_nan=False,
                           description="speed-offset growth [m/s per s], -0.05 to 0.05")
    omega_drift: _Num = Field(default=0.0, ge=-0.005, le=0.005, allow_inf_nan=False,
                               description="yaw-rate offset growth [rad/s per s], -0.005 to 0.005")
    theta_drift: _Num = Field(default=0.0, ge=-0.005, le=0.005, allow_inf_nan=False,
                               description="heading offset growth [rad per s], -0.005 to 0.005")
    delay_s: _Num = Field(default=0.0, ge=0.0, le=0.5, allow_inf_nan=False,
                           description="every sample arrives this late (rounded to whole T_d) [s], "
                           "0 to 0.5")
    gnss_noise_scale: _Num = Field(
        default=1.0, ge=1.0, le=100.0, allow_inf_nan=False,
        description="the position (X, Y) noise sigma is this multiple of noise.position × "
        "noise.scale [-], 1 to 100 (the controllers keep assuming the configured sigma)")
    # the sensor class of issue 35 (tsmpc.sensors): measured = scale · (true + noise) + bias
    # + drift · t + random walk, per sensor; each sensor at its own rate
    x_bias: _Num = Field(default=0.0, ge=-10.0, le=10.0, allow_inf_nan=False,
                          description="pose sensor's X offset [m], -10 to 10")
    y_bias: _Num = Field(default=0.0, ge=-10.0, le=10.0, allow_inf_nan=False,
                          description="pose sensor's Y offset [m], -10 to 10")
    position_scale: _Num = Field(default=1.0, ge=0.8, le=1.2, allow_inf_nan=False,
                                  description="pose sensor's X and Y are this multiple of the true "
                                  "position (a map scale error about the origin) [-], 0.8 to 1.2")
    v_scale: _Num = Field(default=1.0, ge=0.8, le=1.2, allow_inf_nan=False,
                           description="speed sensor's scale factor (e.g. a wrong wheel radius) [-], "
                           "0.8 to 1.2")
    omega_scale: _Num = Field(default=1.0, ge=0.8, le=1.2, allow_inf_nan=False,
                               description="yaw-rate sensor's scale factor [-], 0.8 to 1.2")
    position_walk: _Num = Field(default=0.0, ge=0.0, le=1.0, allow_inf_nan=False,
                                 description="random-walk drift of X and Y (each): the offset's "
                                 "standard deviation grows as position_walk · sqrt(t) [m/sqrt(s)], 0 to 1")
    theta_walk: _Num = Field(default=0.0, ge=0.0, le=0.01, allow_inf_nan=False,
                              description="random-walk drift of the heading [rad/sqrt(s)], 0 to 0.01")
    v_walk: _Num = Field(default=0.0, ge=0.0, le=0.1, allow_inf_nan=False,
                          description="random-walk drift of the speed offset [m/s/sqrt(s)], 0 to 0.1")
    omega_walk: _Num = Field(default=0.0, ge=0.0, le=0.01, allow_inf_nan=False,
                              description="random-walk drift of the yaw-rate offset (a gyro's bias "
                              "instability) [rad/s/sqrt(s)], 0 to 0.01")
    pose_heading: _Flag = Field(default=True, description="the pose sensor delivers the heading with X "
                               "and Y (false: a position-only fix, theta always missing)")
    pose_rate_hz: _Num | None = Field(
        default=None, gt=0.0, allow_inf_nan=False,
        description="sample rate of the pose sensor (X, Y, theta) [Hz], above 0 to 1/rates.Td; a sample "
        "that is not due is missing, as a dropout is; None = every T_d")
    v_rate_hz: _Num | None = Field(default=None, gt=0.0, allow_inf_nan=False,
                                    description="sample rate of the speed sensor [Hz], above 0 to "
                                    "1/rates.Td; None = every T_d")
    omega_rate_hz: _Num | None = Field(default=None, gt=0.0, allow_inf_nan=False,
                                        description="sample rate of the yaw-rate sensor [Hz], above 0 to "
                                        "1/rates.Td; None = every T_d")


class FrictionEvent(_Frozen):
    """A change of μ(road) during a run (issue 21): from a time, a travelled distance or
    a corner's apex, as a step (ramp 0) or a linear ramp, for a while or to the end. Exactly one
    of ``at_s``, ``at_m``, ``at_corner``. Time triggers take ``ramp_s`` / ``duration_s``, the
    distance trigger ``ramp_m`` / ``length_m``. Events apply in order over the base profile."""

    mu: _Num = Field(ge=0.0, le=1.5, allow_inf_nan=False, description="mu(road) of the surface "
                      "[-], 0 to 1.5")
    at_s: _Num | None = Field(default=None, ge=0.0, le=1e5, allow_inf_nan=False,
                               description="start time [s] since the run's start, 0 to 1e5")
    at_m: _Num | None = Field(default=None, ge=0.0, le=1e7, allow_inf_nan=False,
                               description="start at this travelled distance [m], 0 to 1e7")
    at_corner: _Count | None = Field(
        default=None, ge=1, le=1000, description="start at the apex of the k-th corner of the reference "
        "(1-based): the k-th run of samples with |omega_d| above half the reference's largest, at "
        "its largest |omega_d|")
    ramp_s: _Num | None = Field(default=None, ge=0.0, le=600.0, allow_inf_nan=False,
                                 description="transition time [s] (time and corner triggers), 0 to 600")
    duration_s: _Num | None = Field(default=None, gt=0.0, le=1e5, allow_inf_nan=False,
                                     description="how long the surface lasts [s]; None = to the end")
    ramp_m: _Num | None = Field(default=None, ge=0.0, le=1e4, allow_inf_nan=False,
                                 description="transition length [m] (distance trigger), 0 to 1e4")
    length_m: _Num | None = Field(default=None, gt=0.0, le=1e7, allow_inf_nan=False,
                                   description="how long the surface lasts [m]; None = to the end")

    @model_validator(mode="after")
    def _trigger(self) -> FrictionEvent:
        given = [n for n in ("at_s", "at_m", "at_corner") if getattr(self, n) is not None]
        if len(given) != 1:
            raise ConfigError("scenario.friction: give exactly one of at_s, at_m, at_corner "
                              f"(got {', '.join(given) or 'none'})")
        by_distance = self.at_m is not None
        wrong = [n for n in (("ramp_s", "duration_s") if by_distance else ("ramp_m", "length_m"))
                 if getattr(self, n) is not None]
        if wrong:
            unit = "metres (ramp_m, length_m)" if by_distance else "seconds (ramp_s, duration_s)"
            raise ConfigError(f"scenario.friction: {', '.join(wrong)} does not fit the trigger "
                              f"{given[0]}: it takes {unit}")
        return self


class ScenarioActuators(_Frozen):
    """Actuator dynamics between the controllers' command and the plant (issue 21;
    :mod:`tsmpc.vehicle.actuators`); all zero = ideal actuators."""

    steering_time_constant_s: _Num = Field(default=0.0, ge=0.0, le=1.0, allow_inf_nan=False,
                                            description="steering servo lag [s], 0 to 1")
    steering_rate_limit: _Num | None = Field(
        default=None, gt=0.0, le=20.0, allow_inf_nan=False,
        description="steering rate limit [rad/s], above 0 to 20; None = none")
    force_time_constant_s: _Num = Field(default=0.0, ge=0.0, le=2.0, allow_inf_nan=False,
                                         description="drive-force lag [s], 0 to 2")
    measured_steering: _Flag = Field(default=False, description="the platform measures the applied steering "
                                    "angle and gives it to the MHE")

    @property
    def active(self) -> bool:
        """Any actuator dynamics at all."""
        return (self.steering_time_constant_s > 0 or self.steering_rate_limit is not None
                or self.force_time_constant_s > 0)


class KnownPart(StrEnum):
    """What of the plant a run tells the controllers (``scenario.known``; all of it:
    ``scenario.oracle_tuned``)."""

    MASS = "mass"  #: the plant's mass in the models and designs
    INERTIA = "inertia"  #: its yaw inertia
    CORNERING_STIFFNESS = "cornering_stiffness"  #: its front and rear cornering stiffness
    COG = "cog"  #: its CoG position (a, b)
    SENSOR_BIASES = "sensor_biases"  #: calibrated sensors: biases, drifts and scale factors removed
    STEERING_OFFSET = "steering_offset"  #: calibrated steering: the wheels' offset commanded away


class ScenarioSettings(_Frozen):
    """The conditions a run meets beyond the reference (issue 21), written without Python:
    the plant's parameters, μ(road) events, sensor faults and actuators. Applied by
    :func:`tsmpc.conditions.apply_conditions` (``tsmpc compare/run`` and sweeps); the defaults
    change nothing."""

    plant: PlantScales = PlantScales()
    sensors: SensorFaults = SensorFaults()
    friction: tuple[FrictionEvent, ...] = Field(default=(),
                                                description="mu(road) events over the base profile")
    base_mu: _Num | None = Field(default=None, ge=0.0, le=1.5, allow_inf_nan=False,
                                  description="constant mu(road) instead of the scenario's profile "
                                  "(the paper's by time) [-], 0 to 1.5; None = the profile")
    actuators: ScenarioActuators = ScenarioActuators()
    oracle_tuned: _Flag = Field(
        default=False, description="the controllers' vehicle is the plant's (scales applied): models and "
        "LMI designs built from the true parameters, and the sensors calibrated (biases and drifts "
        "removed); dropouts, delay and noise stay (the oracle-tuned comparison row, issue 21; "
        "never a deployable setting)")
    known: tuple[KnownPart, ...] = Field(
        default=(), description="what the controllers are told of the plant, part by part: 'mass', "
        "'inertia', 'cornering_stiffness', 'cog' (the plant's value in the models and LMI designs), "
        "'sensor_biases', 'steering_offset' (calibrated); all of them is oracle_tuned. A diagnostic "
        "that prices one error of a draw at a time against the oracle-tuned row; never a deployable "
        "setting")
    replan_for_force_budget: _Flag = Field(
        default=False, description="the reference is re-timed along its path so that it never asks for "
        "more acceleration than the plant vehicle's force budget allows ((F_max - mu M g - drag)/M "
        "at the base mu, 90 %): the planner knows the real vehicle")


class FusionSettings(_Frozen):
    """Measurement fusion and online adaptation beyond the paper (issue 21): each a named switch,
    on by default, off in the ``paper`` and ``paper-as-run`` presets. Where each signal
    comes from: docs/mismatch.md."""

    reject_repeated_samples: _Flag = Field(
        default=True, description="a sample bit-identical to the previous one (a stalled sensor bus "
        "re-delivering it) is treated as missing, like NaN")
    predict_pose: _Flag = Field(
        default=True, description="a missing pose (NaN, stale, repeated) is replaced by the last good pose "
        "dead-reckoned with the estimate (v, alpha, omega), not held")
    course_slip: _Flag = Field(
        default=True, description="the slip the outer loop uses is corrected by the course over ground: "
        "alpha_hat + kappa a_y + beta, fitted online (least squares) to the measured course minus "
        "heading over a chord of the last MPC poses")
    course_speed: _Flag = Field(
        default=True, description="the speed sensor's offset and scale factor are estimated from the "
        "speed over ground (each interval between two measured poses) and removed before the MHE")
    gyro_bias: _Flag = Field(
        default=True, description="the yaw-rate sensor's bias is estimated as a slowly varying state "
        "(the integrated measured yaw rate against the measured heading's change over chords of 1 s; "
        "needs the pose's heading, else the estimate holds its prior 0) and removed from omega before "
        "the MHE, the inner loop and the course fusion")
    steering_offset: _Flag = Field(
        default=True, description="the wheels' steering-angle offset (a misalignment of the steering) is "
        "estimated as a slow state, fitted from the steady yaw balance of the MHE's single-track model "
        "(the measured yaw rate, bias removed, against the steering sent; least squares with forgetting, "
        "frozen below 2 m/s, above 4 m/s^2 of lateral acceleration and while the sample, the MHE or the "
        "inner loop is unusable), and subtracted from the steering command: a bias correction without "
        "feedback into its own fit")
    stiffness_estimate: _Flag = Field(
        default=True, description="the lateral model of the MHE's and the inner loop's models is fitted "
        "online from the course over ground and the measured lateral and yaw accelerations: the axle "
        "cornering stiffnesses per axle (least squares F_y = C alpha; with lateral_fit, until the joint "
        "fit takes over); the LMI gains stay")
    lateral_fit: _Flag = Field(
        default=True, description="with stiffness_estimate: the lateral model fitted jointly (the axle "
        "stiffnesses, the yaw inertia and the CoG, an extended Kalman filter on the same cornering "
        "chords) and handed to the MHE and the inner loop where the reference runs straight, once it "
        "departs from the model in force by over one sigma")
    mass_estimate: _Flag = Field(
        default=True, description="the part of the friction estimate that follows the acceleration is the "
        "inertia of a mass error: estimated online (high-passed least squares), removed from the "
        "compensation and given to the speed feedback's mass")


class RecoverySettings(_Frozen):
    """What the cascade does when its sensors fail for longer than its estimator can bridge, and
    how it recovers (issue 38; beyond the paper, off in the ``paper`` presets)."""

    enabled: _Flag = Field(
        default=True, description="blind stop, recovery and the pose gate's re-initialisation (below)")
    blind_after_s: PositiveFloat = Field(
        default=0.5, le=10.0, description="no speed / yaw-rate sample accepted for this long [s]: the "
        "cascade is blind and brakes to a stop on its last steering (a minimal-risk manoeuvre) "
        "until a valid sample comes; within (0, 10]")
    stop_decel: PositiveFloat = Field(
        default=3.0, le=10.0, description="deceleration of the blind stop [m/s^2], within (0, 10] (and "
        "the force limits)")
    pose_reinit_s: PositiveFloat = Field(
        default=2.0, le=60.0, description="fresh poses rejected as jumps for this long [s], each "
        "consistent with the one before: the dead-reckoned pose is wrong, not them; the gate "
        "takes them; within (0, 60]")
    yaw_rate_bound: _Flag = Field(
        default=True, description="on the restart after a blind stop (until the car has the reference's "
        "speed again) the yaw-rate reference the outer loop hands the TS-LQR is bounded by what the car's "
        "speed allows, |omega| <= max(v, 0) tan(lqr.delta_max) / (a + b) [rad/s] (the kinematic "
        "bicycle's tightest turn; v the accepted measured speed [m/s], else the last estimate): a car "
        "at rest is not asked to turn in place; acts with enabled only")


class GripSource(StrEnum):
    """Where the speed governor's grip comes from."""

    ESTIMATE = "estimate"  #: the inner loop's friction estimate (and mass estimate)
    ORACLE = "oracle"  #: the true mu(road) of the scenario (simulation only: the reference row)


class GovernorSettings(_Frozen):
    """The speed governor (issue 36; beyond the paper: on by default, off in the ``paper`` presets):
    the reference is re-timed online so that the speed and curvature ahead need at most ``margin``
    x the estimated grip, and its acceleration at most what the drive force leaves after the road's
    resistance (tsmpc.control.governor). Its grip model is the road the run declares (the
    plan check's reading): read from the road's resistance when the tyres' grip follows the road
    (``tyre.scale_grip_with_road`` or ``scenario.plant.grip_scales_with_road``), else the tyre's own
    grip, lowered only by a spin of the rear wheel."""

    enabled: _Flag = Field(default=True, description="re-time the reference online to the estimated grip "
                           "and to the drive force's budget")
    margin: PositiveFloat = Field(
        default=0.8, le=1.0, description="share of the estimated grip mu g the reference ahead may use "
        "(lateral and driven-axle longitudinal acceleration combined) [-], (0, 1]")
    traction_margin: PositiveFloat = Field(
        default=0.5, le=1.0, description="share of the driven axle's grip the reference's own acceleration "
        "may use [-], (0, 1]: the speed loop's transients ask about twice the reference's")
    rate_down: PositiveFloat = Field(
        default=0.15, le=10.0, description="fastest decrease of the governed rate dtau/dt [1/s], (0, 10]")
    rate_up: PositiveFloat = Field(
        default=0.05, le=10.0, description="fastest increase of the governed rate back to 1 [1/s], (0, 10]")
    rate_min: PositiveFloat = Field(
        default=0.3, le=1.0, description="the governed rate never goes below this [-], (0, 1]")
    deadband: NonNegFloat = Field(
        default=0.05, le=0.5, description="the governor acts only when the estimated grip is below "
        "(1 - deadband) x tyre.mu_tyre, the grip the plan was made for [-], 0 to 0.5")
    grip_time_constant_s: PositiveFloat = Field(
        default=0.3, le=10.0, description="low-pass time constant of the grip estimate [s], (0, 10] "
        "(falls at once below it: a lower estimate is taken within one MPC step)")
    grip_source: GripSource = Field(
        default=GripSource.ESTIMATE, description="'estimate' (the friction estimate of the inner loop) or "
        "'oracle' (the scenario's true mu(road): the reference row, simulation only)")


class Config(_Frozen):
    """Everything a run needs. ``Config()`` is the paper's setting."""

    vehicle: VehicleParams = VehicleParams()
    tyre: TyreParams = TyreParams()
    rates: Rates = Rates()
    kinematic_box: KinematicBox = KinematicBox()
    dynamic_box: DynamicBox = DynamicBox()
    kinematic_lmi: KinematicLMISettings = KinematicLMISettings()
    dynamic_lmi: DynamicLMISettings = DynamicLMISettings()
    mpc: MPCSettings = MPCSettings()
    lqr: LQRSettings = LQRSettings()
    mhe: MHESettings = MHESettings()
    noise: NoiseSettings = NoiseSettings()
    planner: PlannerSettings = PlannerSettings()
    metrics: MetricsSettings = MetricsSettings()
    baselines: BaselineSettings = BaselineSettings()
    scenario: ScenarioSettings = ScenarioSettings()  # the conditions a run meets (issue 21)
    fusion: FusionSettings = FusionSettings()  # fusion and adaptation beyond the paper (issue 21)
    recovery: RecoverySettings = RecoverySettings()  # blind stop and recovery (issue 38)
    governor: GovernorSettings = GovernorSettings()  # grip-aware speed governor (issue 36)
    seed: StrictInt = Field(default=0, ge=0, lt=2**63, description="seed of every random draw of a run, "
                            "0 to 2^63 - 1")
    divergence_bound_m: PositiveFloat = Field(
        default=5.0, le=1000.0,
        description="|e_y| [m] beyond which a run is diverged (when the track width is unknown), "
        "(0, 1000]"
    )

    @model_validator(mode="after")
    def _horizons(self) -> Config:
        # Cross-field: the horizons in seconds (a 400-step MPC at Tc = 1 s looks 400 s ahead).
        t_mpc = self.mpc.N * self.rates.Tc
        if t_mpc > 60.0 + 1e-9:
            raise ConfigError(f"mpc.N * rates.Tc = {t_mpc:g} s: the MPC horizon must be <= 60 s")
        t_mhe = self.mhe.N * self.rates.Td
        if t_mhe > 10.0 + 1e-9:
            raise ConfigError(f"mhe.N * rates.Td = {t_mhe:g} s: the MHE window must be <= 10 s")
        return self

    @model_validator(mode="after")
    def _sensor_rates(self) -> Config:
        # Cross-field: a sensor samples at most once per controller call (its base rate 1/T_d).
        base = 1.0 / self.rates.Td
        for name in ("pose_rate_hz", "v_rate_hz", "omega_rate_hz"):
            hz = getattr(self.scenario.sensors, name)
            if hz is not None and hz > base * (1.0 + 1e-9):
                raise ConfigError(f"scenario.sensors.{name} = {hz:g} Hz: above the sensors' base rate "
                                  f"1/rates.Td = {base:g} Hz")
        return self

    @model_validator(mode="after")
    def _force_pairs(self) -> Config:
        # Before the run: a bound given both absolute and per kg must agree at this vehicle's mass
        # (else which one the car has is a guess), and the limits must leave F_min < F_max.
        m = self.vehicle.mass
        for side, absolute, per_kg in (("min", self.lqr.force_min, self.lqr.force_min_per_kg),
                                       ("max", self.lqr.force_max, self.lqr.force_max_per_kg)):
            if absolute is not None and per_kg is not None and not math.isclose(
                    absolute, per_kg * m, rel_tol=1e-9, abs_tol=1e-6):
                raise ConfigError(
                    f"lqr.force_{side} = {absolute:g} N and lqr.force_{side}_per_kg = {per_kg:g} N/kg "
                    f"disagree for a {m:g} kg vehicle ({per_kg * m:g} N): set one of them (per kg "
                    "follows vehicle.mass, absolute does not)")
        self.lqr.force_limits(self.vehicle)
        return self

    @classmethod
    def preset(cls, name: str) -> Config:
        """A named configuration (:data:`PRESETS`): ``"default"`` (our best cascade),
        ``"paper"`` (the cascade as published: no speed-error feedback, the paper's one-step
        UIO friction estimate compensated; every weight is the paper's in both) or
        ``"paper-as-run"`` (the published run's simulation with its quirks, docs: Table 5 explained: never a
        recommendation)."""
        return validate(cls, _preset_dict(name), source=f"preset {name!r}")

    def to_dict(self) -> dict[str, Any]:
        """JSON/TOML-ready nested dict (enums as strings)."""
        return self.model_dump(mode="json")

    def to_toml(self) -> str:
        """Serialise to TOML; :func:`load_config` reads it back to an equal object."""
        import tomli_w

        # TOML has no null: unset optional fields are omitted (they load back as None)
        return tomli_w.dumps(self.model_dump(mode="json", exclude_none=True))


T = TypeVar("T", bound=BaseModel)

#: Every switch of :class:`FusionSettings` off (the paper has none of them).
_FUSION_OFF = {"reject_repeated_samples": False, "predict_pose": False, "course_slip": False,
               "course_speed": False, "gyro_bias": False, "steering_offset": False,
               "stiffness_estimate": False, "lateral_fit": False,
               "mass_estimate": False}

#: Named configurations: overrides of ``Config()`` (beyond the paper). Select with ``Config.preset(name)``,
#: ``preset = "paper"`` at the top of a TOML file, or ``--preset paper`` on the command line.
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    # The cascade as published (paper Sec. 3.2, 4): TS-LQR from the LMI design with the static
    # reference gain, friction compensation with the paper's UIO formula (P-disturb_estimation),
    # no speed-error feedback, the body-frame kinematic error model against the reference heading
    # as given (no slip-aware loop, no tangent heading). The weights are the paper's already.
    # Its force limits are the published absolute [-2000, 10000] N (they do not follow the mass).
    "paper": {"lqr": {"speed_feedback": False, "friction_estimate": "uio", "low_speed_resistance": False,
                      "friction_step": False, "force_min": -2000.0, "force_max": 10000.0},
              "mpc": {"slip_aware": False, "tangent_heading": False, "step_average_reference": False,
                      "offset_free_s": 0.0},
              "fusion": _FUSION_OFF, "recovery": {"enabled": False}, "governor": {"enabled": False},
              "mhe": {"margin_slip_rate": 0.0}},
    # The paper as it was run (the published run): the ``paper`` preset plus every quirk of the published
    # simulation, each its own switch. Quirks of that run, not recommendations; never the default.
    "paper-as-run": {
        "vehicle": {"mu_nominal": 0.65},  # the controller models' nominal μ (M g μ = 4355.15 N)
        "rates": {"Td": 0.001, "inner_steps_per_outer": 101},  # inner loop + MHE at 1 ms, 101 steps
        "dynamic_box": {"v": (2.0, 18.0)},  # the design interval of the speed premise
        # feasibility LMI, 8 vertices, Euler; the point kept: the LMIs' analytic centre (the
        # published solver's point is unknown; the centre is what an interior-point method
        # converges to without objective, in any units)
        "dynamic_lmi": {"formulation": "feasibility-euler", "feasible_point": "analytic-center"},
        "lqr": {"speed_feedback": False, "friction_estimate": "uio", "low_speed_resistance": False,
                "friction_step": False, "force_min": -2000.0, "force_max": 10000.0,  # published, absolute
                "friction_compensation": False,  # the force command was the clipped LQR output
                "true_state_feedback": True,  # the inner law on the true states; MHE unused
                "law": "as-run", "steering_bias_rad": 0.5236, "scheduling_speed_shift": 2.0,
                "extrapolate_memberships": True, "initial_filter_state": (4355.15, 0.52466)},
        "mpc": {"slip_aware": False, "tangent_heading": False, "step_average_reference": False,
                      "offset_free_s": 0.0},
        "noise": {"scale": 0.0},  # the noise model existed but was not called
        "metrics": {"paper_run_rmse": True},
        "fusion": _FUSION_OFF,
        "recovery": {"enabled": False},
        "governor": {"enabled": False},
        "mhe": {"margin_slip_rate": 0.0},
    },
}


def _preset_dict(name: str) -> dict[str, Any]:
    """The overrides of preset ``name`` (case-insensitive, like method names: "Paper" = "paper")."""
    key = name.strip().lower() if isinstance(name, str) else name
    if key not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; allowed: {', '.join(PRESETS)}")
    return {k: dict(v) for k, v in PRESETS[key].items()}


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """Nested dict update: ``over`` wins, tables are merged key by key."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


def format_validation_error(err: ValidationError, source: str = "config",
                            limit: int = MAX_PROBLEMS) -> str:
    """One line per problem: ``source: field.path: reason (got value)``; at most ``limit``
    problems (then a count of the rest), each value shortened: the output stays bounded whatever
    the input (a file with a million unknown keys gives 21 lines)."""
    lines = []
    errors = err.errors()
    for e in errors[:limit]:
        loc = _short(".".join(str(p) for p in e["loc"]) or "<root>", 120).strip("'\"")
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown field (check the spelling; see tsmpc.config for the allowed names)"
        elif e["type"] in ("float_type", "int_type", "bool_type") and isinstance(e.get("input"),
                                                                               (bool, str)):
            msg += " (values are not converted: write a number as a number, a bool as true/false)"
        got = e.get("input")
        tail = "" if e["type"] in ("extra_forbidden", "missing") else f" (got {_short(got)})"
        lines.append(f"{source}: {loc}: {msg}{tail}")
    if len(errors) > limit:
        lines.append(f"{source}: … and {len(errors) - limit} more problems")
    return "\n".join(lines)


def validate(model: type[T], data: Any, source: str = "config") -> T:
    """``model.model_validate(data)`` raising :class:`ConfigError` naming each bad field."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(err, source)) from None


def replace(obj: T, **changes: Any) -> T:
    """A validated copy of ``obj`` with ``changes`` (``model_copy`` does not validate)."""
    data = obj.model_dump()
    data.update(changes)
    return validate(type(obj), data, source=type(obj).__name__)


def load_config(path: str | Path | None = None, preset: str | None = None) -> Config:
    """Load a :class:`Config` from a TOML file (missing sections take the paper's defaults).

    A top-level ``preset = "paper"`` in the file (or the ``preset`` argument, which wins) starts
    from that preset (:data:`PRESETS`); the file's own fields override it.
    Raises :class:`ConfigError` for an unreadable file, invalid TOML, an unknown preset or any
    bad field.
    """
    if path is None:
        return Config() if preset is None else Config.preset(preset)
    from tsmpc.textfile import read_text

    p = Path(path)
    data = parse_toml(read_text(p, "config file (TOML)", ConfigError, limit=MAX_CONFIG_BYTES), p)
    return validate(Config, resolve_preset(data, preset, source=str(p)), source=str(p))


#: Largest config or sweep file read [bytes] (a full config is < 10 kB).
MAX_CONFIG_BYTES = 1024 * 1024


def _too_many_digits(text: str, source: str | Path) -> ConfigError:
    """The error for an integer longer than Python converts (``int()`` raises ``ValueError``
    beyond ``sys.get_int_max_str_digits()`` = 4300 digits), naming the line when it is found."""
    limit = sys.get_int_max_str_digits() or 4300
    m = re.search("[0-9A-Fa-f_]{" + str(limit + 1) + ",}", text)
    where = f"line {text.count(chr(10), 0, m.start()) + 1}: " if m and "\n" in text else ""
    return ConfigError(f"{source}: {where}a number of more than {limit} digits: no value needs "
                       f"that many (at most {limit} digits)")


def _has_huge_int(value: Any) -> bool:
    """Does ``value`` (parsed TOML) hold an integer of more than 4300 decimal digits? Hex, octal
    and binary literals (``0xfff…``) parse at any length, but such a number cannot even be printed
    in an error message (``str()`` raises ``ValueError``). Iterative: the nesting may be deep."""
    limit = 10 ** (sys.get_int_max_str_digits() or 4300)
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list):
            stack.extend(v)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) >= limit:
            return True
    return False


def parse_toml(text: str, source: str | Path) -> dict[str, Any]:
    """``tomllib.loads`` raising :class:`ConfigError` naming ``source`` for invalid TOML, for
    absurd nesting (tomllib recurses: 100 000 nested arrays end in RecursionError) and for an
    integer of more than 4300 digits (Python's ``int()`` refuses it with a bare ``ValueError``).
    The one parser of every value a user types: config and sweep files, and ``--set``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{source}: invalid TOML: {err}") from None
    except RecursionError:
        raise ConfigError(f"{source}: invalid TOML: nested too deeply") from None
    except ValueError:  # int() of a number longer than sys.get_int_max_str_digits()
        raise _too_many_digits(text, source) from None
    if _has_huge_int(data):
        raise _too_many_digits(text, source)
    return data


def resolve_preset(data: dict[str, Any], preset: str | None = None, source: str = "config") -> dict[str, Any]:
    """Config data with its top-level ``preset`` key (or ``preset``, which wins) expanded: the
    preset's values, overridden by the data's own fields. Raises :class:`ConfigError` for an
    unknown preset."""
    data = dict(data)
    name = data.pop("preset", None)
    if preset is None and name is not None:
        if not isinstance(name, str) or name.strip().lower() not in PRESETS:
            raise ConfigError(f"{source}: preset: unknown preset {name!r}; allowed: {', '.join(PRESETS)}")
        preset = name
    base = _preset_dict(preset) if preset is not None else {}
    return _merge(base, data)


def apply_overrides(cfg: Config, assignments: list[str], source: str = "--set") -> Config:
    """``cfg`` with ``KEY=VALUE`` assignments (dotted keys into the config, e.g.
    ``scenario.plant.mass_scale=1.2``; VALUE a TOML value — ``0.3``, ``true``, ``[1, 2]``,
    ``[{at_s = 60, mu = 0.3}]`` — or else a bare string such as ``uio``), validated like a config
    file. Raises :class:`ConfigError` naming the assignment or the field."""
    data = cfg.model_dump(mode="json")
    for text in assignments:
        item = f"{source} {_short(text)}"
        bad = re.search(r"[\x00-\x1f\x7f]", text)
        if bad:  # a newline would start TOML of its own ("700\n[mpc]\nN=2"): one value only
            raise ConfigError(f"{item}: contains a control character ({bad.group()!r}); one "
                              "KEY=VALUE per --set, on one line")
        key, sep, raw = text.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not sep or not key or any(not p.strip() for p in parts):
            raise ConfigError(f"{item}: expected KEY=VALUE with a dotted key, e.g. "
                              "scenario.plant.mass_scale=1.2")
        try:
            doc = tomllib.loads(f"v = {raw.strip()}")
        except tomllib.TOMLDecodeError:
            doc = {"v": raw.strip()}  # a bare word: an enum value or a name
        except RecursionError:
            raise ConfigError(f"{item}: the value is nested too deeply") from None
        except ValueError:  # int() of a number longer than sys.get_int_max_str_digits()
            raise _too_many_digits(raw, item) from None
        if set(doc) != {"v"}:  # unreachable without a newline; never drop a part silently
            raise ConfigError(f"{item}: VALUE must be one TOML value")
        if _has_huge_int(doc):
            raise _too_many_digits(raw, item)
        value: Any = doc["v"]
        node = data
        for p in parts[:-1]:
            nxt = node.get(p) if isinstance(node, dict) else None
            if not isinstance(nxt, dict):
                if isinstance(node, dict) and p not in node:
                    raise ConfigError(f"{source} {text!r}: {key}: unknown field {p!r}")
                raise ConfigError(f"{source} {text!r}: {key}: {p!r} is not a section")
            node = nxt
        node[parts[-1]] = value
    return validate(Config, data, source=source)
