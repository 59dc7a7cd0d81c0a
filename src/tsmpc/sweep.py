"""Monte-Carlo and parameter sweeps on Dask (issue 8).

A sweep file (TOML) names a base configuration, the axes and how long each run lasts::

    name = "robustness"
    duration_s = 20.0                 # simulated seconds per run (omit: the whole reference)
    base_config = "paper.toml"        # optional, relative to the sweep file
    [config.mpc]                      # optional inline overrides, merged over the base
    N = 40
    [grid]                            # cartesian product of the listed axes
    method = ["ref", "fzn"]
    scenario = ["nominal", "noise_x10"]
    seed = [1, 2]
    [cases.heavy]                     # optional named cases: [scenario] tables (issue 21)
    plant = { mass_scale = 1.2 }
    [controllers.oracle]              # optional named controllers: config overrides (a preset too)
    scenario = { oracle_tuned = true }
    [random]                          # optional: n samples per grid point, from a seed
    n = 4
    seed = 7
    per_grid_point = true             # fresh draws at each point (default: the same draws)
    ranges = { mass_scale = [0.9, 1.1] }
    choices = { friction = ["paper", "dry"] }

Runs go to Dask in batches (``client.submit(run_batch, chunk, retries=...)``; ``batch`` runs of
one controller per task, fewer when the sweep is small, so every worker gets two or more; see
:func:`batches`): a worker steps a batch's runs together with the batched kernel
(:mod:`tsmpc.sim.batch`, ~2× the throughput of the runs one by one). A controller with fewer
than :data:`MIN_LANES` runs in the sweep, and every run with ``batch = 1``, is its own task,
simulated by :func:`run_task` exactly as ``tsmpc run`` does (batched runs differ from that by
rounding only).
A run that ends early (diverged, left the track, raised) is *data*: its record says why. The
client writes every finished run's record atomically to ``DIR/runs/<id>.json`` as soon as its
task arrives; ids hash the run's resolved parameters, so ``resume`` skips what is on disk and a
record is never written twice. A worker that dies takes its task with it; the scheduler re-runs
the task on another worker. At the end the aggregate table (one row per run) is written as CSV
and Parquet.

Hostile sweep files and folders (issue 24): the schema is strict (numbers are numbers, booleans
booleans), an axis may be in ``[grid]`` or in ``[random]`` but not both, a sweep has at most
``max_runs`` runs (:data:`MAX_RUNS` unless raised with ``--max-runs``), names are short and
printable. Nothing is written before the file, the base config and its LMI designs are valid.
``resume`` re-reads every record on disk: one that is not a valid record of this sweep (empty,
garbage, ``[]``, a folder, or numbers out of range: :func:`record_problem`) is set aside under
``runs/.unreadable/`` and re-run, and records of tasks lost to worker failures (status
``failed``) are re-run too (``retry_failed``).

Dask's lifecycle (issue 38): a task the cluster lost (cancelled — e.g. the scheduler's
connection lost —, a closed comm, a timeout) gets no record; :class:`SweepResult` lists it in
``incomplete`` with the ``failed`` runs, and the CLI ends such a sweep non-zero with ``PARTIAL``
naming them. The cluster's start-up and shutdown run inside ``shield`` (uninterruptible), and
the outputs are written together or not at all (:func:`write_outputs`).
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from tsmpc.config import (
    MAX_CONFIG_BYTES,
    Config,
    Method,
    StrictBool,
    StrictInt,
    parse_toml,
    resolve_preset,
    validate,
)
from tsmpc.errors import ClusterError, ConfigError
from tsmpc.io import atomic_write_bytes, atomic_write_text
from tsmpc.robustness import ROBUSTNESS_SCENARIOS
from tsmpc.sweep_axes import _CHOICE_AXES, _FLOAT_AXES, AXES

__all__ = [
    "AXES",
    "FRICTIONS",
    "MAX_RUNS",
    "MIN_LANES",
    "RunParams",
    "RunTask",
    "SweepResult",
    "SweepSpec",
    "aggregate",
    "batch_key",
    "batches",
    "connect",
    "dry_run",
    "expand",
    "load_sweep",
    "run_batch",
    "run_sweep",
    "run_task",
]

#: Named friction profiles of the ``friction`` axis.
FRICTIONS: dict[str, str] = {
    "paper": "the paper run's μ(road) by time (the paper's scenario)",
    "dry": "dry asphalt, μ = 0.9",
    "earth": "dry earth, μ = 0.68",
    "wet": "wet asphalt, μ = 0.6",
}
_FRICTION_MU = {"dry": 0.9, "earth": 0.68, "wet": 0.6}
_METHODS = tuple(m.value for m in Method)  # the TS-MPC modes, NL and the baselines (issue 26)
#: Allowed (exclusive lower, inclusive upper) bounds of the numeric axes.
AXIS_LIMITS: dict[str, tuple[float, float]] = {
    "noise_scale": (0.0, 1000.0), "mass_scale": (0.0, 10.0), "inertia_scale": (0.0, 10.0),
    "cornering_scale": (0.0, 10.0),
    # Faster than 3x the planned speed leaves any sensible scheduling box (and the road).
    "speed_scale": (0.0, 3.0),
}
_Noise = Annotated[float, Strict(), Field(gt=0.0, le=1000.0, allow_inf_nan=False)]
_Scale = Annotated[float, Strict(), Field(gt=0.0, le=10.0, allow_inf_nan=False)]
_Speed = Annotated[float, Strict(), Field(gt=0.0, le=3.0, allow_inf_nan=False)]
_Seed = Annotated[int, Strict(), Field(ge=0, lt=2**63)]
_Duration = Annotated[float, Strict(), Field(gt=0.0, le=1e5, allow_inf_nan=False)]
_Real = Annotated[float, Strict(), Field(allow_inf_nan=False)]
#: A path or a name in a sweep file: short and without control characters.
_Text = Annotated[str, Strict(), Field(max_length=4096, pattern=r"^[^\x00-\x1f\x7f]*$")]
#: Most runs of a sweep unless raised (``run_sweep(max_runs=...)``, ``tsmpc sweep --max-runs``).
MAX_RUNS = 10_000
#: Most random draws per grid point.
MAX_RANDOM_N = 10_000
#: Statuses of a run record; ``failed`` = the task was lost to worker failures (retried on resume).
RECORD_STATUSES = ("completed", "diverged", "degraded", "error", "failed")


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class RunParams(_Strict):
    """The resolved parameters of one run (one point of the sweep)."""

    method: str = "REF"
    friction: str = "paper"
    scenario: str = "nominal"
    noise_scale: _Noise = 1.0
    mass_scale: _Scale = 1.0
    inertia_scale: _Scale = 1.0
    cornering_scale: _Scale = 1.0
    speed_scale: _Speed = 1.0
    track: _Text = "builtin"
    seed: _Seed | None = None  #: None: the base config's seed
    case: str = "nominal"  #: a named case of the sweep file (its [scenario] table), issue 21
    controller: str = "default"  #: a named controller (config overrides or a preset), issue 21


def _check_method(v: str) -> str:
    m = str(v).strip().upper()
    if m not in _METHODS:
        raise ConfigError(f"unknown method {v!r}; allowed: {', '.join(x.lower() for x in _METHODS)}")
    return m


def _check_named(v: str, allowed: dict[str, str], what: str) -> str:
    if v not in allowed:
        raise ConfigError(f"unknown {what} {v!r}; allowed: {', '.join(allowed)}")
    return v


class GridAxes(_Strict):
    """Values of each axis; the runs are their cartesian product (missing axes keep defaults)."""

    method: list[_Text] | None = None
    friction: list[_Text] | None = None
    scenario: list[_Text] | None = None
    noise_scale: list[_Noise] | None = None
    mass_scale: list[_Scale] | None = None
    inertia_scale: list[_Scale] | None = None
    cornering_scale: list[_Scale] | None = None
    speed_scale: list[_Speed] | None = None
    track: list[_Text] | None = None
    seed: list[_Seed] | None = None
    case: list[str] | None = None
    controller: list[str] | None = None

    @property
    def size(self) -> int:
        """Points of the cartesian product (before duplicates are merged)."""
        return math.prod(len(getattr(self, name) or [None]) for name in AXES)

    @model_validator(mode="after")
    def _values(self) -> GridAxes:
        for name in AXES:
            vals = getattr(self, name)
            if vals is not None and len(vals) == 0:
                raise ConfigError(f"axis {name!r} is empty: give at least one value or leave it out")
        if self.method:
            object.__setattr__(self, "method", [_check_method(m) for m in self.method])
        for v in self.friction or []:
            _check_named(v, FRICTIONS, "friction profile")
        for v in self.scenario or []:
            _check_named(v, ROBUSTNESS_SCENARIOS, "robustness scenario")
        return self


class RandomSpec(_Strict):
    """``n`` random samples per grid point drawn from ``seed``: floats uniform in ``ranges``,
    the other axes uniformly from ``choices``. ``per_grid_point = false`` (default): the same
    n draws at every grid point (common random numbers: methods compared on equal draws);
    ``true``: fresh draws at every grid point."""

    n: StrictInt = Field(ge=1, le=MAX_RANDOM_N)
    seed: _Seed = 0
    per_grid_point: StrictBool = False
    ranges: dict[str, tuple[_Real, _Real]] = Field(default_factory=dict)
    choices: dict[str, list[Any]] = Field(default_factory=dict)

    @field_validator("ranges")
    @classmethod
    def _ranges(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k, (lo, hi) in v.items():
            if k not in _FLOAT_AXES:
                raise ConfigError(f"ranges: {k!r} is not a numeric axis; "
                                 f"numeric axes: {', '.join(_FLOAT_AXES)}")
            a, b = AXIS_LIMITS[k]
            for x in (lo, hi):
                if not (math.isfinite(x) and a < x <= b):
                    raise ConfigError(f"ranges.{k}: {x!r} is outside the allowed ({a:g}, {b:g}]")
            if lo > hi:
                raise ConfigError(f"ranges.{k}: lower bound {lo} > upper bound {hi}")
        return v

    @field_validator("choices")
    @classmethod
    def _choices(cls, v: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for k, vals in v.items():
            if k not in _CHOICE_AXES:
                raise ConfigError(f"choices: {k!r} is not a choice axis; "
                                 f"choice axes: {', '.join(_CHOICE_AXES)}")
            if not vals:
                raise ConfigError(f"choices.{k} is empty")
            for val in vals:  # every value, not only the ones the draws happen to pick
                try:
                    RunParams(**{k: val})
                    if k == "method":
                        _check_method(val)
                except ValidationError as err:
                    raise ConfigError(f"choices.{k}: {val!r}: {err.errors()[0]['msg']}") from None
        return v


class SweepSpec(_Strict):
    """A validated sweep file."""

    name: Annotated[str, Strict(), Field(min_length=1, max_length=200,
                                         pattern=r"^[^\x00-\x1f\x7f]*$")] = "sweep"
    duration_s: _Duration | None = None
    base_config: _Text | None = None
    config: dict[str, Any] = Field(default_factory=dict)
    grid: GridAxes = GridAxes()
    random: RandomSpec | None = None
    retries: StrictInt = Field(2, ge=0, le=10, description=(
        "Dask retries of a task that raised (a run never raises: its failures are records; "
        "worker deaths are retried by Dask's distributed.scheduler.allowed-failures), 0 to 10"))
    max_lateral_m: _Real = Field(5.0, gt=0.0, le=1e3,
                                 description="|e_y| beyond which a run has diverged")
    batch: StrictInt = Field(64, ge=1, le=1024, description=(
        "runs per Dask task, stepped together by the batched kernel (tsmpc.sim.batch); a sweep "
        "of few runs gets smaller tasks so that every worker has two or more, and a controller "
        "with fewer than 8 runs in the sweep runs one run per task. 1: every run its own task, "
        "simulated exactly as 'tsmpc run' does (bit for bit)"))
    cases: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="named cases of the 'case' axis: each a [scenario] table "
        "(tsmpc.config.ScenarioSettings); 'nominal' (no change) is built in")
    controllers: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="named controllers of the 'controller' axis: config "
        "overrides (a 'preset' key starts from that preset); 'default', 'paper' and 'paper-as-run' "
        "are built in")
    #: Folder the relative paths of the file are resolved against (set by load_sweep).
    root: str = "."

    @model_validator(mode="after")
    def _disjoint(self) -> SweepSpec:
        """An axis is either a grid axis or a random one: in both, the draws would silently
        replace the grid's values."""
        if self.random is not None:
            both = [a for a in AXES if getattr(self.grid, a) is not None
                    and (a in self.random.ranges or a in self.random.choices)]
            if both:
                raise ConfigError(f"axis {both[0]!r} is in [grid] and in [random]: give it in one "
                                  "of them (the random draws would replace the grid's values)")
        return self

    @property
    def n_points(self) -> int:
        """Runs of the sweep before duplicates are merged: grid points × random draws."""
        return self.grid.size * (self.random.n if self.random is not None else 1)


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one run (picklable; no open files or solvers)."""

    id: str
    params: RunParams
    config: dict[str, Any]  #: the resolved base configuration (Config.model_dump())
    duration_s: float | None
    max_lateral_m: float
    root: str
    #: (kinematic, dynamic) LMI designs solved and certified once by the client; None: the
    #: worker loads them from its design cache.
    designs: tuple[Any, Any] | None = None
    #: the config ``designs`` were made for (a run whose controller differs loads its own)
    designs_config: dict[str, Any] | None = None


@dataclass
class SweepResult:
    """What a sweep did."""

    out: Path
    n_runs: int  #: runs in the sweep
    executed: int  #: records written by this call (the rest were on disk already)
    skipped: int  #: records found on disk (resume)
    failed: int  #: tasks lost to repeated worker failures (recorded with status "failed")
    duplicates: int  #: results that arrived for an id already written (never rewritten)
    table: Any = None  #: the aggregate pandas DataFrame
    files: list[Path] = field(default_factory=list)
    #: runs with no result at the end: no valid record on disk (their tasks were lost with the
    #: cluster: cancelled, scheduler connection lost) or a ``failed`` one; --resume runs them
    incomplete: list[str] = field(default_factory=list)
    lost: int = 0  #: runs of this call whose tasks the cluster lost (no record written)
    lost_reason: str = ""  #: why, the first such error (e.g. FutureCancelledError: …)

    @property
    def complete(self) -> bool:
        """Every run has a result record (none missing, none ``failed``)."""
        return not self.incomplete


# -- loading and expansion ----------------------------------------------------------------
def load_sweep(path: str | Path, *, max_runs: int = MAX_RUNS) -> SweepSpec:
    """Read and validate a sweep file; every problem raises :class:`ConfigError` naming the field,
    before any task starts (the base config and track files are checked too; a sweep of more than
    ``max_runs`` runs is refused before it is expanded)."""
    from tsmpc.textfile import read_text

    p = Path(path)
    data = parse_toml(read_text(p, "sweep file (TOML)", ConfigError, limit=MAX_CONFIG_BYTES), p)
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: a sweep file is a TOML table")
    if "root" in data:
        raise ConfigError(f"{p}: root: unknown field (relative paths are resolved against the "
                          "sweep file's folder)")
    data["root"] = str(p.resolve().parent)
    spec = validate(SweepSpec, data, source=str(p))
    if spec.n_points > max_runs:
        raise ConfigError(f"{p}: the sweep has {spec.n_points:,} runs ({spec.grid.size:,} grid "
                          f"points × {spec.random.n if spec.random else 1} random draws), more "
                          f"than {max_runs:,}; raise the limit with --max-runs, or shrink the axes")
    cfg = base_config(spec, source=str(p))
    for name in spec.cases:  # every named case and controller, used or not, before any task
        try:
            run_config(spec, name, "default")
        except ConfigError as err:
            raise ConfigError(f"{p}: cases.{name}: {err}") from None
    for name in spec.controllers:
        try:
            run_config(spec, "nominal", name)
        except ConfigError as err:
            raise ConfigError(f"{p}: controllers.{name}: {err}") from None
    for t in dict.fromkeys(_track_values(spec)):
        _check_track(t, spec, cfg, source=str(p))
    try:
        tasks = expand(spec)
    except ConfigError as err:
        raise ConfigError(f"{p}: {err}") from None
    if not tasks:
        raise ConfigError(f"{p}: the sweep has no runs")
    return spec


def _check_track(track: str, spec: SweepSpec, cfg: Config, source: str) -> None:
    """Load (and plan) a track value as a run would, so a bad file fails before any task."""
    from tsmpc.errors import TsmpcError
    from tsmpc.planning.tracks import is_tumftm, load_tumftm, plan_track
    from tsmpc.sim.compare import check_trackable, load_scenario

    path = track_file(track, spec.root, source=source)
    if path is None:
        return
    try:
        if is_tumftm(path):
            t = load_tumftm(path)
            ref = plan_track(t, cfg.planner, dt=cfg.rates.Tc, tail_s=(cfg.mpc.N + 1) * cfg.rates.Tc)
            check_trackable(ref, cfg, str(path))
        else:
            load_scenario(cfg, path)
    except TsmpcError as err:
        raise ConfigError(f"{source}: track {track!r}: {err}") from None


def base_config(spec: SweepSpec, source: str = "sweep") -> Config:
    """The base config (file, then inline ``[config]`` overrides), validated."""
    data: dict[str, Any] = {}
    if spec.base_config:
        from tsmpc.textfile import read_text

        path = Path(spec.root) / spec.base_config
        try:
            data = parse_toml(read_text(path, "config file (TOML)", ConfigError,
                                        limit=MAX_CONFIG_BYTES), path)
        except ConfigError as err:
            raise ConfigError(f"{source}: base_config: {err}") from None
    merged = resolve_preset(_merge(data, spec.config), source=f"{source}: config")  # preset = "paper"
    return validate(Config, merged, source=f"{source}: config")


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _track_values(spec: SweepSpec) -> list[str]:
    vals = list(spec.grid.track or [])
    if spec.random is not None:
        vals += [str(v) for v in spec.random.choices.get("track", [])]
    return vals


def track_file(track: str, root: str | Path, source: str = "sweep") -> Path | None:
    """The file a sweep's ``track`` value names (None for ``builtin``): a path relative to the sweep
    file's folder ``root``, else a dataset name (``paper``, ``monza``) resolved by
    :func:`tsmpc.datasets.resolve` as on the command line. Raises :class:`ConfigError`."""
    if track == "builtin":
        return None
    p = Path(track)
    p = p if p.is_absolute() else Path(root) / p
    if not p.is_file() and not os.path.lexists(p):
        from tsmpc import datasets

        if datasets.is_dataset_name(track):  # "paper", "monza": the fetched data (tsmpc.datasets)
            try:
                return datasets.resolve(track)
            except datasets.DataNotFoundError as err:
                raise ConfigError(f"{source}: track: {err}") from None
    if not p.is_file():
        raise ConfigError(f"{source}: track: {track!r} is neither 'builtin', a dataset name nor a readable "
                          f"file ({p})")
    return p


def expand(spec: SweepSpec) -> list[RunTask]:
    """The runs of a sweep, in a stable order, with ids that hash their resolved inputs."""
    cfg = base_config(spec)
    cfg_dict = cfg.model_dump(mode="json")
    grid = {name: getattr(spec.grid, name) for name in AXES if getattr(spec.grid, name) is not None}
    points = [dict(zip(grid, combo, strict=True)) for combo in itertools.product(*grid.values())] or [{}]
    if spec.random is not None:
        rs = spec.random
        rng = np.random.default_rng(rs.seed)

        def draw() -> list[dict[str, Any]]:
            samples = []
            for _ in range(rs.n):
                s: dict[str, Any] = {}
                for k, (lo, hi) in sorted(rs.ranges.items()):
                    s[k] = float(rng.uniform(lo, hi))
                for k, vals in sorted(rs.choices.items()):
                    s[k] = vals[int(rng.integers(len(vals)))]
                samples.append(s)
            return samples

        if rs.per_grid_point:  # fresh draws at each point, in grid order (reproducible)
            points = [{**p, **s} for p in points for s in draw()]
        else:  # the same draws at every point
            shared = draw()
            points = [{**p, **s} for p in points for s in shared]
    tasks, seen = [], set()
    for point in points:
        try:
            params = RunParams(**point)
            params = params.model_copy(update={"method": _check_method(params.method)})
            _check_named(params.friction, FRICTIONS, "friction profile")
            _check_named(params.scenario, ROBUSTNESS_SCENARIOS, "robustness scenario")
        except ValidationError as err:
            from tsmpc.config import format_validation_error

            raise ConfigError("random.choices: " + format_validation_error(err, "run")) from None
        except ValueError as err:
            raise ConfigError(f"random.choices: {err}") from None
        run_cfg = cfg_dict
        if (params.case, params.controller) != ("nominal", "default"):
            run_cfg = run_config(spec, params.case, params.controller, cfg_dict)
        payload = json.dumps({"params": params.model_dump(), "config": run_cfg,
                              "duration_s": spec.duration_s, "max_lateral_m": spec.max_lateral_m},
                             sort_keys=True)
        rid = hashlib.sha256(payload.encode()).hexdigest()[:16]
        if rid in seen:  # the same point twice (e.g. a repeated grid value) is one run
            continue
        seen.add(rid)
        tasks.append(RunTask(rid, params, run_cfg, spec.duration_s, spec.max_lateral_m, spec.root))
    return tasks


#: Built-in controllers of the ``controller`` axis (presets).
BUILTIN_CONTROLLERS = ("default", "paper", "paper-as-run")


def run_config(spec: SweepSpec, case: str, controller: str, base: dict[str, Any] | None = None
               ) -> dict[str, Any]:
    """The validated config (as a dict) of a run with the named ``case`` and ``controller``
    (issue 21): the base config, the controller's overrides (a built-in name or a ``preset`` key
    puts that preset's fields over the base), the case as its ``[scenario]`` section.
    Raises :class:`ConfigError` naming an unknown name or a bad field."""
    from tsmpc.config import _merge as merge_config
    from tsmpc.config import _preset_dict

    data = dict(base if base is not None else base_config(spec).model_dump(mode="json"))
    if controller in spec.controllers:
        over = dict(spec.controllers[controller])
        name = over.pop("preset", None)
        if name is not None:
            if not isinstance(name, str):
                raise ConfigError(f"controllers.{controller}.preset: must be a preset name")
            data = merge_config(data, _preset_dict(name))
        data = merge_config(data, over)
    elif controller in BUILTIN_CONTROLLERS:
        data = merge_config(data, _preset_dict(controller))
    else:
        allowed = ", ".join([*BUILTIN_CONTROLLERS, *spec.controllers])
        raise ConfigError(f"controller: unknown {controller!r}; allowed: {allowed}")
    if case in spec.cases:
        data = merge_config(data, {"scenario": spec.cases[case]})
    elif case != "nominal":
        raise ConfigError(f"case: unknown {case!r}; allowed: nominal, {', '.join(spec.cases)}")
    return validate(Config, data, source=f"case {case!r}, controller {controller!r}").model_dump(
        mode="json")


# -- one run (executes on a worker) ---------------------------------------------------------
def run_task(task: RunTask) -> dict[str, Any]:
    """Simulate one run and return its record. Never raises for a bad run: a divergence or an
    exception becomes the record's ``status`` and ``reason``."""
    t0 = time.perf_counter()
    try:
        metrics, status, reason = _simulate(task)
    except Exception as err:  # a failing run is data, not a crash
        metrics, status, reason = {}, _error_status(err), f"{type(err).__name__}: {err}"
    return _record(task, status, reason, metrics, time.perf_counter() - t0)


def _error_status(err: BaseException) -> str:
    """``failed`` when the machine failed the run (out of memory: not a result of the controller,
    re-run by ``--resume``), else ``error`` (the run itself raised: data)."""
    return "failed" if isinstance(err, MemoryError) else "error"


def run_batch(tasks: list[RunTask]) -> list[dict[str, Any]]:
    """Simulate several runs in one process and return their records (as :func:`run_task`
    would, in order). The runs that share a controller (config but the seed, method, duration)
    are stepped together by the batched kernel (:func:`tsmpc.sim.batch.simulate_batch`): their
    plant steps and MHE windows vectorised across runs. A batched run's states differ from the
    same run simulated on its own by rounding only (the plant's vectorised sin/cos/atan, ≤ 2 ulp),
    and never depend on which runs share its batch. Never raises."""

    from tsmpc.sim.batch import simulate_batch

    t0 = time.perf_counter()
    out: list[dict[str, Any] | None] = [None] * len(tasks)
    prepared: dict[int, _Prepared] = {}
    groups: dict[tuple[Any, ...], list[int]] = {}
    batched: list[int] = []
    for i, task in enumerate(tasks):
        try:
            prep = _prepare(task)
        except Exception as err:  # a failing run is data, not a crash
            out[i] = _record(task, _error_status(err), f"{type(err).__name__}: {err}", {}, 0.0)
            continue
        prepared[i] = prep
        controller = prep.cfg.model_dump(mode="json")
        controller.pop("seed", None)
        key = (prep.method, prep.max_steps, json.dumps(controller, sort_keys=True))
        groups.setdefault(key, []).append(i)
    for idxs in groups.values():
        first = prepared[idxs[0]]
        try:
            logs = simulate_batch(first.cfg, first.method, [prepared[i].scenario for i in idxs],
                                  seeds=[prepared[i].cfg.seed for i in idxs],
                                  kinematic_design=first.designs[0],
                                  dynamic_design=first.designs[1], max_steps=first.max_steps)
        except Exception:  # the batch as a whole failed: each run on its own, as run_task does
            for i in idxs:
                out[i] = run_task(tasks[i])
            continue
        for i, log in zip(idxs, logs, strict=True):
            try:
                metrics, status, reason = _verdict(prepared[i], log)
            except Exception as err:
                metrics, status, reason = {}, _error_status(err), f"{type(err).__name__}: {err}"
            out[i] = _record(tasks[i], status, reason, metrics, float("nan"))
            batched.append(i)
    share = (time.perf_counter() - t0) / max(1, len(tasks))  # a batched run's share of the batch
    for i in batched:
        out[i]["elapsed_s"] = share  # type: ignore[index]
    bkey = batch_key(tasks)
    recs = [rec for rec in out if rec is not None]
    for rec in recs:
        rec["batch"] = bkey  # the Dask task that ran it
    return recs


def dry_run(task: RunTask) -> dict[str, Any]:
    """A stand-in for :func:`run_task` that does not simulate: it sleeps a little and returns
    deterministic fake metrics. For checking a cluster's plumbing (``tsmpc sweep --dry-run``)."""
    h = int(task.id[:8], 16) / 0xFFFFFFFF
    time.sleep(0.2 + 0.2 * h)
    metrics = {"rmse": {k: h for k in ("x", "y", "theta", "v", "omega")}, "max_abs_lateral_m": h,
               "mpc_ms": {"median": 0.3, "p99": 0.5}, "wall_s": 0.2 + 0.2 * h}
    return _record(task, "completed", "", metrics, 0.2 + 0.2 * h)


def _record(
    task: RunTask, status: str, reason: str, metrics: dict[str, Any], elapsed: float
) -> dict[str, Any]:
    return {"id": task.id, "params": task.params.model_dump(), "status": status, "reason": reason,
            "metrics": metrics, "elapsed_s": elapsed, "worker_pid": os.getpid()}


def _simulate(task: RunTask) -> tuple[dict[str, Any], str, str]:
    from tsmpc.sim.simulator import simulate

    prep = _prepare(task)
    log = simulate(prep.cfg, prep.method, prep.scenario, kinematic_design=prep.designs[0],
                   dynamic_design=prep.designs[1], max_steps=prep.max_steps)
    return _verdict(prep, log)


@dataclass
class _Prepared:
    """One run as :func:`_simulate` sets it up: the controller's config (its seed the run's),
    the scenario, the designs, the step budget, the track it must stay on."""

    cfg: Config
    method: str
    scenario: Any
    designs: tuple[Any, Any]
    max_steps: int | None
    track: Any


def _prepare(task: RunTask) -> _Prepared:
    from dataclasses import replace as dc_replace

    from tsmpc.blas import limit_blas_threads

    limit_blas_threads()  # a Dask worker per core: one BLAS thread each (tsmpc.blas)

    from tsmpc.config import replace
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.planning.reference import Reference
    from tsmpc.planning.tracks import is_tumftm, load_tumftm, plan_track
    from tsmpc.robustness import apply_robustness
    from tsmpc.scenarios import ConstantFriction, paper_friction_profile
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.simulator import Scenario
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    p = task.params
    cfg = validate(Config, task.config, source="sweep config")
    if p.seed is not None:
        cfg = replace(cfg, seed=p.seed)
    if p.noise_scale != 1.0:
        cfg = replace(cfg, noise=replace(cfg.noise, scale=cfg.noise.scale * p.noise_scale))
    Tc, N = cfg.rates.Tc, cfg.mpc.N
    track = None
    if p.track == "builtin":
        sc = Scenario("builtin-circuit", builtin_circuit(dt=Tc), meta={"reference": "builtin-circuit"})
    else:
        path = track_file(p.track, task.root)
        assert path is not None  # "builtin" is handled above
        if is_tumftm(path):
            track = load_tumftm(path)
            ref = plan_track(track, cfg.planner, dt=Tc, tail_s=(N + 1) * Tc)
            sc = Scenario(track.name, ref, meta={"reference": str(path)})
        else:
            sc = load_scenario(cfg, path)
    if p.speed_scale != 1.0:  # the same path, traversed faster: time compressed by the scale
        r = sc.reference
        s = p.speed_scale
        fast = Reference(r.t / s, r.x, r.y, r.theta, r.v * s, r.omega * s, r.kappa)
        sc = dc_replace(sc, reference=fast.resample(Tc))
    friction = (paper_friction_profile() if p.friction == "paper"
                else ConstantFriction(_FRICTION_MU[p.friction]))
    bound = task.max_lateral_m
    if track is not None:  # beyond the widest point of the track the car is off it for sure
        bound = min(bound, float(np.max(np.maximum(track.w_left, track.w_right))))
    sc = dc_replace(sc, friction=friction, divergence_bound_m=bound)
    if (p.mass_scale, p.inertia_scale, p.cornering_scale) != (1.0, 1.0, 1.0):
        v = cfg.vehicle
        sc = dc_replace(sc, plant_vehicle=replace(
            v.with_stiffness_scaled(p.cornering_scale), mass=v.mass * p.mass_scale,
            inertia=v.inertia * p.inertia_scale))
    cfg, sc = apply_robustness(p.scenario, cfg, sc, until_s=task.duration_s)
    from tsmpc.conditions import apply_conditions  # the config's [scenario] section (issue 21)

    cfg, sc = apply_conditions(cfg, sc)
    kd, dd = task.designs or (None, None)
    if kd is None or not _same_designs(task.designs_config, cfg):
        kd, dd = load_or_design_kinematic(cfg), load_or_design_dynamic(cfg)  # this run's controller
    max_steps = None if task.duration_s is None else max(1, round(task.duration_s / Tc))
    return _Prepared(cfg, p.method, sc, (kd, dd), max_steps, track)


def _verdict(prep: _Prepared, log: Any) -> tuple[dict[str, Any], str, str]:
    """(metrics, status, reason) of a finished run."""
    from tsmpc.planning.tracks import off_track
    from tsmpc.sim.metrics import compute_metrics

    track = prep.track
    metrics = compute_metrics(log)
    status, reason = "completed", ""
    if log.termination != "completed":
        status, reason = "diverged", log.termination
    elif track is not None and off_track(track, log.state_outer[:, 0], log.state_outer[:, 1]).any():
        k = int(np.argmax(off_track(track, log.state_outer[:, 0], log.state_outer[:, 1])))
        status, reason = "diverged", f"left the track at t = {log.t_outer[k] - log.t_outer[0]:.1f} s"
    else:
        from tsmpc.sim.health import health_problem

        problem = health_problem(metrics)  # completed, but the controller did not work
        if problem:
            status, reason = "degraded", problem
        else:
            from tsmpc.sim.health import degradation

            problem = degradation(metrics, log, prep.cfg)  # or the car could not do it (issue 36)
            if problem:
                status, reason = "degraded", problem
    return metrics, status, reason


# -- execution -----------------------------------------------------------------------------
ProgressFn = Callable[[int, int, dict[str, Any]], None]
#: Writes the summary plots of a sweep table into a folder; returns the files (report layer).
PlotFn = Callable[[Any, Path, tuple[str, ...]], list[Path]]


def read_record(path: Path, rid: str | None = None, params: dict[str, Any] | None = None
                ) -> dict[str, Any] | None:
    """The run record at ``path`` if it is one, else None. A record is a JSON object with this
    ``id`` (``rid``, default the file's stem), a known status, valid params (``params``: equal to
    these, the run's own) and metrics that make sense (:func:`record_problem`). Not a record:
    empty, garbage, ``[]``, a folder, too large, too deeply nested, an RMSE of ``-1e300`` or
    ``"oops"`` — resume sets it aside and re-runs it, aggregation never sees it."""
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import read_text

    try:
        rec = json.loads(read_text(path, "run record", limit=16 * 1024 * 1024))
    except (TsmpcError, ValueError, RecursionError):
        return None
    if not isinstance(rec, dict) or rec.get("id") != (rid or path.stem):
        return None
    if record_problem(rec, params) is not None:
        return None
    return rec


#: The timing blocks and scalar metrics a record may carry (the columns of the aggregate table):
#: each a number >= 0, or NaN (not measured: no samples, no such force in the plant).
_TIMINGS = ("mpc_ms", "mhe_ms")
_SCALARS = ("max_abs_lateral_m", "friction_rmse_N", "slip_rmse_rad", "simulated_s", "wall_s")
_RMSE_KEYS = ("x", "y", "theta", "v", "omega")


def _measure(v: Any, *, inf_ok: bool = False) -> bool:
    """A measured quantity: a number (not a bool), >= 0, NaN (not measured) or finite
    (``inf_ok``: +inf too, e.g. the real-time factor of a run that took no measurable time)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    if isinstance(v, int):
        return v >= 0
    return math.isnan(v) or (v >= 0 and (inf_ok or math.isfinite(v)))


def record_problem(rec: dict[str, Any], params: dict[str, Any] | None = None) -> str | None:
    """What makes ``rec`` not a valid run record (None: valid): status, params (strictly the
    :class:`RunParams` schema; equal to ``params`` when given), reason, elapsed time, and every
    metric the aggregate table reads in range (an RMSE, a time, a count: >= 0; NaN = not
    measured; never ±inf, a string or a bool)."""
    if rec.get("status") not in RECORD_STATUSES:
        return f"status {_clip(rec.get('status'))}: not one of {', '.join(RECORD_STATUSES)}"
    p = rec.get("params")
    if not isinstance(p, dict):
        return "params: not an object"
    try:
        RunParams(**p)
    except (ValidationError, TypeError, ValueError):
        return "params: not the parameters of a run"
    if params is not None and p != params:
        return "params: not this run's"
    if not isinstance(rec.get("reason", ""), str):
        return "reason: not a string"
    if "elapsed_s" in rec and not _measure(rec["elapsed_s"]):
        return f"elapsed_s = {_clip(rec['elapsed_s'])}: not a time >= 0"
    m = rec.get("metrics", {})
    if not isinstance(m, dict):
        return "metrics: not an object"
    rmse = m.get("rmse", {})
    if not isinstance(rmse, dict) or set(rmse) - set(_RMSE_KEYS):
        return "metrics.rmse: not an object of x, y, theta, v, omega"
    for k, v in rmse.items():
        if not _measure(v):
            return f"metrics.rmse.{k} = {_clip(v)}: an RMSE is a finite number >= 0"
    for block in _TIMINGS:
        t = m.get(block, {})
        if not isinstance(t, dict):
            return f"metrics.{block}: not an object"
        for q in ("median", "p99"):
            if q in t and not _measure(t[q]):
                return f"metrics.{block}.{q} = {_clip(t[q])}: a time is a finite number >= 0"
    for k in _SCALARS:
        if k in m and not _measure(m[k]):
            return f"metrics.{k} = {_clip(m[k])}: must be a finite number >= 0"
    if "realtime_factor" in m and not _measure(m["realtime_factor"], inf_ok=True):
        return f"metrics.realtime_factor = {_clip(m['realtime_factor'])}: must be >= 0"
    events = m.get("events", {})
    if not isinstance(events, dict):
        return "metrics.events: not an object"
    for k, v in events.items():
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            return f"metrics.events.{_clip(k)} = {_clip(v)}: a count is an integer >= 0"
    return None


def _clip(v: Any) -> str:
    """A short repr of a value read from a file (huge ints and strings cut)."""
    try:
        text = repr(v)
    except ValueError:  # an int beyond sys.get_int_max_str_digits()
        return "<a huge integer>"
    return text if len(text) <= 40 else text[:37] + "..."


def _set_aside(path: Path, runs_dir: Path) -> None:
    """Move an unreadable record out of the way (kept for inspection, never deleted)."""
    bad = runs_dir / ".unreadable"
    bad.mkdir(exist_ok=True)
    target = bad / f"{path.name}.{time.strftime('%Y%m%dT%H%M%S')}.{os.getpid()}"
    os.replace(path, target)


def records_on_disk(runs_dir: Path, ids: set[str] | dict[str, dict[str, Any]], *, repair: bool,
                    retry_failed: bool) -> tuple[set[str], int, int]:
    """(ids whose record on disk counts as done, unreadable records, failed records to retry).
    ``ids`` may map each id to its run's params (a record must then hold exactly those).
    ``repair``: unreadable records are set aside under ``runs/.unreadable/``."""
    done: set[str] = set()
    unreadable = retry = 0
    if not runs_dir.is_dir():
        return done, 0, 0
    expected = ids if isinstance(ids, dict) else {}
    for path in sorted(runs_dir.glob("*.json")):
        if path.stem not in ids:
            continue
        rec = read_record(path, params=expected.get(path.stem))
        if rec is None:
            unreadable += 1
            if repair:
                _set_aside(path, runs_dir)
            continue
        if rec["status"] == "failed" and retry_failed:
            retry += 1
            continue
        done.add(path.stem)
    return done, unreadable, retry


def run_sweep(
    spec: SweepSpec, out: str | Path, *, scheduler: str | None = None, workers: int = 2,
    resume: bool = False, run_fn: Callable[[RunTask], dict[str, Any]] = run_task,
    progress: ProgressFn | None = None, plots: bool = True, plotter: PlotFn | None = None,
    connect_timeout: float = 5.0, design_fn: Callable[[Config], tuple[Any, Any]] | None = None,
    retry_failed: bool | None = None,
    shield: Callable[[], contextlib.AbstractContextManager[Any]] = contextlib.nullcontext,
) -> SweepResult:
    """Run every task of ``spec`` on Dask and write the records, the aggregate and the plots.

    Args:
        spec: validated sweep (see :func:`load_sweep`).
        out: output folder (``runs/`` holds one JSON record per run).
        scheduler: address of an existing Dask scheduler; None starts a LocalCluster of
            ``workers`` single-threaded worker processes on the loopback interface.
        resume: skip runs whose record is already in ``out/runs``. Without it an ``out`` that
            already holds records is refused (nothing is overwritten). Unreadable records are
            set aside (``runs/.unreadable/``) and re-run.
        retry_failed: re-run the runs whose record says ``failed`` (lost to worker failures);
            None = with ``resume``.
        run_fn: the task function (default: simulate; :func:`dry_run` for plumbing checks).
        progress: called as ``progress(done, total, record)`` after each record is written.
        plots: write the summary plots.
        plotter: writes them as ``plotter(table, out, AXES)``; None = the report layer's
            :func:`tsmpc.report.sweep_plots.save_sweep_plots`, imported only then (this module
            imports no plotting code at import time).
        connect_timeout: seconds to wait for ``scheduler`` before giving up (ConfigError).
        design_fn: loads or solves the LMI designs of the base config (e.g. with a status line).
        shield: a context manager around the cluster's start-up and shutdown, which must not be
            cut in the middle (the CLI's ``deferred_interrupts``: a signal is acted on once the
            cluster is whole or gone; a LocalCluster interrupted in its start-up left a Dask
            traceback at exit).

    A task the *cluster* lost — cancelled, the scheduler's connection lost, a comm closed — is
    not a result: no record is written for it, and it is listed in ``incomplete`` (with the runs
    whose record says ``failed``); the caller reports the sweep unfinished and ``resume`` runs them.
    """
    out = Path(out)
    runs_dir = out / "runs"
    tasks = expand(spec)
    ids = {t.id for t in tasks}
    retry_failed = resume if retry_failed is None else retry_failed
    any_on_disk = runs_dir.is_dir() and any(p.stem in ids for p in runs_dir.glob("*.json"))
    if any_on_disk and not resume:
        raise ConfigError(f"{out}: already holds records of this sweep; "
                          "use --resume to finish it or choose another --out")
    expected = {t.id: t.params.model_dump(mode="json") for t in tasks}
    on_disk, _, _ = records_on_disk(runs_dir, expected, repair=resume, retry_failed=retry_failed)
    pending = [t for t in tasks if t.id not in on_disk]
    skipped = len(tasks) - len(pending)
    written: set[str] = set()
    failed = duplicates = lost = 0
    lost_reason = ""
    # Connect first (a wrong address fails in seconds), then the designs: nothing is written
    # before both worked.
    with shield():  # a cluster is started whole, or not at all
        client, cluster = connect(scheduler, workers, connect_timeout) if pending else (None, None)
    try:
        if client is not None and run_fn is run_task:
            # The axes never touch the controller settings, so one pair of LMI designs serves
            # every run: solved (or loaded from the design cache) and certified here, shipped
            # with the tasks — remote workers need no shared disk and solve nothing.
            cfg = base_config(spec)
            designs = design_fn(cfg) if design_fn is not None else _designs(cfg)
            _solve_run_designs(pending, cfg, design_fn)  # the controllers the axes name
            if scheduler is None:  # local workers share this machine's kernel cache: fill it once
                from tsmpc import kernels

                kernels.warmup()
                if spec.batch > 1:
                    from tsmpc.sim import batch

                    batch.warmup()
            pending = [RunTask(t.id, t.params, t.config, t.duration_s, t.max_lateral_m, t.root,
                               designs, cfg.model_dump(mode="json")) for t in pending]
    except BaseException:
        with shield():
            _close(client, cluster)
        raise
    runs_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "sweep.json", json.dumps(
        {"name": spec.name, "spec": spec.model_dump(mode="json"),
         "runs": [{"id": t.id, **t.params.model_dump()} for t in tasks]}, indent=1))
    if client is not None:
        try:
            with _quiet_dask():
                tally = _collect(client, pending, tasks, spec, run_fn, workers, runs_dir, progress, skipped)
        finally:
            with shield():
                _close(client, cluster)
        written, failed, duplicates, lost, lost_reason = tally
    table = aggregate(out, expected)
    files = write_outputs(table, out, plots=plots, plotter=plotter)
    done_ids, _, _ = records_on_disk(runs_dir, expected, repair=False, retry_failed=True)
    incomplete = [t.id for t in tasks if t.id not in done_ids]
    return SweepResult(out, len(tasks), len(written), skipped, failed, duplicates, table, files,
                       incomplete, lost, lost_reason)


def _collect(client: Any, pending: list[RunTask], tasks: list[RunTask], spec: SweepSpec,
             run_fn: Callable[[RunTask], dict[str, Any]], workers: int, runs_dir: Path,
             progress: ProgressFn | None, done: int) -> tuple[set[str], int, int, int, str]:
    """Submit the pending runs (in batches where the engine batches them), write each record as
    it comes: (ids written, runs failed, duplicates, runs the cluster lost, why it lost them)."""
    from dask.distributed import as_completed

    written: set[str] = set()
    failed = duplicates = lost = 0
    lost_reason = ""
    chunks: list[list[RunTask]] = []
    singles = pending
    if run_fn is run_task:
        n_workers = max(1, len(client.scheduler_info().get("workers", {})) or workers)
        chunks, singles = batches(pending, spec.batch, n_workers, among=tasks)
    futures = {client.submit(run_batch, c, key=batch_key(c), retries=spec.retries,
                             pure=False): c for c in chunks}
    futures.update({client.submit(run_fn, t, key=f"tsmpc-run-{t.id}", retries=spec.retries,
                                  pure=False): [t] for t in singles})
    for fut in as_completed(futures):
        chunk = futures.pop(fut)
        try:
            got = fut.result()
            recs = got if isinstance(got, list) else [got]
        except Exception as err:
            if _cluster_lost(err):  # not a result: no record; resume runs it
                lost += len(chunk)
                lost_reason = lost_reason or " ".join(f"{type(err).__name__}: {err}".split())
                with contextlib.suppress(Exception):
                    fut.release()
                continue
            # e.g. KilledWorker after repeated worker deaths: a record says so
            failed += len(chunk)
            recs = [_record(t, "failed", f"{type(err).__name__}: {err}", {}, float("nan"))
                    for t in chunk]
        # Forget the result on the cluster at once: a finished task whose result still sits in
        # a worker's memory would be recomputed if that worker died.
        with contextlib.suppress(Exception):  # the scheduler may be gone by now
            fut.release()
        del fut
        for task, rec in zip(chunk, recs, strict=True):
            if task.id in written:
                duplicates += 1
                continue
            atomic_write_text(runs_dir / f"{task.id}.json", json.dumps(rec, indent=1))
            written.add(task.id)
            done += 1
            if progress is not None:
                progress(done, len(tasks), rec)
    return written, failed, duplicates, lost, lost_reason


def _cluster_lost(err: BaseException) -> bool:
    """Did the cluster, not the task, fail (``FutureCancelledError`` — e.g. reason
    "scheduler-connection-lost" —, a closed comm, a timeout, a lost connection)? A task of the
    sweep never raises for a bad run (its failures are records), so these are no results."""
    import asyncio
    import concurrent.futures

    from distributed.comm.core import CommClosedError

    return isinstance(err, concurrent.futures.CancelledError | asyncio.CancelledError
                      | CommClosedError | OSError | TimeoutError)


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """This process's Dask log lines silenced: a lost scheduler logs errors (and tracebacks) of
    its own, while the sweep reports, in one line and in PARTIAL, what is missing."""
    import logging

    # Dask's logging config gives some children a level of their own (distributed.client):
    # each is silenced, not only the parent.
    names = ["distributed", *(n for n in list(logging.root.manager.loggerDict)
                              if n.startswith("distributed."))]
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)


def _close(client: Any, cluster: Any) -> None:
    """Close the client and the local cluster, whatever state they are in: a client whose
    scheduler is gone raises or waits on close (bounded here)."""
    with _quiet_dask():
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=10)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=20)


#: Runs of one controller a sweep must hold for them to be batched: below it, the batch kernel's
#: vector groups (32 lanes) would run mostly empty and one run per task is faster.
MIN_LANES = 8


def _controller(t: RunTask) -> tuple[Any, ...]:
    """What the runs of one batch share: method, duration and the config but the seed."""
    controller = dict(t.config)
    controller.pop("seed", None)
    return (t.params.method, t.duration_s, json.dumps(controller, sort_keys=True))


def batches(tasks: list[RunTask], size: int, n_workers: int, *,
            among: list[RunTask] | None = None) -> tuple[list[list[RunTask]], list[RunTask]]:
    """(batches, single runs): the Dask tasks of a sweep. Runs of one controller go together in
    chunks of at most ``size`` runs, of near-equal size, small enough that each worker gets two or
    more (but ≥ :data:`MIN_LANES` runs); a controller with fewer than ``min(MIN_LANES, size)``
    runs in the whole sweep (``among``, default ``tasks``) runs one run per task, as does every
    run when ``size`` is 1. Whether a run is batched depends on the sweep alone — never on what
    is pending (``--resume``) or on the number of workers — so its record does too."""
    counts: dict[tuple[Any, ...], int] = {}
    for t in among if among is not None else tasks:
        key = _controller(t)
        counts[key] = counts.get(key, 0) + 1
    floor = min(MIN_LANES, size)
    per = min(size, max(MIN_LANES, math.ceil(len(tasks) / (2 * max(1, n_workers)))))
    groups: dict[tuple[Any, ...], list[RunTask]] = {}
    singles: list[RunTask] = []
    for t in tasks:
        key = _controller(t)
        if size > 1 and counts.get(key, 0) >= floor:
            groups.setdefault(key, []).append(t)
        else:
            singles.append(t)
    chunks: list[list[RunTask]] = []
    for g in groups.values():
        k = math.ceil(len(g) / per)
        q, r = divmod(len(g), k)
        i = 0
        for j in range(k):
            n = q + (1 if j < r else 0)
            chunks.append(g[i:i + n])
            i += n
    return chunks, singles


def batch_key(chunk: list[RunTask]) -> str:
    """The Dask key of a batch: its runs' ids hashed (``tsmpc-batch-<hash>-<n runs>``)."""
    digest = hashlib.sha256("".join(t.id for t in chunk).encode()).hexdigest()[:20]
    return f"tsmpc-batch-{digest}-{len(chunk)}"


def _same_designs(a: dict[str, Any] | None, cfg: Config) -> bool:
    """Do the designs made for config ``a`` serve ``cfg`` (same design inputs)?"""
    if a is None:
        return False
    from tsmpc.synthesis.cache import dynamic_key, kinematic_key

    base = validate(Config, a, source="sweep designs")
    return kinematic_key(base) == kinematic_key(cfg) and dynamic_key(base) == dynamic_key(cfg)


def _solve_run_designs(tasks: list[RunTask], base: Config,
                       design_fn: Callable[[Config], tuple[Any, Any]] | None) -> None:
    """Solve (or load) once, into the design cache, the designs of every controller the runs use
    beyond the base config's (other presets, oracle-tuned or told vehicles), so workers only load them."""
    from tsmpc.conditions import controller_vehicle
    from tsmpc.config import replace
    from tsmpc.synthesis.cache import dynamic_key, kinematic_key

    seen = {(kinematic_key(base), dynamic_key(base))}
    for t in tasks:
        cfg = validate(Config, t.config, source="sweep run")
        cfg = replace(cfg, vehicle=controller_vehicle(cfg))  # (oracle-tuned or told parts of the plant)
        key = (kinematic_key(cfg), dynamic_key(cfg))
        if key not in seen:
            seen.add(key)
            (design_fn or _designs)(cfg)


def _designs(cfg: Config) -> tuple[Any, Any]:
    """The base config's designs; a failed design is a :class:`ConfigError` naming the likely
    field (tsmpc.diagnose), whatever the solver raised."""
    from tsmpc.diagnose import explain_design_failure
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    out = []
    for kind, fn in (("kinematic", load_or_design_kinematic), ("dynamic", load_or_design_dynamic)):
        try:
            out.append(fn(cfg))
        except Exception as err:  # the solver's own exceptions too
            raise ConfigError(f"base config: {explain_design_failure(kind, cfg, err)}") from None
    return out[0], out[1]


def connect(scheduler: str | None, workers: int, timeout: float = 5.0) -> tuple[Any, Any]:
    """(client, cluster): a client of the scheduler at ``scheduler`` (within ``timeout`` s), or
    of a new LocalCluster of ``workers`` single-threaded processes (cluster None when remote).
    An unreachable or malformed address raises :class:`ConfigError` (one line)."""
    import logging

    from dask.distributed import Client, LocalCluster

    if scheduler is None:
        # The workers' own log lines (a task cancelled at shutdown, a lost connection) are not
        # the user's: what a sweep lost, it reports itself (records, PARTIAL).
        try:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=":0",
                                   silence_logs=logging.CRITICAL)
        except Exception as err:  # e.g. "Nanny failed to start." on a machine short of memory
            raise ClusterError(f"the local Dask cluster of {workers} worker processes did not "
                               f"start ({type(err).__name__}: {' '.join(str(err).split())[:200]}); "
                               "the machine may be short of memory or processes: try fewer "
                               "--workers") from None
        try:
            return Client(cluster), cluster
        except Exception as err:
            _close(None, cluster)
            raise ClusterError(f"could not connect to the local Dask cluster ({type(err).__name__}: "
                               f"{' '.join(str(err).split())[:200]})") from None
    if not math.isfinite(timeout) or timeout <= 0:
        raise ConfigError(f"--connect-timeout = {timeout}: must be a finite number > 0")
    from distributed.comm import parse_address  # pyright: ignore[reportPrivateImportUsage]  # (no __all__)

    try:
        proto, loc = parse_address(scheduler)
        if proto not in ("tcp", "tls", "inproc", "ucx", "ws", "wss") or ":" not in loc:
            raise ValueError("expected PROTOCOL://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    except (ValueError, TypeError) as err:
        raise ConfigError(f"--scheduler {scheduler!r}: not a scheduler address ({err})") from None
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)  # the connection retries log tracebacks of their own
    try:
        _probe(scheduler, timeout)
        return Client(scheduler, timeout=timeout), None
    except (OSError, TimeoutError, ValueError) as err:
        raise ConfigError(f"--scheduler {scheduler}: no scheduler answered within {timeout:g} s "
                          f"({type(err).__name__}); check the address or --connect-timeout") from None
    finally:
        quiet.setLevel(level)


def _probe(address: str, timeout: float) -> None:
    """Open a comm to ``address`` and complete Dask's handshake within ``timeout`` seconds (raises
    TimeoutError/OSError otherwise). ``Client(timeout=...)`` does not bound the handshake: a port
    that accepts but never speaks held it for a minute (issue 24)."""
    import asyncio

    from distributed.comm import connect as comm_connect  # pyright: ignore[reportPrivateImportUsage]

    async def go() -> None:
        comm = await asyncio.wait_for(comm_connect(address, timeout=timeout), timeout)
        await comm.close()

    asyncio.run(go())


# -- aggregation ---------------------------------------------------------------------------
def _row(rec: dict[str, Any]) -> dict[str, Any]:
    m = rec.get("metrics") or {}
    row: dict[str, Any] = {"id": rec["id"], "status": rec["status"], "reason": rec.get("reason", "")}
    row.update(rec["params"])
    for k, v in (m.get("rmse") or {}).items():
        row[f"rmse_{k}"] = v
    row["max_abs_lateral_m"] = m.get("max_abs_lateral_m", math.nan)
    for block in ("mpc_ms", "mhe_ms"):
        for q in ("median", "p99"):
            row[f"{block[:3]}_{q}_ms"] = (m.get(block) or {}).get(q, math.nan)
    for k in ("friction_rmse_N", "slip_rmse_rad", "simulated_s", "wall_s", "realtime_factor"):
        row[k] = m.get(k, math.nan)
    for k, v in (m.get("events") or {}).items():
        row[f"events_{k}"] = v
    row["elapsed_s"] = rec.get("elapsed_s", math.nan)
    return row


def aggregate(out: str | Path, ids: list[str] | dict[str, dict[str, Any]] | None = None) -> Any:
    """The aggregate table (pandas DataFrame, one row per valid run record in ``out/runs``;
    restricted to ``ids`` in that order when given; ``ids`` may map each id to its run's params,
    which a record must then hold)."""
    import pandas as pd

    runs_dir = Path(out) / "runs"
    expected = ids if isinstance(ids, dict) else {}
    recs = {}
    for p in sorted(runs_dir.glob("*.json")):
        # An unreadable or senseless record is no row (resume sets it aside and re-runs it).
        rec = read_record(p, params=expected.get(p.stem))
        if rec is not None:
            recs[rec["id"]] = rec
    order = [i for i in ids if i in recs] if ids is not None else list(recs)
    return pd.DataFrame([_row(recs[i]) for i in order])


#: The files a sweep writes next to ``runs/`` (the plots' names: tsmpc.report.sweep_plots).
OUTPUT_NAMES = ("aggregate.csv", "aggregate.parquet", "solve_times.png",
                *(f"by_{axis}.png" for axis in AXES))


def write_outputs(table: Any, out: Path, *, plots: bool = True, plotter: PlotFn | None = None
                  ) -> list[Path]:
    """Write the aggregate table (CSV, Parquet) and the plots of ``table`` into ``out``, together
    or not at all: every file is made in a staging folder first (``out/.tsmpc-outputs-*``), then
    the outputs of an earlier call that this one does not make are removed (no stale plot or
    Parquet next to a rewritten CSV) and the new files are moved in. A failure before the move
    leaves the earlier outputs as they were; one during the move removes them all."""
    import io
    import shutil
    import tempfile

    stage = Path(tempfile.mkdtemp(dir=out, prefix=".tsmpc-outputs-"))
    try:
        made = [stage / "aggregate.csv", stage / "aggregate.parquet"]
        buf = io.BytesIO()
        table.to_parquet(buf, index=False)  # may refuse the table: before any file is made
        atomic_write_text(made[0], table.to_csv(index=False))
        atomic_write_bytes(made[1], buf.getvalue())
        if plots and len(table):
            if plotter is None:
                from tsmpc.report.sweep_plots import save_sweep_plots

                plotter = save_sweep_plots
            made += [Path(f) for f in plotter(table, stage, AXES)]
        names = {f.name for f in made}
        try:
            for name in OUTPUT_NAMES:
                if name not in names:
                    (out / name).unlink(missing_ok=True)
            for f in made:
                os.replace(f, out / f.name)
        except BaseException:  # half moved: no mix of new and old outputs is left
            for name in OUTPUT_NAMES:
                with contextlib.suppress(OSError):
                    (out / name).unlink(missing_ok=True)
            raise
        return [out / f.name for f in made]
    finally:
        shutil.rmtree(stage, ignore_errors=True)

