"""One pipeline from inputs to results: ``tsmpc compare`` and ``tsmpc run`` are thin shells over it,
so a library user gets exactly what the command line does (beyond the paper).

Two steps, so that every input is checked before anything is solved or written:

1. :func:`prepare` validates and assembles the experiment — config (preset, seed), scenario
   (reference, window, laps, column period), robustness case, plant (tsmpc's own or a CommonRoad
   model, with the controllers set up for it) and the operating envelope (the designs' boxes widened
   to cover the reference, or refused with ``strict_box``). Bad input raises a
   :class:`~tsmpc.errors.TsmpcError` that is also a ``ValueError``; nothing is solved or written.
2. :func:`run` solves (or loads) and certifies the designs of that config
   (:func:`solve_designs`; a config no design can be certified for raises
   :class:`~tsmpc.errors.DesignError`, a bad input), loads the compiled kernels, runs every method
   and writes the outputs (:func:`tsmpc.sim.compare.compare`).

    exp = prepare(Config(), ["ref"], reference=Path("monza.csv"))
    result = run(exp, Path("out"))          # same metrics.json as `tsmpc run --reference monza.csv`

Progress and status: ``status(text)`` receives one line before each design is solved ("…: solving
and certifying…") and one after its certificates were checked ("…: certified … (smallest relative
margin …)"), never before; ``progress_factory`` as in :func:`~tsmpc.sim.compare.compare`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import Any

from tsmpc.config import Config, Method, replace
from tsmpc.errors import ConfigError, DesignError
from tsmpc.sim.compare import CompareResult, FigureFn, ProgressFactory, compare, load_scenario
from tsmpc.sim.plant import Plant
from tsmpc.sim.simulator import Scenario

__all__ = ["PLANTS", "PUBLISHED_EXEMPT", "Experiment", "StatusFn", "check_plan_limits", "prepare", "run",
           "solve_designs"]

#: One line of progress for the user (design solving, kernel compilation).
StatusFn = Callable[[str], None]
#: Plants an experiment can run on: tsmpc's own, or CommonRoad's single-track / multi-body model.
PLANTS = ("tsmpc", "commonroad-st", "commonroad-mb")


@dataclass(frozen=True)
class Experiment:
    """A validated experiment: what :func:`run` executes.

    Attributes:
        config: the config of the run (preset, seed, plant set-up and envelope widening applied).
        scenario: reference, friction, faults, plant parameters of the run.
        methods: outer-loop methods, run one after the other on fresh plants from the same seed.
        envelope: the reference's ranges and the boxes widened to cover them
            (:class:`~tsmpc.envelope.EnvelopeFit`).
        plant: "tsmpc", "commonroad-st" or "commonroad-mb".
        cr_vehicle: CommonRoad parameter set (1, 2, 3) of a CommonRoad plant.
        oracle: the inner loop gets the true state (the ablation; no friction compensation).
        max_steps: track only the first ``max_steps`` MPC steps (None: the whole reference).
        plan_note: one line when the reference exceeded the vehicle's limits (capped, or exempt:
            :func:`tsmpc.planning.feasibility.feasible_plan`); "" when it is within them.
    """

    config: Config
    scenario: Scenario
    methods: tuple[Method, ...]
    envelope: Any
    plant: str = "tsmpc"
    cr_vehicle: int = 2
    oracle: bool = False
    max_steps: int | None = None
    plan_note: str = ""

    def plant_factory(self) -> Callable[[], Plant] | None:
        """A fresh plant per method (None: tsmpc's own, built by the simulator)."""
        if self.plant == "tsmpc":
            return None
        from tsmpc.vehicle.commonroad import COMMONROAD_MODELS, CommonRoadPlant

        model, vid, h = COMMONROAD_MODELS[self.plant], self.cr_vehicle, self.config.rates.h
        return lambda: CommonRoadPlant(vid, model=model, h=h)


def prepare(
    cfg: Config,
    methods: Sequence[Method | str],
    *,
    reference: Path | str | None = None,
    window: tuple[int, int] | None = None,
    laps: int = 1,
    dt: float | None = None,
    robustness: str = "nominal",
    duration: float | None = None,
    seed: int | None = None,
    plant: str = "tsmpc",
    cr_vehicle: int = 2,
    strict_box: bool = False,
    oracle: bool = False,
    strict_plan: bool = False,
) -> Experiment:
    """Validate every input and assemble the experiment; nothing is solved or written.

    Args mirror ``tsmpc compare`` / ``tsmpc run``: ``reference`` None is the built-in circuit,
    a path, or a dataset name (``"paper"``: :func:`tsmpc.datasets.resolve`);
    ``window`` 1-based (FIRST, LAST) columns/rows; ``duration`` [s] tracks only the first part;
    ``robustness`` a named scenario of :mod:`tsmpc.robustness`; ``strict_box`` refuses a
    reference beyond the designs' boxes instead of widening them; ``strict_plan`` refuses a
    reference beyond the vehicle's grip or force budget instead of capping its speed profile
    (:func:`check_plan_limits`).

    Raises :class:`~tsmpc.errors.TsmpcError` (a ``ValueError``) naming the bad input.
    """
    from tsmpc.envelope import fit_envelope

    if duration is not None and not (duration >= 0.1 and duration < float("inf")):
        raise ConfigError(f"duration = {duration!r}: must be a finite number >= 0.1 s")
    if seed is not None:
        if seed < 0:
            raise ConfigError(f"seed = {seed}: must be an integer >= 0")
        cfg = replace(cfg, seed=seed)
    parsed = tuple(m if isinstance(m, Method) else Method.parse(m) for m in methods)
    if not parsed:
        raise ConfigError("methods: empty; give at least one of " +
                          ", ".join(m.value.lower() for m in Method))
    scenario = load_scenario(cfg, reference, window, laps=laps, dt=dt)
    if robustness != "nominal":
        from tsmpc.robustness import apply_robustness

        cfg, scenario = apply_robustness(robustness, cfg, scenario, until_s=duration)
    from tsmpc.conditions import apply_conditions  # the config's [scenario] section (issue 21)

    cfg, scenario = apply_conditions(cfg, scenario)
    name = plant.strip().lower()
    if name not in PLANTS:
        raise ConfigError(f"unknown plant {plant!r}; allowed: {', '.join(PLANTS)}")
    if name != "tsmpc":
        cfg, scenario = _commonroad_setup(name, cr_vehicle, cfg, scenario)
    scenario, plan_note = check_plan_limits(cfg, scenario, strict=strict_plan)
    fit = fit_envelope(cfg, scenario.reference, strict=strict_box)
    if fit.widened:
        scenario = dc_replace(scenario, meta={
            **scenario.meta, "envelope_widened": sorted({s.field for s in fit.widened})})
    max_steps = None if duration is None else max(1, round(duration / fit.config.rates.Tc))
    return Experiment(fit.config, scenario, parsed, fit, name, cr_vehicle, oracle, max_steps, plan_note)


#: Why the published reference is tracked as it is (:func:`check_plan_limits`).
PUBLISHED_EXEMPT = ("the published reference, the benchmark of the paper's Table 5 (its v row "
                    "jumps in single samples)")


def check_plan_limits(cfg: Config, scenario: Scenario, *, strict: bool = False) -> tuple[Scenario, str]:
    """(scenario, line): the reference checked against the vehicle's grip and force budget on the
    scenario's μ(road) (:func:`tsmpc.planning.feasibility.feasible_plan`), before any work.
    Beyond them it is capped (the line says how much and which limit; the scenario's meta records
    it), or with ``strict`` refused (:class:`ConfigError`). The published reference is exempt
    (:data:`PUBLISHED_EXEMPT`); the line says so when it exceeds them.

    The check uses what the controllers know: the config's vehicle and tyre (μ_tyre), with the
    road the scenario declares — its μ(road) profile, and whether the tyre has a friction ellipse
    or its grip follows the road. A plant that differs from the config (``scenario.plant`` scales
    and μ_tyre) is the mismatch an experiment measures, not a planning input
    (``scenario.replan_for_force_budget`` plans for it, explicitly)."""
    from tsmpc.planning.feasibility import feasible_plan

    exempt = PUBLISHED_EXEMPT if scenario.meta.get("paper_reference") else ""
    road = scenario.plant_tyre or cfg.tyre
    tyre = replace(cfg.tyre, model=road.model, combined_slip=road.combined_slip,
                   scale_grip_with_road=road.scale_grip_with_road, mu_dry=road.mu_dry)
    ref, check, line = feasible_plan(scenario.reference, cfg.vehicle, tyre, cfg.lqr, scenario.friction,
                                     strict=strict, exempt=exempt)
    if ref is scenario.reference:
        return scenario, line
    meta = {**scenario.meta, "plan_capped": {"limit": check.limit, "ratio": round(check.ratio, 4),
                                             "duration_s": [scenario.reference.duration, ref.duration]}}
    return dc_replace(scenario, reference=ref, meta=meta), line


def _commonroad_setup(name: str, vid: int, cfg: Config, scenario: Scenario) -> tuple[Config, Scenario]:
    """Controllers set up for CommonRoad vehicle ``vid``; the servo's steering angle measured."""
    from tsmpc.vehicle.commonroad import COMMONROAD_MODELS, CommonRoadPlant, commonroad_config

    cfg = commonroad_config(cfg, vid)
    CommonRoadPlant(vid, model=COMMONROAD_MODELS[name], h=cfg.rates.h)  # unusable: fail now
    meta = {**scenario.meta, "plant": name, "cr_vehicle": vid}
    return cfg, dc_replace(scenario, measured_steering=True, meta=meta)


def solve_designs(cfg: Config, status: StatusFn | None = None) -> tuple[Any, Any]:
    """The (kinematic, dynamic) LMI designs of ``cfg``, loaded from the design cache or solved,
    and certified on this machine either way.

    ``status`` gets "LMI design: NAME: solving and certifying…" (or "loading…" for a cached one)
    before, and "LMI design: NAME: certified in S s (every LMI holds with a relative margin ≥ M, …;
    tightest: CERTIFICATE)"
    after the certificates hold. Raises :class:`~tsmpc.errors.DesignError` (a bad input: no
    certified design exists for these settings) with the solver's diagnosis."""
    from tsmpc.synthesis.cache import (
        cache_dir,
        dynamic_key,
        kinematic_key,
        load_or_design_dynamic,
        load_or_design_kinematic,
    )
    from tsmpc.synthesis.certificates import MIN_RELATIVE_MARGIN, worst

    say = status or (lambda _text: None)
    out = []
    for name, key, fn, _inputs in (  # the inputs: tsmpc.diagnose.DESIGN_INPUTS
        ("kinematic", kinematic_key, load_or_design_kinematic,
         "kinematic_box, kinematic_lmi, rates.Tc"),
        ("dynamic", dynamic_key, load_or_design_dynamic,
         "dynamic_box, dynamic_lmi, vehicle, rates.Td"),
    ):
        cached = (cache_dir() / f"{name}-{key(cfg)[:32]}.json").exists()
        say(f"LMI design: {name}: " + ("loading from the cache and re-certifying…" if cached
                                      else "solving and certifying (new inputs: seconds to a minute)…"))
        t0 = time.perf_counter()
        try:
            design = fn(cfg)
        except Exception as err:  # the solver's own exceptions too (issue 24): a result, not a crash
            from tsmpc.diagnose import explain_design_failure

            raise DesignError(explain_design_failure(name, cfg, err)) from None
        w = worst(design.certificates)
        # the certificate's number is λmax of a matrix that must be ≺ 0, relative: the margin is −it
        say(f"LMI design: {name}: certified in {time.perf_counter() - t0:.1f} s (every LMI holds with "
            f"a relative margin ≥ {-w.relative:.1e}, {MIN_RELATIVE_MARGIN:g} required; tightest: "
            f"{w.name})")
        out.append(design)
    return out[0], out[1]


def run(
    exp: Experiment,
    out_dir: Path | None,
    *,
    plots: bool = True,
    progress_factory: ProgressFactory | None = None,
    status: StatusFn | None = None,
    designs: tuple[Any, Any] | None = None,
    figures: FigureFn | None = None,
    mat: bool = False,
) -> CompareResult:
    """Solve and certify the designs (unless given), load the kernels and run every method of
    ``exp``; write the outputs into ``out_dir`` (None: nothing written). A diverged method is a
    result (``metrics["diverged"]``), not an exception. ``mat``: also write ``timeseries.mat``."""
    from tsmpc import kernels

    if designs is None:
        designs = solve_designs(exp.config, status)
    kernels.warmup()  # compile/load before the first timed step (the first run says so)
    return compare(exp.config, exp.scenario, list(exp.methods), out_dir, plots=plots,
                   oracle=exp.oracle, max_steps=exp.max_steps, progress_factory=progress_factory,
                   designs=designs, plant_factory=exp.plant_factory(), figures=figures, mat=mat)
