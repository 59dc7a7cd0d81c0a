"""Table 5 explained: the paper as it was run, and each step from there to ours.

The runs behind the explained table of README.md and docs/paper.md, every row measured here
(:mod:`generator.paper_explained` formats them; ``examples/paper_explained.py`` is the script):

* the ``paper-as-run`` preset (the published run's quirks, each its own switch) with FZN, REF, NL
  beside the paper's Table 5, in both RMSE conventions;
* its quirks removed one at a time, *cumulatively*, in the order of :data:`QUIRKS` — the last
  removal lands exactly on the ``paper`` preset (checked by :func:`walk_rows`);
* the ablation beyond the paper up to the default (the rows of ``examples/paper_ablation.py``);
* a sensitivity study of the start-up transient to the steering row of the gains (not a preset:
  the published gains are unknown);
* the points of the feasibility LMI a solver could have returned (:func:`design_points`) and the
  counterfactuals that test the speed-headroom explanation of x and of NL's divergence
  (:func:`headroom_counterfactuals`): studies, not presets.

Every row is a REF run of the paper window unless said otherwise. No matplotlib here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import Any

import numpy as np

from tsmpc.config import Config, replace
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.log import RunLog
from tsmpc.sim.metrics import compute_metrics, tracking_errors
from tsmpc.sim.simulator import Method, Scenario, simulate

__all__ = [
    "QUIRKS",
    "DesignPoint",
    "ExplainedRow",
    "Quirk",
    "RowResult",
    "SpeedHeadroom",
    "Stretch",
    "Transient",
    "ablation_rows",
    "design_points",
    "divergence_onset",
    "gain_sensitivity",
    "headroom_counterfactuals",
    "longitudinal_stretch",
    "measure",
    "run_row",
    "speed_headroom",
    "startup_transient",
    "steady_straight",
    "walk_rows",
]


@dataclass(frozen=True)
class Quirk:
    """One condition of the published run and how to remove it.

    Attributes:
        name: short label ("steering bias 30°").
        switch: the config field(s) and their values, as-run → paper ("lqr.steering_bias_rad
            0.5236 → 0").
        remove: the config with this quirk removed (the others untouched).
    """

    name: str
    switch: str
    remove: Callable[[Config], Config]


def _lqr(**kw: Any) -> Callable[[Config], Config]:
    return lambda c: replace(c, lqr=replace(c.lqr, **kw))


def _paper_value(section: str, field: str) -> Any:
    return getattr(getattr(Config.preset("paper"), section), field)


#: The published run's quirks in the order the walk removes them (the published run). The order keeps every
#: intermediate configuration valid: the as-run law's own switches go before the law, the 1 ms
#: inner rate before the design formulation (ours does not certify at 1 ms), the 101-step time
#: base before the 1 ms rate, the feasible point before the formulation it belongs to.
QUIRKS: tuple[Quirk, ...] = (
    Quirk("initial filter states", "lqr.initial_filter_state (4355.15 N, 0.52466 rad) → bumpless",
          _lqr(initial_filter_state=None)),
    Quirk("steering bias σ = δ + 30°", "lqr.steering_bias_rad 0.5236 → 0",
          _lqr(steering_bias_rad=0.0)),
    Quirk("speed shift +2 m/s in the scheduling", "lqr.scheduling_speed_shift 2 → 0",
          _lqr(scheduling_speed_shift=0.0)),
    Quirk("unclipped memberships", "lqr.extrapolate_memberships true → false",
          _lqr(extrapolate_memberships=False)),
    Quirk("as-run inner law", "lqr.law as-run → static-gain (exact filter, anti-windup)",
          _lqr(law="static-gain")),
    Quirk("no friction compensation", "lqr.friction_compensation false → true (UIO estimate)",
          _lqr(friction_compensation=True)),
    Quirk("nominal μ 0.65 in the models", "vehicle.mu_nominal 0.65 → 0.5",
          lambda c: replace(c, vehicle=replace(c.vehicle, mu_nominal=_paper_value("vehicle",
                                                                                  "mu_nominal")))),
    Quirk("inner law on the true state", "lqr.true_state_feedback true → false (MHE estimate)",
          _lqr(true_state_feedback=False)),
    Quirk("101 inner steps per outer step", "rates.inner_steps_per_outer 101 → T_c/T_d",
          lambda c: replace(c, rates=replace(c.rates, inner_steps_per_outer=None))),
    Quirk("inner loop and MHE at 1 ms", "rates.Td 0.001 → 0.01",
          lambda c: replace(c, rates=replace(c.rates, Td=_paper_value("rates", "Td")))),
    # not a quirk of the published run but our reading of it (its solver's point is unknown)
    Quirk("its analytic centre (our reading of the unknown point)",
          "dynamic_lmi.feasible_point analytic-center → solver (Clarabel's answer)",
          lambda c: replace(c, dynamic_lmi=replace(
              c.dynamic_lmi, feasible_point=_paper_value("dynamic_lmi", "feasible_point")))),
    Quirk("feasibility LMI (8 vertices, Euler)", "dynamic_lmi.formulation feasibility-euler → "
          "guaranteed-cost", lambda c: replace(c, dynamic_lmi=replace(
              c.dynamic_lmi, formulation=_paper_value("dynamic_lmi", "formulation")))),
    Quirk("design interval v ∈ [2, 18] m/s", "dynamic_box.v (2, 18) → (2, 20)",
          lambda c: replace(c, dynamic_box=replace(c.dynamic_box, v=_paper_value("dynamic_box", "v")))),
    Quirk("no sensor noise", "noise.scale 0 → 1",
          lambda c: replace(c, noise=replace(c.noise, scale=_paper_value("noise", "scale")))),
)


@dataclass(frozen=True)
class ExplainedRow:
    """One row of the explained table: a label, the config it runs, what changed from the row
    above, and its kind ("as-run", "walk", "paper", "ablation")."""

    label: str
    config: Config
    what: str
    kind: str
    oracle: bool = False


def _same_run(a: Config, b: Config) -> bool:
    """Equal apart from what only changes the tables (``metrics``)."""
    return a.model_dump(exclude={"metrics"}) == b.model_dump(exclude={"metrics"})


def walk_rows() -> list[ExplainedRow]:
    """``paper-as-run``, then each quirk of :data:`QUIRKS` removed in turn (cumulatively); the last
    row is the ``paper`` preset. Raises AssertionError if the walk does not end on it."""
    cfg = Config.preset("paper-as-run")
    rows = [ExplainedRow("paper-as-run", cfg, "the published run", "as-run")]
    for i, q in enumerate(QUIRKS):
        cfg = q.remove(cfg)
        last = i == len(QUIRKS) - 1
        rows.append(ExplainedRow(f"− {q.name}" + (" (= paper preset)" if last else ""), cfg,
                                 q.switch, "paper" if last else "walk"))
    if not _same_run(cfg, Config.preset("paper")):
        raise AssertionError("removing every quirk does not give the paper preset")
    return rows


def ablation_rows() -> list[ExplainedRow]:
    """The ablation beyond the paper, from the paper preset to the default
    (``examples/paper_ablation.py``)."""
    paper = Config.preset("paper")
    fb = replace(paper, lqr=replace(paper.lqr, speed_feedback=True))
    win = replace(fb, lqr=replace(fb.lqr, friction_estimate="window"))
    low = replace(win, lqr=replace(win.lqr, low_speed_resistance=True))
    return [
        ExplainedRow("+ speed-error feedback", fb, "lqr.speed_feedback false → true", "ablation"),
        ExplainedRow("+ MHE-window friction estimate", win, "lqr.friction_estimate uio → window",
                     "ablation"),
        ExplainedRow("+ low-speed model resistance", low,
                     "lqr.low_speed_resistance false → true", "ablation"),
        ExplainedRow("+ friction step detection", replace(low, lqr=replace(low.lqr, friction_step=True)),
                     "lqr.friction_step false → true", "ablation"),
        ExplainedRow("+ slip-aware outer loop, tangent heading, step-average reference",
                     replace(Config(), fusion=paper.fusion),
                     "mpc.slip_aware, mpc.tangent_heading, mpc.step_average_reference false → true",
                     "ablation"),
        ExplainedRow("+ fusion and adaptation (= default)", Config(), "fusion.* false → true",
                     "ablation"),
    ]


@dataclass(frozen=True)
class Transient:
    """The start-up transient: peaks of |e_y|, |e_θ| and |ω_d − ω| in the first ``window_s``
    seconds (reference time from the first sample) and when they occur."""

    window_s: float
    ey_peak_m: float
    ey_peak_t_s: float
    eth_peak_rad: float
    eth_peak_t_s: float
    omega_err_peak: float  #: [rad/s]
    omega_err_peak_t_s: float


def startup_transient(log: RunLog, window_s: float = 8.0) -> Transient:
    """Peaks of the tracking errors of ``log`` in its first ``window_s`` seconds (signed values
    at the peak of the magnitude)."""
    err = tracking_errors(log)
    t = log.t_outer - (log.t_outer[0] if log.n_outer else 0.0)
    m = t < window_s + 1e-9
    out = []
    for key in ("y", "theta", "omega"):
        e = err[key][m]
        k = int(np.argmax(np.abs(e))) if e.size else 0
        out += [float(e[k]) if e.size else float("nan"), float(t[m][k]) if e.size else float("nan")]
    return Transient(window_s, *out)


@dataclass(frozen=True)
class RowResult:
    """A measured row: its metrics.json entry (``rmse``, ``rmse_paper_run``, ...), the start-up
    transient, and the run log when kept."""

    label: str
    method: str
    what: str
    kind: str
    metrics: dict[str, Any]
    transient: Transient
    max_abs_longitudinal_m: float  #: max |e_x| over the run [m]
    log: RunLog | None = None


def run_row(row: ExplainedRow, reference: Path | Scenario, *, method: Method = Method.REF,
            max_steps: int | None = None, keep_log: bool = False,
            dynamic_design: Any = None) -> RowResult:
    """Run one row (``reference``: the paper-format file, or a scenario already loaded)."""
    sc = reference if isinstance(reference, Scenario) else load_scenario(row.config, reference)
    log = simulate(row.config, method, sc, oracle=row.oracle, max_steps=max_steps,
                   dynamic_design=dynamic_design)
    ex = np.abs(log.errors[:, 0])
    return RowResult(row.label, method.value, row.what, row.kind, compute_metrics(log),
                     startup_transient(log), float(ex.max()) if ex.size else float("nan"),
                     log if keep_log else None)


def measure(reference: Path, rows: Sequence[ExplainedRow], *, methods: Sequence[Method] = (Method.REF,),
            max_steps: int | None = None, keep_logs: bool = False,
            progress: Callable[[str], None] | None = None) -> list[RowResult]:
    """Every row with every method, in order."""
    out = []
    for row in rows:
        for method in methods:
            if progress is not None:
                progress(f"{row.label} [{method.value}]")
            out.append(run_row(row, reference, method=method, max_steps=max_steps,
                               keep_log=keep_logs))
    return out


def gain_sensitivity(reference: Path, factors: Sequence[float] = (1.0, 0.7, 0.5), *,
                     max_steps: int | None = None, keep_logs: bool = False) -> list[RowResult]:
    """``paper-as-run`` (REF) with the ζ entry of the steering row of every vertex gain scaled by
    each factor: a study, not a switch. The published gains are unknown; the δ_f / ζ
    ratio of the steering row sets how much of the 30° bias the yaw-rate integrator must wind out
    (Δζ = b (1 − K_δ,δf) / K_δ,ζ) and so the size of the start-up transient."""
    from tsmpc.synthesis.cache import load_or_design_dynamic

    cfg = Config.preset("paper-as-run")
    dd = load_or_design_dynamic(cfg)
    sc = load_scenario(cfg, reference)
    out = []
    for f in factors:
        K = np.array(dd.K, dtype=float)
        K[:, 1, 5] *= f
        ratio = float(np.mean(K[:, 1, 4] / K[:, 1, 5]))
        row = ExplainedRow(f"ζ gain × {f:g}", cfg, f"steering row δ_f / ζ = {ratio:.2f}", "study")
        out.append(run_row(row, sc, max_steps=max_steps, keep_log=keep_logs,
                           dynamic_design=dc_replace(dd, K=K)))
    return out


@dataclass(frozen=True)
class SpeedHeadroom:
    """Can the as-run law keep up on the fastest stretch without compensation? The law's steady
    force on a straight at the plant speed ``v`` with ``v_ref`` at the MPC's bound, against the
    force the plant needs there (dry asphalt, drag)."""

    v: float  #: plant speed needed at the fastest reference sample [m/s] (v_d,max T_c / (n T_d))
    v_ref_bound: float  #: the MPC's upper bound of v_ref [m/s]
    force_at_bound_N: float  #: the law's steady force with v_ref at the bound [N]
    force_needed_N: float  #: μ_dry M g + drag at v [N]
    gain_N_per_mps: float  #: ∂F/∂v_ref of the law's steady force at v [N/(m/s)]


def steady_straight(law: Any, v: float, v_ref: float) -> tuple[float, float]:
    """(F₁, ζ) at the fixed point of the as-run law's filters on a straight (α = ω = ω_ref = 0,
    δ = 0 so σ₁ = b) at speed ``v`` and reference ``v_ref``: two linear equations in (F₁, ζ)."""
    from tsmpc.control.paper_as_run import as_run_reference_gain

    st = law.settings
    b = st.steering_bias_rad
    K = law.gains((0.0, v + st.scheduling_speed_shift, 0.0))
    r = as_run_reference_gain(law.model5(0.0, v), law.B5, K) @ np.array([v_ref, 0.0])
    M = np.array([[1.0 - K[0, 3], -K[0, 5]], [-K[1, 3], -K[1, 5]]])
    rhs = np.array([r[0] + K[0, 0] * v + K[0, 4] * b, r[1] + K[1, 0] * v - b * (1.0 - K[1, 4])])
    F, zeta = np.linalg.solve(M, rhs)
    return float(F), float(zeta)


def speed_headroom(cfg: Config, design: Any, v_d_max: float, mu_dry: float = 0.9) -> SpeedHeadroom:
    """:class:`SpeedHeadroom` of ``cfg`` (an as-run law config) with ``design``'s gains."""
    from tsmpc.control.paper_as_run import AsRunLQR
    from tsmpc.models.dynamic import DynamicTS

    rates = cfg.rates
    law = AsRunLQR(design.K, DynamicTS(cfg.dynamic_box, cfg.vehicle, rates.Td), cfg.vehicle, cfg.lqr,
                   rates.Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth)
    v = v_d_max * rates.Tc / (rates.inner_per_outer * rates.Td)
    bound = cfg.mpc.u_max[0]
    p = cfg.vehicle
    f = steady_straight(law, v, bound)[0]
    return SpeedHeadroom(v, bound, f, mu_dry * p.mass * p.g + p.drag_factor * v * v,
                         steady_straight(law, v, v + 1.0)[0] - steady_straight(law, v, v)[0])


@dataclass(frozen=True)
class Stretch:
    """Where |e_x| exceeds a threshold after the start-up (reference time), and RMSE_x without it."""

    threshold_m: float
    start_s: float
    end_s: float
    max_abs_m: float
    rmse_x_outside_m: float
    rmse_x_inside_m: float


def longitudinal_stretch(log: RunLog, threshold_m: float = 1.0, after_s: float = 10.0) -> Stretch | None:
    """The span from the first to the last step after ``after_s`` with |e_x| > ``threshold_m``;
    None when there is none."""
    t = log.t_outer - log.t_outer[0]
    ex = log.errors[:, 0]
    idx = np.flatnonzero((np.abs(ex) > threshold_m) & (t > after_s))
    if idx.size == 0:
        return None
    a, b = int(idx[0]), int(idx[-1])
    inside = np.zeros(ex.size, dtype=bool)
    inside[a:b + 1] = True
    rms = lambda e: float(np.sqrt(np.mean(e**2))) if e.size else float("nan")  # noqa: E731
    return Stretch(threshold_m, float(t[a]), float(t[b]), float(np.max(np.abs(ex[inside]))),
                   rms(ex[~inside]), rms(ex[inside]))


def _as_run_design(cfg: Config) -> Any:
    from tsmpc.synthesis.cache import load_or_design_dynamic

    return load_or_design_dynamic(cfg)


@dataclass(frozen=True)
class DesignPoint:
    """A point of the published run's feasibility LMI and what it does in the run.

    Attributes:
        label: which point ("analytic centre", "Clarabel's answer", ...).
        status: the solver's status ("—" for the analytic centre's Newton).
        certified: every recomputed vertex certificate holds (relative margin ≤ −1e-6).
        worst_relative: the largest (least negative) relative certificate margin.
        steering_ratio: mean over the vertices of the steering row's δ_f / ζ entries.
        headroom: :class:`SpeedHeadroom` on the fastest reference sample.
        result: the REF run with these gains (shortened for an uncertified point).
        max_steps: the outer steps the run was limited to (None: the whole reference).
    """

    label: str
    status: str
    certified: bool
    worst_relative: float
    steering_ratio: float
    headroom: SpeedHeadroom
    result: RowResult
    max_steps: int | None = None


def design_points(reference: Path, centre: RowResult | None = None, *,
                  max_steps: int | None = None, uncertified_steps: int = 150) -> list[DesignPoint]:
    """The feasibility LMI's points and their REF runs (``paper-as-run`` otherwise):

    * the analytic centre (the preset's; ``centre``: its run when already measured);
    * Clarabel's answer in the scaled coordinates (``dynamic_lmi.feasible_point = "solver"``);
    * Clarabel on the LMI in physical units as a MATLAB user would pose it
      (:func:`~tsmpc.synthesis.paper_as_run.solve_unscaled`): its certificates fail, so it is
      only run for the first ``uncertified_steps`` outer steps (a study of what the published
      solver may have returned, never a design a run uses).
    """
    from tsmpc.synthesis.paper_as_run import solve_unscaled

    cfg = Config.preset("paper-as-run")
    sc = load_scenario(cfg, reference)
    v_d_max = float(np.max(sc.reference.v))
    out = []

    def point(label: str, c: Config, design: Any, status: str, certs: Any, steps: int | None,
              done: RowResult | None = None) -> DesignPoint:
        K = np.asarray(design.K, dtype=float)
        row = ExplainedRow(label, c, "", "study")
        res = done or run_row(row, sc, max_steps=steps, dynamic_design=design)
        return DesignPoint(label, status, all(x.holds for x in certs),
                           max(x.relative for x in certs), float(np.mean(K[:, 1, 4] / K[:, 1, 5])),
                           speed_headroom(c, design, v_d_max), res, steps)

    dc = _as_run_design(cfg)
    out.append(point("analytic centre (the preset)", cfg, dc, f"Newton, {dc.center_iterations} steps",
                     dc.certificates, max_steps, centre))
    cs = replace(cfg, dynamic_lmi=replace(cfg.dynamic_lmi, feasible_point="solver"))
    ds = _as_run_design(cs)
    out.append(point("Clarabel's answer, scaled coordinates", cs, ds, ds.status, ds.certificates,
                     max_steps))
    K, P, status, certs = solve_unscaled(cfg.dynamic_box, cfg.vehicle, cfg.dynamic_lmi, cfg.rates.Td)
    steps = uncertified_steps if max_steps is None else min(uncertified_steps, max_steps)
    out.append(point("Clarabel's answer, physical units (as posed in MATLAB)", cfg,
                     dc_replace(dc, K=K, P=P, certificates=tuple(certs)), status, certs, steps))
    return out


def headroom_counterfactuals(reference: Path, methods: Sequence[Method] = (Method.FZN, Method.REF,
                                                                           Method.NL), *,
                             v_bound: float = 22.0, speed_factor: float = 2.5,
                             max_steps: int | None = None, keep_logs: bool = False,
                             progress: Callable[[str], None] | None = None) -> list[RowResult]:
    """Two changes of ``paper-as-run`` that each remove the speed shortfall on the fastest
    stretch, with every method: the MPC's upper bound on v_ref raised to ``v_bound`` (a config
    change), and the force row's speed entry of every vertex gain scaled by ``speed_factor`` (a
    study of the unknown gains, like :func:`gain_sensitivity`). If the shortfall explains RMSE_x
    and NL's divergence, both rows bring x into the band and NL completes."""
    cfg = Config.preset("paper-as-run")
    bound = replace(cfg, mpc=replace(cfg.mpc, u_max=(v_bound, cfg.mpc.u_max[1])))
    dd = _as_run_design(cfg)
    K = np.array(dd.K, dtype=float)
    K[:, 0, 0] *= speed_factor
    fast = dc_replace(dd, K=K)
    sc = load_scenario(cfg, reference)
    rows = [(ExplainedRow(f"v_ref bound {v_bound:g} m/s", bound,
                          f"mpc.u_max[0] {cfg.mpc.u_max[0]:g} → {v_bound:g}", "study"), None),
            (ExplainedRow(f"speed gain × {speed_factor:g}", cfg,
                          f"force row's v entry × {speed_factor:g} (gains study)", "study"), fast)]
    out = []
    for row, design in rows:
        for method in methods:
            if progress is not None:
                progress(f"{row.label} [{method.value}]")
            out.append(run_row(row, sc, method=method, max_steps=max_steps, keep_log=keep_logs,
                               dynamic_design=design))
    return out


def divergence_onset(a: RunLog, b: RunLog, threshold_m: float = 0.1) -> tuple[float, float] | None:
    """The first reference time [s] at which the lateral errors of two runs of the same scenario
    differ by more than ``threshold_m``, and |e_x| of ``a`` then; None when they never do."""
    n = min(a.n_outer, b.n_outer)
    d = np.abs(a.errors[:n, 1] - b.errors[:n, 1])
    idx = np.flatnonzero(d > threshold_m)
    if idx.size == 0:
        return None
    k = int(idx[0])
    return float(a.t_outer[k] - a.t_outer[0]), float(abs(a.errors[k, 0]))
