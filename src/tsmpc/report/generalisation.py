"""The generalisation benchmark (issue 35): random draws from a *class* of sensor and vehicle errors,
each drawn from the whole class at once, the default controller against the oracle-tuned one.

The class (uniform draws, independent, bounds of issue 35), in the scenario vocabulary
(:class:`tsmpc.config.ScenarioSettings`):

| quantity | field | bounds |
|---|---|---|
| yaw-rate sensor bias | `scenario.sensors.omega_bias` | ±0.02 rad/s |
| speed sensor bias | `scenario.sensors.v_bias` | ±0.5 m/s |
| speed sensor scale | `scenario.sensors.v_scale` | 1 ± 0.03 |
| steering offset | `scenario.plant.steering_offset_rad` | ±1° (±0.017453 rad) |
| front cornering stiffness | `scenario.plant.cornering_front_scale` | 1 ± 0.4 |
| rear cornering stiffness | `scenario.plant.cornering_rear_scale` | 1 ± 0.4 |
| mass | `scenario.plant.mass_scale` | 1 ± 0.25 |
| yaw inertia | `scenario.plant.inertia_scale` | 1 ± 0.3 |
| CoG position | `scenario.plant.cog_to_front_scale` | ±10 % of the wheelbase |
| pose sample rate | `scenario.sensors.pose_rate_hz` | 1 to 10 Hz |

The CoG is drawn as a shift s of the wheelbase L = a + b (positive: forward, towards the front
axle) and written as the scale of a that gives it: ``cog_to_front_scale = (a − s L) / a`` with the
config's vehicle's a and b (the plant keeps the wheelbase; :func:`tsmpc.conditions.plant_vehicle`).

:func:`draws` is the whole draw procedure: ``numpy.random.default_rng(seed)``, one
``uniform(lo, hi, size=(n, 10))`` in the order of :data:`CLASS`, each value rounded to
:data:`DIGITS` decimals (the rounded value stays within its bounds). :func:`sweep_toml` writes the
draws as the cases of a sweep file (``examples/generalisation_draws.py`` writes
``examples/generalisation.toml`` and the held-back ``examples/generalisation_heldback.toml``).

From a sweep's aggregate table, :func:`draw_results` gives each draw's worst-column ratio: the
largest default / oracle-tuned over the mismatch benchmark's columns
(:data:`tsmpc.report.mismatch.RATIO_COLUMNS`: RMSE x, y, θ, v, ω and max |e_y|); a default run that
does not complete has ratio ∞. :func:`distribution` summarises them (median, 90th percentile by
linear interpolation between order statistics — ``numpy.percentile``'s default —, worst,
completions) and :func:`acceptance` checks issue 35's bounds: every draw completes, p90 ≤ 1.5,
worst ≤ 2.5. Computation only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tsmpc.report.mismatch import COLUMNS, RATIO_COLUMNS

__all__ = [
    "ATTRIBUTION",
    "CLASS",
    "DIGITS",
    "LEVEL_COLUMNS",
    "P90_BOUND",
    "WORST_BOUND",
    "WORST_K",
    "Draw",
    "DrawResult",
    "Param",
    "Summary",
    "acceptance",
    "attribution_controllers",
    "attribution_table",
    "case_table",
    "distribution",
    "draw_results",
    "draws",
    "drivers",
    "drivers_table",
    "levels_table",
    "summary_table",
    "sweep_toml",
    "worst_draws",
    "worst_table",
]


@dataclass(frozen=True)
class Param:
    """One quantity of the class: drawn uniformly in [lo, hi]."""

    key: str  #: the draw's name for it (a :class:`Draw` field)
    label: str  #: for tables
    lo: float
    hi: float
    unit: str


#: The class of issue 35, in draw order (changing the order changes every draw).
CLASS: tuple[Param, ...] = (
    Param("omega_bias", "yaw-rate bias", -0.02, 0.02, "rad/s"),
    Param("v_bias", "speed bias", -0.5, 0.5, "m/s"),
    Param("v_scale", "speed scale", 0.97, 1.03, "-"),
    Param("steering_offset_rad", "steering offset", -math.radians(1.0), math.radians(1.0), "rad"),
    Param("cornering_front_scale", "C_f", 0.6, 1.4, "-"),
    Param("cornering_rear_scale", "C_r", 0.6, 1.4, "-"),
    Param("mass_scale", "mass", 0.75, 1.25, "-"),
    Param("inertia_scale", "I_z", 0.7, 1.3, "-"),
    Param("cog_shift", "CoG shift (of L, + forward)", -0.1, 0.1, "-"),
    Param("pose_rate_hz", "pose rate", 1.0, 10.0, "Hz"),
)
#: Decimals each drawn value is rounded to (the TOML stays readable; far below any effect).
DIGITS = 6
#: Issue 35's acceptance: the 90th percentile and the worst of the worst-column ratio.
P90_BOUND = 1.5
WORST_BOUND = 2.5


@dataclass(frozen=True)
class Draw:
    """One draw of the class (fields as in :data:`CLASS`)."""

    name: str
    omega_bias: float
    v_bias: float
    v_scale: float
    steering_offset_rad: float
    cornering_front_scale: float
    cornering_rear_scale: float
    mass_scale: float
    inertia_scale: float
    cog_shift: float
    pose_rate_hz: float

    def value(self, key: str) -> float:
        return float(getattr(self, key))


def draws(seed: int, n: int, prefix: str = "d") -> list[Draw]:
    """``n`` draws of the class from ``seed`` (names ``{prefix}01``…), reproducible on any machine
    (numpy's PCG64 bit generator and its uniform doubles are fixed across numpy releases)."""
    if n < 1:
        raise ValueError(f"n = {n}: at least one draw")
    rng = np.random.default_rng(seed)
    lo = np.array([p.lo for p in CLASS])
    hi = np.array([p.hi for p in CLASS])
    u = rng.uniform(lo, hi, size=(n, len(CLASS)))
    width = max(2, len(str(n)))
    out = []
    for i, row in enumerate(u):
        vals = {p.key: min(max(round(float(v), DIGITS), p.lo), p.hi) for p, v in zip(CLASS, row, strict=True)}
        out.append(Draw(f"{prefix}{i + 1:0{width}d}", **vals))
    return out


def case_table(d: Draw, a: float, b: float) -> dict[str, dict[str, float]]:
    """The draw as a ``[scenario]`` table for a vehicle with CoG-to-axle distances ``a``, ``b``."""
    cog = (a - d.cog_shift * (a + b)) / a
    return {"sensors": {"omega_bias": d.omega_bias, "v_bias": d.v_bias, "v_scale": d.v_scale,
                        "pose_rate_hz": d.pose_rate_hz},
            "plant": {"steering_offset_rad": d.steering_offset_rad,
                      "cornering_front_scale": d.cornering_front_scale,
                      "cornering_rear_scale": d.cornering_rear_scale, "mass_scale": d.mass_scale,
                      "inertia_scale": d.inertia_scale, "cog_to_front_scale": round(cog, DIGITS)}}


def _inline(table: dict[str, float]) -> str:
    return "{ " + ", ".join(f"{k} = {v!r}" for k, v in table.items()) + " }"


def sweep_toml(name: str, seed: int, ds: list[Draw], track: str, a: float, b: float,
               header: str = "") -> str:
    """The sweep file of the draws: the paper's reference ``track``, REF, seed 1, the default and
    the oracle-tuned controller, one case per draw (its CoG shift in a comment)."""
    cases = ", ".join(f'"{d.name}"' for d in ds)
    lines = [header.rstrip("\n"), "", f'name = "{name}"', "",
             f"# {len(ds)} draws of tsmpc.report.generalisation.draws(seed={seed}, n={len(ds)})", "[grid]",
             f'track = ["{track}"]', 'controller = ["default", "oracle-tuned"]', 'method = ["ref"]',
             f"case = [{cases}]", "seed = [1]", "", "[controllers.oracle-tuned]",
             "scenario = { oracle_tuned = true }", ""]
    for d in ds:
        t = case_table(d, a, b)
        lines += [f"[cases.{d.name}]   # CoG shift {d.cog_shift:+.6f} of the wheelbase",
                  f"sensors = {_inline(t['sensors'])}", f"plant = {_inline(t['plant'])}", ""]
    return "\n".join(lines).lstrip("\n")


# -- the results ------------------------------------------------------------------------------

@dataclass(frozen=True)
class DrawResult:
    """One draw's default run against its oracle-tuned run."""

    case: str
    worst_ratio: float  #: largest default / oracle over RATIO_COLUMNS (∞ when the default did not complete)
    worst_column: str  #: the column of worst_ratio ("" when the default run has no metrics)
    ratios: dict[str, float]
    default_status: str
    oracle_status: str

    @property
    def completed(self) -> bool:
        return self.default_status == "completed"


def _ratio(a: float, b: float) -> float:
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    if b <= 0.0:
        return 1.0 if a <= 0.0 else math.inf
    return a / b


def draw_results(table: Any, cases: list[str], default: str = "default",
                 oracle: str = "oracle-tuned") -> list[DrawResult]:
    """Each case of ``cases`` with both runs in ``table`` (a sweep's aggregate, one track)."""
    out = []
    for case in cases:
        d = table[(table["case"] == case) & (table["controller"] == default)]
        o = table[(table["case"] == case) & (table["controller"] == oracle)]
        if d.empty or o.empty:
            continue
        dr, orow = d.iloc[0], o.iloc[0]
        ratios = {k: _ratio(float(dr.get(k, math.nan)), float(orow.get(k, math.nan))) for k in RATIO_COLUMNS}
        worst = max(ratios, key=lambda k: ratios[k])
        d_status, o_status = str(dr["status"]), str(orow["status"])
        value = ratios[worst] if d_status == "completed" else math.inf
        out.append(DrawResult(case, value, worst, ratios, d_status, o_status))
    return out


@dataclass(frozen=True)
class Summary:
    """The distribution of the worst-column ratio over a set of draws."""

    n: int
    median: float
    p90: float
    worst: float
    completed_default: int
    completed_oracle: int
    #: how often each column is the worst one (completed default runs)
    worst_columns: dict[str, int]


def _percentile(s: np.ndarray, q: float) -> float:
    """``numpy.percentile(s, q)`` (linear interpolation between order statistics) of sorted ``s``,
    where a percentile that leans on an ∞ (a run that did not complete) is ∞, not nan."""
    pos = q / 100.0 * (len(s) - 1)
    lo, hi = math.floor(pos), math.ceil(pos)
    frac = pos - lo
    if frac == 0.0 or math.isinf(s[hi]):
        return float(s[lo]) if frac == 0.0 else math.inf
    return float(s[lo] + frac * (s[hi] - s[lo]))


def distribution(results: list[DrawResult]) -> Summary:
    """Median, 90th percentile (linear interpolation, ``numpy.percentile``), worst and completions."""
    if not results:
        raise ValueError("no draw has both runs")
    r = np.array([x.worst_ratio for x in results], dtype=float)
    counts: dict[str, int] = {}
    for x in results:
        if x.completed:
            counts[x.worst_column] = counts.get(x.worst_column, 0) + 1
    s = np.sort(r)
    med, p90 = _percentile(s, 50.0), _percentile(s, 90.0)
    return Summary(len(results), med, p90, float(r.max()),
                   sum(x.completed for x in results), sum(x.oracle_status == "completed" for x in results),
                   dict(sorted(counts.items(), key=lambda kv: -kv[1])))


def acceptance(s: Summary) -> bool:
    """Issue 35's bounds: every draw completes, p90 ≤ 1.5, worst ≤ 2.5."""
    return s.completed_default == s.n and s.p90 <= P90_BOUND and s.worst <= WORST_BOUND


def _label(col: str) -> str:
    return dict((k, label) for k, label, _ in COLUMNS).get(col, col)


def _x(v: float) -> str:
    return "∞" if math.isinf(v) else f"{v:.2f}"


#: The rows' own levels beside the ratio: (aggregate column, label, digits).
LEVEL_COLUMNS = (("rmse_y", "RMSE y [m]", 4), ("max_abs_lateral_m", "max abs e_y [m]", 3),
                 ("rmse_v", "RMSE v [m/s]", 3))


def levels_table(rows: list[tuple[str, Any]],
                 controllers: tuple[str, ...] = ("default", "oracle-tuned")) -> str:
    """Markdown: per set of draws (name, its sweep's aggregate) and controller, the median over the
    draws of each of :data:`LEVEL_COLUMNS` (completed runs). The ratio's denominator in the open: a
    change that makes the oracle-tuned row worse shrinks every ratio without helping the default."""
    head = ["draws", "controller", *(f"median {label}" for _, label, _ in LEVEL_COLUMNS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, table in rows:
        for c in controllers:
            t = table[(table["controller"] == c) & (table["status"] == "completed")]
            cells = [f"{float(t[col].median()):.{d}f}" if len(t) else "—" for col, _, d in LEVEL_COLUMNS]
            lines.append(f"| {name} | {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_table(rows: list[tuple[str, Summary]]) -> str:
    """Markdown: one row per set of draws (name, summary)."""
    lines = ["| draws | runs completed (default / oracle-tuned) | median | 90th percentile | worst | "
             "worst column (how often) | met (all complete, p90 ≤ 1.5, worst ≤ 2.5) |",
             "|---|---|---|---|---|---|---|"]
    for name, s in rows:
        cols = ", ".join(f"{_label(k)} {n}" for k, n in s.worst_columns.items())
        lines.append(f"| {name} | {s.completed_default} / {s.completed_oracle} of {s.n} | {_x(s.median)} | "
                     f"{_x(s.p90)} | {_x(s.worst)} | {cols} | {'yes' if acceptance(s) else '**no**'} |")
    return "\n".join(lines)


#: Draws the worst-draw tables show (and the attribution re-runs).
WORST_K = 5


def worst_draws(results: list[DrawResult], k: int = WORST_K) -> list[DrawResult]:
    """The ``k`` draws of largest worst-column ratio, largest first (ties in the given order)."""
    return sorted(results, key=lambda x: -x.worst_ratio)[:k]


def worst_table(results: list[DrawResult], ds: list[Draw], k: int = WORST_K) -> str:
    """Markdown: the ``k`` draws of largest worst-column ratio with their parameters."""
    by_name = {d.name: d for d in ds}
    top = worst_draws(results, k)
    head = ["draw", "worst ratio", "column", "yaw-rate bias [rad/s]", "speed bias [m/s]", "speed scale",
            "steering offset [°]", "C_f ×", "C_r ×", "mass ×", "I_z ×", "CoG shift [% of L]",
            "pose rate [Hz]", "default run"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for x in top:
        d = by_name[x.case]
        status = "completed" if x.completed else f"**{x.default_status}**"
        column = _label(x.worst_column) if x.completed else "—"  # ∞ in every column
        lines.append(
            f"| {x.case} | {_x(x.worst_ratio)} | {column} | {d.omega_bias:+.4f} | "
            f"{d.v_bias:+.3f} | {d.v_scale:.4f} | {math.degrees(d.steering_offset_rad):+.2f} | "
            f"{d.cornering_front_scale:.2f} | {d.cornering_rear_scale:.2f} | {d.mass_scale:.2f} | "
            f"{d.inertia_scale:.2f} | {100.0 * d.cog_shift:+.1f} | {d.pose_rate_hz:.1f} | {status} |")
    return "\n".join(lines)


#: The attribution's controllers: the default told one part of the plant (``scenario.known``), the
#: plant unchanged — (controller name, column label, the parts told).
ATTRIBUTION: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("told-mass", "mass", ("mass",)),
    ("told-inertia", "I_z", ("inertia",)),
    ("told-stiffness", "C_f, C_r", ("cornering_stiffness",)),
    ("told-cog", "CoG", ("cog",)),
    ("told-vehicle", "all four", ("mass", "inertia", "cornering_stiffness", "cog")),
    ("told-sensors", "sensor biases", ("sensor_biases",)),
    ("told-steering", "steering offset", ("steering_offset",)),
)


def attribution_controllers() -> dict[str, dict[str, Any]]:
    """The ``[controllers]`` tables of :data:`ATTRIBUTION` for a sweep."""
    return {name: {"scenario": {"known": list(parts)}} for name, _, parts in ATTRIBUTION}


def attribution_table(table: Any, cases: list[str]) -> str:
    """Markdown: for each draw of ``cases``, the worst-column ratio against the oracle-tuned row of
    the default controller and of the default told each part of :data:`ATTRIBUTION` (a sweep's
    aggregate holding all those controllers; ∞: the run did not complete, —: no run)."""
    head = ["draw", "default", *(f"told {label}" for _, label, _ in ATTRIBUTION)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for case in cases:
        cells = []
        for name in ("default", *(n for n, _, _ in ATTRIBUTION)):
            r = draw_results(table, [case], default=name)
            cells.append(_x(r[0].worst_ratio) if r else "—")
        lines.append(f"| {case} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 0…n−1 (ties get their mean rank; ∞ ranks highest)."""
    order = np.argsort(x, kind="stable")
    r = np.empty(len(x))
    r[order] = np.arange(len(x), dtype=float)
    for v in np.unique(x):  # ties: the mean of their ranks
        tie = x == v
        if tie.sum() > 1:
            r[tie] = r[tie].mean()
    return r


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    ra, rb = _ranks(a), _ranks(b)
    ra, rb = ra - ra.mean(), rb - rb.mean()
    den = math.sqrt(float((ra * ra).sum() * (rb * rb).sum()))
    return float((ra * rb).sum() / den) if den > 0 else 0.0


def drivers(results: list[DrawResult], ds: list[Draw]) -> list[tuple[Param, float, float]]:
    """Which quantity of the class drives the worst-column ratio: per quantity, Spearman's rank
    correlation of the ratio with the drawn value and with its distance from the class's centre
    (nominal), largest first by the larger of the two in magnitude."""
    by_name = {d.name: d for d in ds}
    r = np.array([x.worst_ratio for x in results])
    out = []
    for p in CLASS:
        v = np.array([by_name[x.case].value(p.key) for x in results])
        out.append((p, _spearman(v, r), _spearman(np.abs(v - 0.5 * (p.lo + p.hi)), r)))
    return sorted(out, key=lambda t: -max(abs(t[1]), abs(t[2])))


def drivers_table(results: list[DrawResult], ds: list[Draw]) -> str:
    """Markdown of :func:`drivers` (|ρ| above 2/√n stands out from chance at about 5 %)."""
    lines = ["| quantity | field | rank correlation with the value | with its distance from nominal |",
             "|---|---|---|---|"]
    field = {"omega_bias": "sensors.omega_bias", "v_bias": "sensors.v_bias", "v_scale": "sensors.v_scale",
             "pose_rate_hz": "sensors.pose_rate_hz", "cog_shift": "plant.cog_to_front_scale"}
    for p, rho, rho_abs in drivers(results, ds):
        lines.append(f"| {p.label} | `{field.get(p.key, 'plant.' + p.key)}` | {rho:+.2f} | {rho_abs:+.2f} |")
    return "\n".join(lines)
