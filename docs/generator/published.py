"""Every result the documentation publishes, produced from real runs: the producers of the
generated blocks of README.md and docs/*.md (:mod:`generator.blocks`) and of the figures in
docs/img. ``python docs/generate.py`` is the one command that runs them all (``--only`` a subset,
``--check`` compares with the published numbers instead of writing).

Each :class:`Producer` is one section of the generator: it runs the runs the text describes
(the same library calls as the documented commands), renders its blocks and, when asked, writes
its figures. Runs are deterministic (fixed seeds), so a fresh run reproduces a published number to
its printed digits; timings are machine-dependent and marked so the drift check skips them.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import Any

import numpy as np

from .blocks import BlockId

__all__ = [
    "PRODUCERS",
    "TIMING_COLUMNS",
    "Context",
    "Produced",
    "Producer",
    "load_average",
    "precise",
    "producer_names",
]

#: Table columns holding timings (machine-dependent): regenerated, never drift-checked.
TIMING_COLUMNS = ("[ms]", "real-time", "wall", "step ÷")
#: Text lines holding timings: regenerated, never drift-checked.
TIMING_LINES = ("load average",)

RMSE_KEYS = ("x", "y", "theta", "v", "omega")
_SYM = {"x": "x", "y": "y", "theta": "θ", "v": "v", "omega": "ω"}


@dataclass
class Context:
    """What producers share: the repository root, the paper's data, where figures go (None: a
    scratch folder), a cache of runs shared by producers of one invocation, and progress."""

    root: Path
    img_dir: Path | None = None
    progress: Callable[[str], None] = lambda _s: None
    quick: bool = False  #: the CI subset: only the rows the drift test re-runs
    max_steps: int | None = None  #: shortened runs (examples under test); never for the docs
    reference: Path | None = None  #: the paper's reference file (default: tsmpc.datasets.resolve)
    cache: dict[str, Any] = field(default_factory=dict)
    #: where the runs of one invocation go; $TSMPC_DOCS_SCRATCH keeps them between invocations (a
    #: sweep there is finished, not run again: its records are reused)
    scratch: Path = field(default_factory=lambda: Path(os.environ["TSMPC_DOCS_SCRATCH"])
                          if os.environ.get("TSMPC_DOCS_SCRATCH")
                          else Path(tempfile.mkdtemp(prefix="tsmpc-docs-")))

    @property
    def paper_reference(self) -> Path:
        """The paper's reference: ``reference``, else where :func:`tsmpc.datasets.resolve` finds it
        ($TSMPC_DATA_DIR, the cache of ``tsmpc data fetch``, ../shared/data of a checkout)."""
        from tsmpc import datasets

        return self.reference or datasets.resolve("paper")

    def track(self, name: str) -> Path:
        """A race track's file (``tsmpc data fetch tracks``)."""
        from tsmpc import datasets

        return datasets.resolve(name)

    @property
    def tracks(self) -> Path:
        """The folder of the race tracks."""
        from tsmpc import datasets

        return datasets.resolve("tracks")

    def figure(self, name: str) -> Path:
        folder = self.img_dir if self.img_dir is not None else self.scratch / "img"
        folder.mkdir(parents=True, exist_ok=True)
        return folder / name

    def memo(self, key: str, fn: Callable[[], Any]) -> Any:
        if key not in self.cache:
            self.cache[key] = fn()
        return self.cache[key]


@dataclass
class Produced:
    """A producer's output: block bodies, figures written, blocks holding only timings (not
    drift-checked) and blocks re-run only in part (the fresh table holds a subset of rows)."""

    blocks: dict[BlockId, str] = field(default_factory=dict)
    figures: list[Path] = field(default_factory=list)
    timing: set[BlockId] = field(default_factory=set)
    partial: set[BlockId] = field(default_factory=set)

    def add(self, producer: str, name: str, body: str, *, timing: bool = False,
            partial: bool = False) -> None:
        b = BlockId(producer, name)
        self.blocks[b] = body
        if timing:
            self.timing.add(b)
        if partial:
            self.partial.add(b)


@dataclass(frozen=True)
class Producer:
    """One section of the generator."""

    name: str
    fn: Callable[[Context], Produced]
    about: str
    ci: bool = False  #: re-run by the drift test in CI


def load_average() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


# -- formatting ------------------------------------------------------------------------------

#: Extra decimals printed by :func:`_d` (the drift check renders fresh numbers more precisely, so
#: a published number is compared with the fresh run's value, not with its rounding).
_EXTRA_DIGITS = [0]


@contextlib.contextmanager
def precise(extra: int = 4) -> Iterator[None]:
    """Within the block, producers print every number with ``extra`` more decimals (for
    :func:`generator.blocks.drift`: the tolerance is then 2 % plus half a unit of the published
    number's last digit, not of both numbers')."""
    old = _EXTRA_DIGITS[0]
    _EXTRA_DIGITS[0] = extra
    try:
        yield
    finally:
        _EXTRA_DIGITS[0] = old


def _d(v: float, d: int) -> str:
    """``v`` with ``d`` decimals (more inside :func:`precise`)."""
    return f"{float(v):.{d + _EXTRA_DIGITS[0]}f}"


def _f(v: float | None, d: int = 3) -> str:
    if v is None or not math.isfinite(float(v)):
        return "—"
    return _d(v, d)


def _rmse_cells(r: dict[str, float]) -> list[str]:
    return [_f(r[k], 4 if k in ("theta", "omega") else 3) for k in RMSE_KEYS]


def _row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    return "\n".join([_row(head), "|" + "---|" * len(head), *(_row(r) for r in rows)]) + "\n"


def _pct(a: float, b: float) -> str:
    """a relative to b, signed percent."""
    return ("+" if a >= b else "") + f"{_d(100.0 * (a / b - 1.0), 0)} %".replace("-", "−") if b else "—"


def _diverged_at(termination: str) -> str:
    return termination.split(" at ")[-1] if " at " in termination else termination


def _ms(x: float) -> str:
    return f"{x:.3g}"


# -- running ---------------------------------------------------------------------------------

def _experiment(ctx: Context, key: str, cfg: Any, methods: Sequence[str], *, out: Path | None = None,
                plots: bool = False, **kw: Any) -> Any:
    """One run through :mod:`tsmpc.sim.experiment` (what ``tsmpc compare`` / ``run`` do),
    memoised by ``key`` within this invocation."""
    from tsmpc.sim import experiment

    def go() -> Any:
        ctx.progress(key)
        if ctx.max_steps is not None:
            kw["duration"] = ctx.max_steps * cfg.rates.Tc
        exp = experiment.prepare(cfg, list(methods), **kw)
        return experiment.run(exp, out, plots=plots)

    return ctx.memo(key, go)


def _simulate(ctx: Context, key: str, cfg: Any, scenario: Any, method: str = "ref", *,
              oracle: bool = False, plant: Any = None) -> Any:
    from tsmpc.sim.simulator import simulate

    def go() -> Any:
        ctx.progress(key)
        return simulate(cfg, method, scenario, oracle=oracle, plant=plant, max_steps=ctx.max_steps)

    return ctx.memo(key, go)


@contextlib.contextmanager
def _timed_child() -> Iterator[dict[str, float]]:
    """Wall and CPU time of the child processes run inside the block."""
    import resource

    r0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    out: dict[str, float] = {}
    yield out
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    out["wall"] = time.perf_counter() - t0
    out["cpu"] = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _cli(ctx: Context, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``tsmpc ARGS`` in a fresh process from the repository root (as a user types it)."""
    e = {**os.environ, **(env or {})}
    src = str(ctx.root / "src")
    e["PYTHONPATH"] = os.pathsep.join([src, e.get("PYTHONPATH", "")])
    res = subprocess.run([sys.executable, "-m", "tsmpc", *args], cwd=ctx.root, env=e,
                         capture_output=True, text=True, timeout=3600)
    if res.returncode not in (0, 1):
        raise RuntimeError(f"tsmpc {' '.join(args)} exited {res.returncode}: {res.stderr[-2000:]}")
    return res


# -- quick start: `tsmpc compare` on the built-in circuit -------------------------------------

def _quickstart_run(ctx: Context) -> tuple[Path, dict[str, float]]:
    def go() -> tuple[Path, dict[str, float]]:
        out = ctx.scratch / "compare"
        ctx.progress("tsmpc compare (built-in circuit, four methods)")
        with _timed_child() as t:
            _cli(ctx, "compare", "--out", str(out))
        t["load"] = load_average()
        return out, t

    return ctx.memo("quickstart", go)


def quickstart(ctx: Context) -> Produced:
    from tsmpc.config import Config, replace
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.metrics import compute_metrics
    from tsmpc.sim.run_dir import load_run

    p = Produced()
    out, t = _quickstart_run(ctx)
    run = load_run(out)
    rows = []
    for name, m in run.metrics["methods"].items():
        rows.append([name, *_rmse_cells(m["rmse"]), _f(m["max_abs_lateral_m"]),
                     _ms(m["mpc_ms"]["median"]), f"{_d(m['realtime_factor'], 0)}×"])
    p.add("quickstart", "table", _table(
        ["approach", "x [m]", "y [m]", "θ [rad]", "v [m/s]", "ω [rad/s]", "max \\|e_y\\| [m]",
         "MPC median [ms]", "real-time factor"], rows))
    p.add("quickstart", "command", f"load average {_d(t['load'], 1)}: the whole command took "
          f"{_d(t['wall'], 1)} s of wall time, {_d(t['cpu'], 1)} s of CPU", timing=True)
    cfg = Config()
    off = replace(cfg, mpc=replace(cfg.mpc, slip_aware=False, tangent_heading=False))
    m_off = compute_metrics(_simulate(ctx, "builtin REF, slip-aware and tangent heading off", off,
                                      load_scenario(off)))
    p.add("quickstart", "without-slip-aware", f"without them REF's RMSE y is "
          f"{_d(m_off['rmse']['y'], 3)} m and its max |e_y| {_d(m_off['max_abs_lateral_m'], 2)} m")
    logs = run.logs
    if "FZN" in logs and "NL" in logs:
        k = min(logs["FZN"].n_outer, logs["NL"].n_outer)
        d = np.abs(logs["FZN"].errors[:k, 1] - logs["NL"].errors[:k, 1])
        i = int(np.argmax(d))
        p.add("quickstart", "differences", f"here FZN's lateral error differs from NL's by at most "
              f"{_d(1000 * d[i], 1)} mm (at t = {_d(logs['NL'].t_outer[i], 0)} s)")
    for stem in ("friction", "differences", "control", "solve_time"):
        dst = ctx.figure(f"compare_{stem}.png")
        shutil.copyfile(out / f"{stem}.png", dst)
        p.figures.append(dst)
    # the friction figure's dip at the ice patch, explained with the run's numbers
    log = logs.get("REF") or next(iter(logs.values()))
    i = int(np.argmin(log.F_fr_true))
    p.add("quickstart", "ice", f"{_d(log.F_fr_true[i] / 1000, 1)} kN at t = {_d(log.t_inner[i], 1)} s "
          f"(μ(road) = {_d(log.mu_road[i], 2)} against the models' μ_o = {run.config.vehicle.mu_nominal:g})")
    return p


def animation(ctx: Context) -> Produced:
    """The README's GIF: REF of the quick-start run (`tsmpc animate RUN --method ref`)."""
    from tsmpc.report.animation import animate_run
    from tsmpc.sim.run_dir import load_run

    p = Produced()
    out, _ = _quickstart_run(ctx)
    run = load_run(out)
    dst = ctx.figure("animation.gif")
    ctx.progress("animation (REF, whole circuit)")
    t0 = time.perf_counter()
    res = animate_run(run.logs["REF"], ctx.scratch / "animation_full.gif", vehicle=run.config.vehicle,
                      road_width=4.0, mp4=False)
    full_s = time.perf_counter() - t0
    # the README shows the fast S-bend, 12 s at 640 × 480 (the full run is 100 MB of GIF)
    short = animate_run(run.logs["REF"], dst, vehicle=run.config.vehicle, road_width=4.0,
                        start_s=58.0, duration_s=12.0, size_px=(640, 480), mp4=False)
    p.figures.append(short.gif)
    w, h = 800, 600
    p.add("animation", "timing", f"({res.frames} frames, {w} × {h}) renders in "
          f"{_d(full_s, 0)} s at load average {_d(load_average(), 1)}", timing=True)
    return p


# -- design time -----------------------------------------------------------------------------

def design_time(ctx: Context) -> Produced:
    from tsmpc.config import Config
    from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

    p = Produced()
    cfg = Config()
    with tempfile.TemporaryDirectory() as tmp:
        ctx.progress("LMI designs from an empty cache")
        t0 = time.perf_counter()
        load_or_design_kinematic(cfg, Path(tmp))
        t1 = time.perf_counter()
        load_or_design_dynamic(cfg, Path(tmp))
        t2 = time.perf_counter()
    p.add("design", "time", f"measured {_d(t2 - t0, 1)} s — kinematic {_d(t1 - t0, 1)} s, dynamic "
          f"{_d(t2 - t1, 1)} s — on 2 cores at load average {_d(load_average(), 1)}", timing=True)
    return p


def terminal_set(ctx: Context) -> Produced:
    """How far the kinematic design's terminal set lands from the paper's S."""
    from tsmpc.config import Config
    from tsmpc.synthesis.cache import load_or_design_kinematic

    p = Produced()
    S = load_or_design_kinematic(Config()).S
    paper = np.array([[0.465, 0, 0], [0, 23.813, 76.596], [0, 76.596, 257.251]])
    nz = paper != 0
    dev = np.abs(S[nz] / paper[nz] - 1.0) * 100.0
    p.add("terminal-set", "deviation", f"{_d(dev.min(), 0)}–{_d(dev.max(), 0)} %")
    return p


# -- the ablation on the paper reference -------------------------------------------------------

def ablation_rows() -> list[tuple[str, Any, bool]]:
    """(label, config, oracle) of each row of the ablation, in order."""
    from tsmpc.config import Config, replace

    paper = Config.preset("paper")
    fb = replace(paper, lqr=replace(paper.lqr, speed_feedback=True))
    win = replace(fb, lqr=replace(fb.lqr, friction_estimate="window"))
    low = replace(win, lqr=replace(win.lqr, low_speed_resistance=True))
    return [
        ("**paper preset**", paper, False),
        ("+ speed-error feedback", fb, False),
        ("+ MHE-window friction estimate", win, False),
        ("+ low-speed model resistance", low, False),
        ("+ friction step detection", replace(low, lqr=replace(low.lqr, friction_step=True)), False),
        ("+ outer-loop mechanisms", replace(Config(), fusion=paper.fusion), False),
        ("+ fusion and adaptation (**= default**)", Config(), False),
        ("oracle (`--oracle`)", Config(), True),
        ("paper preset, compensation off", replace(paper, lqr=replace(paper.lqr,
                                                                      friction_compensation=False)),
         False),
    ]


def _ablation_runs(ctx: Context) -> list[tuple[str, Any, Any]]:
    from tsmpc.sim.compare import load_scenario

    out = []
    for label, cfg, oracle in ablation_rows():
        log = _simulate(ctx, f"paper reference REF: {label}{' oracle' if oracle else ''}", cfg,
                        load_scenario(cfg, ctx.paper_reference), oracle=oracle)
        out.append((label, cfg, log))
    return out


def _dF_std_outside(log: Any, start_s: float, end_s: float) -> float:
    """σ of the force command's increments [N] outside [start_s, end_s] (run time)."""
    dF = np.diff(log.command[:, 0])
    t = np.arange(len(dF)) * log.Td
    return float(np.std(dF[(t < start_s) | (t > end_s)]))


def _launch_error(log: Any, until_s: float = 2.0) -> float:
    """Largest |F̂ − F_fr| [N] of the first ``until_s`` seconds (the launch), after the window's
    first 0.3 s."""
    t = np.arange(len(log.F_fr_hat)) * log.Td
    m = (t >= 0.3) & (t <= until_s)
    return float(np.abs(log.F_fr_hat - log.F_fr_true)[m].max())


def ablation(ctx: Context) -> Produced:
    from tsmpc.sim.metrics import PAPER_TABLE5, compute_metrics

    p = Produced()
    runs = _ablation_runs(ctx)
    ms = []
    rows, effort = [], []
    for label, _cfg, log in runs:
        m = compute_metrics(log)
        ev = log.events
        m["dF_std"] = float(np.std(np.diff(log.command[:, 0])))
        ms.append(m)
        steps = f"{ev['mpc_soft']} / {ev['mpc_fallback']}"
        if log.termination != "completed":
            rows.append([label, f"diverged at {_diverged_at(log.termination)}", "—", "—", "—", "—",
                         _f(m["max_abs_lateral_m"], 2)])
            effort.append([label, steps, "—"])
            continue
        rows.append([label, *_rmse_cells(m["rmse"]), _f(m["max_abs_lateral_m"], 2)])
        effort.append([label, steps, f"{_d(m['dF_std'], 0)}"])
    t5 = PAPER_TABLE5["REF"]
    rows.append(["REF, paper Table 5", *_rmse_cells(t5), "—"])
    # two narrow tables rather than one wide one: each fits a page at 1400 px
    p.add("ablation", "table", _table(["row", "x", "y", "θ", "v", "ω", "max \\|e_y\\| [m]"], rows))
    p.add("ablation", "effort", _table(["row", "soft / fallback MPC steps", "σ(ΔF_xR) [N]"], effort))
    paper, fb, win, low, fstep, mech, dflt, oracle, _off = ms
    ((_, _, log_paper), (_, _, log_fb), (_, _, log_win), (_, _, log_low), (_, _, log_step), _, _, _,
     (_, _, log_off)) = runs

    def ratios(m: dict[str, Any]) -> str:
        return ", ".join(f"{_d(m['rmse'][k] / t5[k], 2)}× ({_SYM[k]})" for k in RMSE_KEYS)

    def err_rms(log: Any, raw: bool) -> float:
        est = log.F_fr_raw if raw else log.F_fr_hat
        return float(np.sqrt(np.mean((est - log.F_fr_true) ** 2)))

    # the paper scenario's ice patch (tsmpc.scenarios.PaperFriction: μ = 0.1 for 70.0–70.1 s), with
    # 0.1 s before it and 0.7 s after its end (one MHE window, 0.3 s, and the speed's recovery)
    ice = (69.9, 70.8)
    status = ("completes the paper run with no soft or fallback MPC step"
              if log_paper.termination == "completed" and not log_paper.events["mpc_soft"]
              and not log_paper.events["mpc_fallback"] else f"ends: {log_paper.termination}")
    k10 = min(round(10.0 / log_off.Tc), log_off.n_outer - 1)
    bullets = [
        f"* **paper preset**: {status}; against the paper's REF row it lands at {ratios(paper)}.",
        f"* **+ speed-error feedback**: RMSE x {_d(paper['rmse']['x'], 3)} → {_d(fb['rmse']['x'], 3)} m "
        f"(÷ {_d(paper['rmse']['x'] / fb['rmse']['x'], 1)}), RMSE v {_d(paper['rmse']['v'], 3)} → "
        f"{_d(fb['rmse']['v'], 3)} m/s (÷ {_d(paper['rmse']['v'] / fb['rmse']['v'], 1)}).",
        f"* **+ MHE-window friction estimate**: RMSE x {_d(fb['rmse']['x'], 4)} → "
        f"{_d(win['rmse']['x'], 4)} m, "
        f"RMSE v {_d(fb['rmse']['v'], 3)} → {_d(win['rmse']['v'], 3)} m/s; σ(ΔF_xR) {_d(fb['dF_std'], 0)} → "
        f"{_d(win['dF_std'], 0)} N; RMS error of the friction estimate {_d(err_rms(log_fb, True), 0)} N "
        f"(one-step formula) → {_d(err_rms(log_win, False), 0)} N (window).",
        f"* **+ low-speed model resistance**: the launch's largest friction-"
        f"estimate error (first 2 s) {_d(_launch_error(log_win), 0)} → {_d(_launch_error(log_low), 0)} N, "
        f"inner saturations {log_win.events['inner_saturated']} → {log_low.events['inner_saturated']}, "
        f"RMSE v {_d(win['rmse']['v'], 3)} → {_d(low['rmse']['v'], 3)} m/s.",
        f"* **+ friction step detection**: {log_step.events['friction_steps']} steps of the friction "
        f"force declared on the paper run (the scenario's own friction changes); RMSE v "
        f"{_d(low['rmse']['v'], 3)} → {_d(fstep['rmse']['v'], 3)} m/s, x {_d(low['rmse']['x'], 4)} → "
        f"{_d(fstep['rmse']['x'], 4)} m; σ(ΔF_xR) {_d(low['dF_std'], 0)} → {_d(fstep['dF_std'], 0)} N, "
        f"from the ice patch the force now follows: outside {_d(ice[0], 1)}–{_d(ice[1], 1)} s "
        f"{_d(_dF_std_outside(log_low, *ice), 0)} → {_d(_dF_std_outside(log_step, *ice), 0)} N.",
        f"* **+ outer-loop mechanisms**: RMSE y {_d(fstep['rmse']['y'], 3)} → "
        f"{_d(mech['rmse']['y'], 3)} m, max \\|e_y\\| {_d(fstep['max_abs_lateral_m'], 2)} → "
        f"{_d(mech['max_abs_lateral_m'], 2)} m, RMSE θ {_d(fstep['rmse']['theta'], 4)} → "
        f"{_d(mech['rmse']['theta'], 4)} rad.",
        f"* **+ fusion and adaptation (= default)**: on the nominal vehicle RMSE x "
        f"{_d(mech['rmse']['x'], 4)} → {_d(dflt['rmse']['x'], 4)} m, y {_d(mech['rmse']['y'], 4)} → "
        f"{_d(dflt['rmse']['y'], 4)} m, v {_d(mech['rmse']['v'], 3)} → {_d(dflt['rmse']['v'], 3)} m/s "
        "(what they are for shows under mismatch and faults: the page *Mismatch, faults and race speeds*).",
        f"* **oracle**: RMSE x {_d(oracle['rmse']['x'], 3)} m against the default's "
        f"{_d(dflt['rmse']['x'], 3)} m.",
        f"* **compensation off**: e_x is {_d(log_off.errors[k10, 0], 1)} m at t = "
        f"{_d(log_off.t_outer[k10] - log_off.t_outer[0], 0)} s; the run "
        + ("completes." if log_off.termination == "completed"
           else f"ends {log_off.termination.split(':')[0]} at {_diverged_at(log_off.termination)}."),
    ]
    p.add("ablation", "reading", "\n".join(bullets) + "\n")
    # the paper preset's speed loop, from the same runs (docs/paper.md)
    def miss(log: Any) -> tuple[float, float, float]:
        v_end = log.state_outer[1:, 3]
        u = log.u_c[:-1, 0]
        vd = log.ref[:-1, 3]
        def rms(a):
            return (float(np.sqrt(np.mean(a ** 2))))
        return rms(v_end - u), rms(u - vd), rms(log.ref[:, 3] - log.state_outer[:, 3])

    a, b, c = miss(log_paper)
    a2, b2, _ = miss(log_fb)
    p.add("ablation", "speed-loop",
          f"On the paper run with the paper preset, v at the end of each T_c misses the command "
          f"held over it by {_d(a, 2)} m/s RMS; the MPC makes up for it by commanding v_ref {_d(b, 2)} m/s "
          f"RMS away from v_d — the outer loop closes the speed loop itself, through an input its "
          f"model takes for the speed — and the car's own v stays within {_d(c, 2)} m/s RMS of v_d at "
          f"the price of RMSE_x {_d(paper['rmse']['x'], 2)} m. With the speed-error feedback the miss "
          f"drops to {_d(a2, 2)} m/s RMS and the command's departure from v_d to {_d(b2, 2)} m/s RMS.")
    return p


def slip_aware(ctx: Context) -> Produced:
    """The two outer-loop mechanisms switched one at a time (docs/design-decisions.md)."""
    from tsmpc.config import Config, replace
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.metrics import compute_metrics

    p = Produced()
    rows = []
    base = Config()
    for sa, th in ((False, False), (True, False), (False, True), (True, True)):
        cfg = replace(base, mpc=replace(base.mpc, slip_aware=sa, tangent_heading=th))
        m = compute_metrics(_simulate(ctx, f"paper reference REF, slip-aware {sa}, tangent {th}", cfg,
                                      load_scenario(cfg, ctx.paper_reference)))
        bold = (lambda s: f"**{s}**") if sa and th else (lambda s: s)
        rows.append(["on" if sa else "off", "on (default)" if sa and th else ("on" if th else "off"),
                     bold(_f(m["rmse"]["y"])), bold(_f(m["max_abs_lateral_m"])),
                     _f(m["rmse"]["theta"], 4)])
    p.add("slip-aware", "table", _table(["slip-aware", "tangent heading", "RMSE y [m]",
                                         "max \\|e_y\\| [m]", "RMSE θ [rad]"], rows))
    return p


def speed_mode(ctx: Context) -> Produced:
    """Speed-mode time constants per vertex of the dynamic design, and the figure."""
    from tsmpc.config import Config
    from tsmpc.control.speed_mode import speed_modes
    from tsmpc.models.dynamic import DynamicTS
    from tsmpc.synthesis.cache import load_or_design_dynamic

    p = Produced()
    cfg = Config()
    dd = load_or_design_dynamic(cfg)
    verts = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td).premise_box.vertices()
    lam, tau = cfg.dynamic_lmi.filter_bandwidth, cfg.lqr.speed_time_constant
    modes = speed_modes(dd.K, verts, cfg.vehicle, lam, tau)
    groups: dict[tuple[float, ...], list[int]] = {}
    for s in modes:
        key = (round(s.design, 2), round(s.reference_scheduled, 2), round(s.static_gain, 2),
               round(s.with_speed_feedback, 2), s.v)
        groups.setdefault(key, []).append(s.vertex)
    rows = []
    for _key, idx in groups.items():
        s = modes[idx[0]]
        poles = ", ".join(f"{t:.2g}" for t in s.design_poles_tau)
        rows.append([f"{', '.join(map(str, idx))}: (±{_d(np.degrees(abs(s.delta)), 0)}°, {s.v:g}, "
                     f"±{abs(s.alpha):g})", f"{_d(s.design, 2)}", f"{_d(s.reference_scheduled, 2)}",
                     f"{_d(s.static_gain, 2)}", f"{_d(s.with_speed_feedback, 2)}", poles])
    p.add("speed-mode", "table", _table(
        ["vertex (δ, v, α)", "design model [s]", "feed-forward at the reference (old) [s]",
         "N̄ at the measured speed (paper preset) [s]", "+ speed-error feedback (default) [s]",
         "design closed-loop poles 1/\\|Re s\\| [s]"], rows))
    def rng(attr):
        return (f"{_d(min(getattr(s, attr) for s in modes), 2)}–"
               f"{_d(max(getattr(s, attr) for s in modes), 2)} s")
    gains = [-k[0, 0] / (1.0 - k[0, 3]) for k in dd.K]
    p.add("speed-mode", "summary",
          f"* design model: {rng('design')}; the LQR's own speed gain through the filter is "
          f"{_d(min(gains), 0)}–{_d(max(gains), 0)} N per m/s (−K_v/(1 − K_F) over the vertices);\n"
          f"* feed-forward at the reference (the old law): {rng('reference_scheduled')};\n"
          f"* static reference gain N̄ at the measured speed (paper preset): {rng('static_gain')};\n"
          f"* + speed-error feedback, τ = {tau:g} s (default): {rng('with_speed_feedback')}.\n")
    dst = ctx.figure("speed_mode.png")
    _speed_mode_figure(cfg, dd, dst)
    p.figures.append(dst)
    return p


def _speed_mode_figure(cfg: Any, dd: Any, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tsmpc.control.speed_mode import speed_modes
    from tsmpc.models.dynamic import DynamicTS

    pb = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td).premise_box
    v = np.linspace(cfg.dynamic_box.v[0], cfg.dynamic_box.v[1], 37)
    z = np.stack([np.zeros_like(v), v, np.zeros_like(v)], axis=-1)
    K = np.tensordot(pb.memberships(z), dd.K, axes=(1, 0))
    modes = speed_modes(K, z, cfg.vehicle, cfg.dynamic_lmi.filter_bandwidth, cfg.lqr.speed_time_constant)
    fig, ax = plt.subplots(figsize=(7, 4))
    for attr, label, style in (
        ("reference_scheduled", "feed-forward scheduled at the reference (exact equilibrium)", "r--"),
        ("design", "LMI design model (rolling resistance as −μ_o g/v · v)", "k:"),
        ("static_gain", "static reference gain N̄ at the measured speed (paper preset)", "b-"),
        ("with_speed_feedback", "+ speed-error feedback, τ = 0.3 s (default)", "g-"),
    ):
        ax.plot(v, [getattr(m, attr) for m in modes], style, label=label)
    ax.set_xlabel("speed v [m/s]")
    ax.set_ylabel("63 % time of a v_ref step [s]")
    ax.set_yscale("log")
    ax.axhline(cfg.rates.Tc, color="0.6", lw=0.8)
    ax.text(v[-1], cfg.rates.Tc * 1.1, "T_c (what the MPC assumes)", ha="right", fontsize=8, color="0.4")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Speed mode of the inner loop (paper's LQR weights, δ = 0)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- the four methods --------------------------------------------------------------------------

def _agreement(metrics: dict[str, Any]) -> float:
    """Largest relative spread of any RMSE column across the methods, in percent."""
    worst = 0.0
    for k in RMSE_KEYS:
        vals = [m["rmse"][k] for m in metrics["methods"].values()]
        worst = max(worst, (max(vals) - min(vals)) / min(vals) * 100.0)
    return worst


def four_methods(ctx: Context) -> Produced:
    from tsmpc.config import Config

    p = Produced()
    res = _experiment(ctx, "paper reference, four methods", Config(), ["fzn", "ref", "iter", "nl"],
                      reference=ctx.paper_reference)
    rows = [[n, *_rmse_cells(m["rmse"]), _ms(m["mpc_ms"]["median"]), f"{_d(m['wall_s'], 1)}"]
            for n, m in res.metrics["methods"].items()]
    p.add("four-methods", "table", _table(["approach", "x", "y", "θ", "v", "ω", "MPC median [ms]",
                                           "run wall [s]"], rows))
    p.add("four-methods", "agreement", f"agree within {max(1, math.ceil(_agreement(res.metrics)))} %")
    p.add("four-methods", "timing", f"measured at load average {_d(load_average(), 1)}", timing=True)
    return p


def offset_start(ctx: Context) -> Produced:
    """`tsmpc compare --reference PAPER --scenario offset_start`: where the methods differ."""
    from tsmpc.config import Config

    p = Produced()
    out = ctx.scratch / "offset_start"
    res = _experiment(ctx, "paper reference, offset_start, four methods", Config(),
                      ["fzn", "ref", "iter", "nl"], reference=ctx.paper_reference,
                      robustness="offset_start", out=None if ctx.quick else out, plots=not ctx.quick)
    ms = res.metrics["methods"]
    rows = []
    for n, m in ms.items():
        clipped = "—" if n == "NL" else str(m["events"]["mpc_scheduling_clipped"])
        rows.append([n, *_rmse_cells(m["rmse"]), _f(m["max_abs_lateral_m"], 2), clipped,
                     _ms(m["mpc_ms"]["median"])])
    p.add("offset-start", "table", _table(
        ["approach", "x", "y", "θ", "v", "ω", "max \\|e_y\\| [m]", "clipped premise samples",
         "MPC median [ms]"], rows))
    nl = ms.get("NL")
    if nl is not None:
        parts = []
        for n, m in ms.items():
            if n == "NL":
                continue
            k = max(RMSE_KEYS, key=lambda key, m=m: abs(m["rmse"][key] / nl["rmse"][key] - 1.0))
            parts.append(f"{n} {_pct(m['rmse'][k], nl['rmse'][k])} in {_SYM[k]}")
        p.add("offset-start", "vs-nl", "the largest difference of each method from NL over the "
              "five RMSE columns: " + ", ".join(parts))
    if not ctx.quick:
        dst = ctx.figure("offset_start_errors.png")
        shutil.copyfile(out / "errors.png", dst)
        p.figures.append(dst)
    return p


# -- CommonRoad ----------------------------------------------------------------------------------

_CR_ROWS = ("CommonRoad ST", "tsmpc plant, same parameters (linear tyres, same servo)",
            "CommonRoad multi-body (`--plant commonroad-mb`)")


def commonroad(ctx: Context) -> Produced:
    """REF on the built-in circuit on CommonRoad's vehicle 2 (`tsmpc run --plant commonroad-st`
    / `commonroad-mb`) and on tsmpc's plant with the same parameters (examples/commonroad_plant.py)."""
    from tsmpc.config import Config, TyreModel, TyreParams
    from tsmpc.sim.compare import load_scenario
    from tsmpc.sim.metrics import compute_metrics
    from tsmpc.vehicle.actuators import Actuators, SteeringServo
    from tsmpc.vehicle.commonroad import commonroad_config

    p = Produced()
    logs: dict[str, Any] = {}
    walls: dict[str, float] = {}
    wanted = _CR_ROWS[:1] if ctx.quick else _CR_ROWS
    for label in wanted:
        if label == _CR_ROWS[1]:
            cfg = commonroad_config(Config(), vehicle_id=2)
            sc = dc_replace(load_scenario(cfg), measured_steering=True, plant_tyre=TyreParams(
                model=TyreModel.LINEAR), actuators=Actuators(SteeringServo(time_constant_s=0.05,
                                                                              rate_limit=0.4)))
            logs[label] = _simulate(ctx, "CommonRoad vehicle 2 on tsmpc's plant", cfg, sc)
        else:
            plant = "commonroad-st" if label == _CR_ROWS[0] else "commonroad-mb"
            res = _experiment(ctx, f"built-in circuit REF on {plant}", Config(), ["ref"], plant=plant,
                              cr_vehicle=2)
            logs[label] = res.logs["REF"]
        walls[label] = logs[label].wall_s
    ms = {k: compute_metrics(v) for k, v in logs.items()}
    rows = [[k, *(_f(m["rmse"][c], 4) for c in RMSE_KEYS), _f(m["max_abs_lateral_m"])]
            for k, m in ms.items()]
    p.add("commonroad", "table", _table(["plant", "x", "y", "θ", "v", "ω", "max abs(e_y) [m]"], rows),
          partial=ctx.quick)
    if ctx.quick:
        return p
    st, own, mb = (ms[k] for k in _CR_ROWS)
    p.add("commonroad", "vs-own", "; ".join(f"{_SYM[k]} {_pct(st['rmse'][k], own['rmse'][k])}"
                                            for k in RMSE_KEYS))
    fails, speeds = [], []
    for log in logs.values():
        bad = log.mhe_status == "failed"
        fails.append(int(bad.sum()))
        if bad.any():
            speeds += [float(log.state[bad, 3].min()), float(log.state[bad, 3].max())]
    p.add("commonroad", "mhe", f"{min(fails)}–{max(fails)} failed steps"
          + (f" (model prediction used) at {_d(min(speeds), 1)}–{_d(max(speeds), 1)} m/s" if speeds else ""))
    sim_s = logs[_CR_ROWS[2]].simulated_s
    p.add("commonroad", "mb-cost", f"costs {_d(walls[_CR_ROWS[2]] / sim_s, 2)} s of computation per "
          f"simulated second (load average {_d(load_average(), 1)})", timing=True)
    p.add("commonroad", "mb-max", f"{_d(mb['max_abs_lateral_m'], 2)} m")
    return p


# -- race tracks, the envelope -----------------------------------------------------------------

TRACKS = ("Hockenheim", "Monza", "Silverstone", "Spa", "Zandvoort")


def _plan(ctx: Context, track: str, *extra: str) -> Path:
    """`tsmpc plan TRACK --out t.csv [extra]` (in this process)."""
    from typer.testing import CliRunner

    from tsmpc.cli import app

    def go() -> Path:
        out = ctx.scratch / "plans" / f"{track}{'_'.join(extra)}.csv"
        out.parent.mkdir(parents=True, exist_ok=True)
        res = CliRunner().invoke(app, ["plan", str(ctx.track(track)), "--out", str(out), *extra])
        if res.exit_code != 0:
            raise RuntimeError(f"tsmpc plan {track} failed: {res.output}")
        return out

    return ctx.memo(f"plan {track} {extra}", go)


def _track_run(ctx: Context, track: str, *, before: bool = False, laps: int = 1,
               plan: Sequence[str] = ()) -> Any:
    from tsmpc.config import Config, replace

    cfg = Config()
    if before:
        cfg = replace(cfg, mpc=replace(cfg.mpc, slip_aware=False, tangent_heading=False))
    key = f"{track} REF{' before' if before else ''}{f' {laps} laps' if laps > 1 else ''} {plan}"
    return _experiment(ctx, key, cfg, ["ref"], reference=_plan(ctx, track, *plan), laps=laps)


def race_tracks(ctx: Context) -> Produced:
    p = Produced()
    rows = []
    for track in (("Zandvoort",) if ctx.quick else TRACKS):
        after = _track_run(ctx, track).metrics["methods"]["REF"]
        before = _track_run(ctx, track, before=True).metrics["methods"]["REF"]
        ev = after["events"]
        rows.append([track, f"{_d(before['max_abs_lateral_m'], 2)} / {_d(before['rmse']['y'], 3)}",
                     f"{_d(after['max_abs_lateral_m'], 2)} / {_d(after['rmse']['y'], 3)}",
                     _f(after["rmse"]["x"]), f"{_d(after['outer_steps'] * 0.1, 0)}",
                     str(ev["mpc_soft"] + ev["mpc_fallback"])])
    p.add("race-tracks", "table", _table(
        ["track", "outer loop of the paper: max \\|e_y\\| / RMSE y [m]", "default", "RMSE x default [m]",
         "lap [s]", "soft + fallback MPC steps"], rows), partial=ctx.quick)
    if ctx.quick:
        return p
    laps = _track_run(ctx, "Zandvoort", laps=3).metrics["methods"]["REF"]
    p.add("race-tracks", "laps", ", ".join(f"{_d(v, 3)}" for v in laps["max_abs_lateral_per_lap_m"])
          + " m")
    return p


def envelope(ctx: Context) -> Produced:
    """Monza beyond the default box (docs/envelope.md)."""
    from tsmpc.config import Config, replace

    p = Produced()
    plan = ("--v-max", "25", "--a-lat", "6")
    fast = _track_run(ctx, "Monza", plan=plan).metrics["methods"]["REF"]
    ev = fast["events"]
    cfg = Config()
    off = replace(cfg, mpc=replace(cfg.mpc, slip_aware=False, tangent_heading=False))
    m_off = _experiment(ctx, "Monza 25 m/s REF, slip-aware off", off, ["ref"],
                        reference=_plan(ctx, "Monza", *plan)).metrics["methods"]["REF"]
    soft = ev["mpc_soft"] + ev["mpc_fallback"]
    p.add("envelope", "fast",
          f"the lap ({_d(fast['outer_steps'] * 0.1, 0)} s) ends {fast['termination']} with max |e_y| "
          f"{_d(fast['max_abs_lateral_m'], 2)} m, RMSE y {_d(fast['rmse']['y'], 3)} m, RMSE v "
          f"{_d(fast['rmse']['v'], 3)} m/s and {'no' if soft == 0 else soft} soft or fallback MPC "
          f"step{'' if soft == 1 else 's'}; with the boxes widened but without the slip-aware loop "
          f"and the tangent heading max |e_y| is {_d(m_off['max_abs_lateral_m'], 2)} m")
    grip = _experiment(ctx, "Monza a_lat 10 REF", Config(), ["ref"],
                       reference=_plan(ctx, "Monza", "--v-max", "25", "--a-lat", "10"))
    g = grip.metrics["methods"]["REF"]
    p.add("envelope", "grip", f"`REF ({g['status']})`: max |e_y| {_d(g['max_abs_lateral_m'], 2)} m, "
          f"RMSE y {_d(g['rmse']['y'], 3)} m")
    return p


def plan_feasibility(ctx: Context) -> Produced:
    """The public tracks planned at 30 m/s and 8 m/s², capped by the plan check and run
    (docs/planning.md); the force limits per kg and a degraded run (docs/configuration.md,
    docs/outputs.md)."""
    from tsmpc.config import Config, PlannerSettings, apply_overrides
    from tsmpc.planning.feasibility import feasible_plan_for
    from tsmpc.planning.planner import plan_path
    from tsmpc.planning.reference import Reference
    from tsmpc.planning.tracks import load_tumftm

    p = Produced()
    rows = []
    plan = ("--v-max", "30", "--a-lat", "8")
    for track in (("Zandvoort",) if ctx.quick else TRACKS):
        raw = plan_path(load_tumftm(ctx.track(track)).centre, PlannerSettings(v_max=30.0, a_lat_max=8.0),
                        closed=True, dt=0.1)
        _, check, _ = feasible_plan_for(Config(), raw)
        capped = Reference.from_csv(_plan(ctx, track, *plan))
        m = _track_run(ctx, track, plan=plan).metrics["methods"]["REF"]
        rows.append([track, f"{check.limit}: {_d(check.demand, 2)} > {_d(check.allowed, 2)} m/s²",
                     f"{_d(raw.duration, 1)} → {_d(capped.duration, 1)}", m["status"],
                     _d(m["max_abs_lateral_m"], 3), _d(m["rmse"]["y"], 3)])
    p.add("plan-feasibility", "tracks", _table(
        ["track", "plan check", "lap [s]: planned → capped", "run", "max \\|e_y\\| [m]", "RMSE y [m]"],
        rows), partial=ctx.quick)
    if ctx.quick:
        return p
    cfg = Config()
    nominal = _experiment(ctx, "builtin REF", cfg, ["ref"]).metrics["methods"]["REF"]
    heavy = _experiment(ctx, "builtin REF mass 1000", apply_overrides(cfg, ["vehicle.mass=1000.0"]),
                        ["ref"]).metrics["methods"]["REF"]
    r0, r1 = nominal["rmse"], heavy["rmse"]
    p.add("plan-feasibility", "mass",
          f"RMSE x {_d(r1['x'], 3)} m, y {_d(r1['y'], 4)} m, max |e_y| "
          f"{_d(heavy['max_abs_lateral_m'], 3)} m, "
          f"{heavy['status']} (683 kg: RMSE x {_d(r0['x'], 3)} m, y {_d(r0['y'], 4)} m)")
    weak = _experiment(ctx, "builtin REF plant mass +45 %, 20 s",
                       apply_overrides(cfg, ["scenario.plant.mass_scale=1.45", "governor.enabled=false"]),
                       ["ref"],
                       duration=20.0).metrics["methods"]["REF"]
    p.add("plan-feasibility", "degraded", f"`{weak.get('degraded', weak['status'])}`")
    return p


# -- the speed governor (docs/configuration.md, [governor]) -----------------------------------

#: μ(road) 0.9 → 0.5 at 30 s on the friction-ellipse tyre whose grip follows the road (issue 36's
#: acceptance case), and a μ 0.3 patch inside a braking zone (a case it does not carry).
_GRIP_ROAD = ["scenario.plant.combined_slip=true", "scenario.plant.grip_scales_with_road=true",
              "scenario.base_mu=0.9"]
_GOVERNOR_CASES = (("μ 0.9 → 0.5 at 30 s", ["scenario.friction=[{at_s = 30.0, mu = 0.5}]"]),
                   ("μ 0.3 for 10 s from 45 s", ["scenario.friction=[{at_s = 45.0, mu = 0.3, "
                                                 "duration_s = 10.0}]"]))
_HEAVY = ["scenario.plant.mass_scale=1.15", "scenario.plant.cornering_front_scale=0.75",
          "scenario.plant.cornering_rear_scale=0.85"]


def governor(ctx: Context) -> Produced:
    """The speed governor on a road that loses grip, with its estimate and with the oracle that
    knows μ(t), on the built-in circuit and the paper reference, nominal car and a heavier car
    with softer tyres (docs/configuration.md)."""
    from tsmpc.config import Config, apply_overrides

    p = Produced()
    rows = []
    for ref_label, ref in (("built-in circuit", None), ("paper reference", ctx.paper_reference)):
        for case, sets in _GOVERNOR_CASES:
            if case.startswith("μ 0.3") and ref is not None:
                continue
            for car, extra in (("nominal", []), ("mass +15 %, C_f −25 %, C_r −15 %", _HEAVY)):
                runs = {}
                for source in ("estimate", "oracle"):
                    cfg = apply_overrides(Config(), [*_GRIP_ROAD, *sets, *extra,
                                                     f'governor.grip_source="{source}"'])
                    runs[source] = _experiment(ctx, f"governor {ref_label} {case} {car} {source}", cfg,
                                               ["ref"], reference=ref).metrics["methods"]["REF"]
                est, orc = runs["estimate"], runs["oracle"]

                def cell(m: dict[str, Any]) -> str:
                    if m["status"] == "diverged":
                        return f"left the road at {_diverged_at(m['termination'])}"
                    return f"{_d(m['max_abs_lateral_m'], 3)} m"
                done = est["status"] != "diverged" and orc["status"] != "diverged"
                ratio = _d(est["max_abs_lateral_m"] / orc["max_abs_lateral_m"], 2) + "×" if done else "—"
                rows.append([ref_label, case, car, cell(est), cell(orc), ratio,
                             str(est["events"].get("governor_actions", 0)),
                             _d(est.get("plan_delay_s", 0.0), 1)])
    p.add("governor", "table", _table(
        ["reference", "road", "car", "max \\|e_y\\| (estimate)", "max \\|e_y\\| (oracle)", "ratio",
         "actions", "behind plan [s]"], rows))
    if not ctx.quick:
        p.add("governor", "class", _governor_class(ctx))
    return p


#: The class the governor is checked on (measured, never tuned on): μ(road) 0.9 → μ at a time, for
#: 5 s or for good, nominal and heavy car, each with the estimate and the oracle governor.
GOVERNOR_CLASS_MU = (0.3, 0.4, 0.5)
GOVERNOR_CLASS_AT_S = (20.0, 40.0, 60.0)
GOVERNOR_CLASS_FOR_S = (5.0, None)


def _governor_class(ctx: Context) -> str:
    """Per reference and μ: how many of the 12 cases (3 times × 2 durations × 2 cars) each governor
    carries (completed, max |e_y| ≤ 0.5 m), and in how many of those both carry the estimate is
    within 1.5× of the oracle."""
    from tsmpc.config import Config, apply_overrides

    rows = []
    for ref_label, ref in (("built-in circuit", None), ("paper reference", ctx.paper_reference)):
        for mu in GOVERNOR_CLASS_MU:
            ok = {"estimate": 0, "oracle": 0}
            both = near = 0
            worst = 0.0
            for at, dur, (car, extra) in itertools.product(
                    GOVERNOR_CLASS_AT_S, GOVERNOR_CLASS_FOR_S, (("nominal", []), ("heavy", _HEAVY))):
                drop = f"at_s = {at}, mu = {mu}" + ("" if dur is None else f", duration_s = {dur}")
                m = {}
                for source in ("estimate", "oracle"):
                    cfg = apply_overrides(Config(), [*_GRIP_ROAD, f"scenario.friction=[{{{drop}}}]", *extra,
                                                     f'governor.grip_source="{source}"'])
                    m[source] = _experiment(ctx, f"governor class {ref_label} {drop} {car} {source}", cfg,
                                            ["ref"], reference=ref).metrics["methods"]["REF"]
                good = {k: v["status"] != "diverged" and v["max_abs_lateral_m"] <= 0.5 for k, v in m.items()}
                for k in ok:
                    ok[k] += good[k]
                if good["estimate"]:
                    worst = max(worst, m["estimate"]["max_abs_lateral_m"])
                if good["estimate"] and good["oracle"]:
                    both += 1
                    near += m["estimate"]["max_abs_lateral_m"] <= 1.5 * m["oracle"]["max_abs_lateral_m"]
            rows.append([ref_label, f"0.9 → {mu}", f"{ok['estimate']} / 12", f"{ok['oracle']} / 12",
                         f"{near} / {both}", f"{_d(worst, 3)} m"])
    return _table(["reference", "μ(road)", "carried (estimate)", "carried (oracle)",
                   "estimate within 1.5× of the oracle", "largest max \\|e_y\\| carried (estimate)"], rows)


# -- recovery (docs/configuration.md, [recovery]) ---------------------------------------------

#: The recovery experiment: seconds of all-NaN samples from the start (one run each), the run's
#: length [s], the road's μ, and the restart's window after the first clean sample [s] (the rest
#: of the run is the settled window).
RECOVERY_NAN_S = (1.0, 5.0)
RECOVERY_T_S = 30.0
RECOVERY_MU = 0.9
RECOVERY_SETTLE_S = 5.0


@dataclass(frozen=True)
class _Restart:
    """One run of the recovery experiment: |e_y| and the nearest reference sample per call, the
    calls during which the reference waited for the car, the MHE-UIO's status at the first
    clean sample and the run's events."""

    ey: Any
    k_path: Any
    catch_up: Any
    status: str
    events: dict[str, int]


def _restart(cfg: Any, ref: Any, nan_s: float) -> _Restart:
    """:class:`~tsmpc.control.cascade.Cascade` in a loop with tsmpc's plant (examples/cascade_loop.py)
    from the reference's first sample (x0: its pose and speed, no slip, no yaw rate), fed all-NaN
    samples before ``nan_s`` and exact ones after, on a road of μ = RECOVERY_MU."""
    from tsmpc.control.cascade import Cascade, Measurement
    from tsmpc.vehicle.plant import VehiclePlant

    x0 = [ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, 0.0]
    cas = Cascade(cfg, "ref", ref, x0=x0)
    car = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    car.reset(x0)
    Td, n = cfg.rates.Td, round(RECOVERY_T_S / cfg.rates.Td)
    i0 = round(nan_s / Td)
    ey, k_path, catch_up = np.empty(n), np.empty(n, dtype=int), np.zeros(n, dtype=bool)
    status = ""
    for i in range(n):
        X, Y, th, v, _, om = car.state
        m = (Measurement((math.nan,) * 3, math.nan, math.nan) if i < i0
             else Measurement((X, Y, th), v, om))
        cmd = cas.step(i * Td, m)
        if i == i0:
            status = str(cmd.estimate.status)
        car.step([cmd.F_xR, cmd.delta], Td, mu_road=RECOVERY_MU)
        # the distance to the path (the nearest sample's lateral error): a recovery moves the
        # reference's timing, not its path
        k = int(np.argmin(np.hypot(ref.x - X, ref.y - Y)))
        ey[i] = abs(-math.sin(ref.theta[k]) * (X - ref.x[k]) + math.cos(ref.theta[k]) * (Y - ref.y[k]))
        k_path[i] = k
        # the cascade's own flag (no public view): the reference time advancing at the car's speed
        catch_up[i] = cas._catch_up
    return _Restart(ey, k_path, catch_up, status, cas.events)


def recovery(ctx: Context) -> Produced:
    """The restart after all-NaN samples from the start ([recovery], docs/configuration.md): the
    lateral error after the first clean sample against the undisturbed run's, the time until the
    reference runs at its own rate again, with and without ``recovery.yaw_rate_bound``; on the
    built-in circuit and the paper reference (2 references x (1 + 2 x 2) runs of 30 s)."""
    from tsmpc.config import Config, replace
    from tsmpc.envelope import fit_envelope
    from tsmpc.sim.compare import load_scenario

    p = Produced()
    cfg0 = Config()
    p.add("recovery", "curvature",
          _d(math.tan(cfg0.lqr.delta_max) / cfg0.vehicle.wheelbase, 2) + " rad/s per m/s")
    out: dict[str, dict[str, Any]] = {}
    for label, path in (("the built-in circuit", None), ("the paper reference", ctx.paper_reference)):
        scenario = load_scenario(cfg0, path)
        cfg = fit_envelope(cfg0, scenario.reference).config  # as `tsmpc run` prepares it
        ref, Td = scenario.reference, cfg.rates.Td
        unbounded = replace(cfg, recovery=replace(cfg.recovery, yaw_rate_bound=False))
        ctx.progress(f"recovery: {label}, undisturbed")
        base = _restart(cfg, ref, 0.0)
        r: dict[str, Any] = {"late": 0.0, "late_base": 0.0, "late_path": 0.0, "first": 0.0,
                             "ratio": 0.0, "resume": [], "status": set(), "blind": [], "recoveries": set(),
                             "all": 0.0, "off_max": 0.0, "off_above_s": 0.0}
        for nan_s in RECOVERY_NAN_S:
            i0, i5 = round(nan_s / Td), round((nan_s + RECOVERY_SETTLE_S) / Td)
            ctx.progress(f"recovery: {label}, {nan_s:g} s of NaN")
            run = _restart(cfg, ref, nan_s)
            late = run.ey[i5:]
            # the undisturbed run over the same time, and over the same stretch of path
            on_path = (base.k_path >= run.k_path[i5:].min()) & (base.k_path <= run.k_path[i5:].max())
            r["late"] = max(r["late"], late.max())
            r["late_base"] = max(r["late_base"], base.ey[i5:].max())
            r["late_path"] = max(r["late_path"], base.ey[on_path].max())
            r["first"] = max(r["first"], run.ey[i0:i5].max())
            r["ratio"] = max(r["ratio"], run.ey[i0:].max() / base.ey[i0:].max())
            r["all"] = max(r["all"], run.ey[i0:].max())
            waiting = np.flatnonzero(run.catch_up)
            r["resume"].append((waiting[-1] + 1 - i0) * Td if waiting.size else 0.0)
            r["status"].add(run.status)
            r["blind"].append(run.events["blind_steps"])
            r["recoveries"].add(run.events["recoveries"])
            ctx.progress(f"recovery: {label}, {nan_s:g} s of NaN, no yaw_rate_bound")
            off = _restart(unbounded, ref, nan_s)
            limit = 1.5 * base.ey[i0:].max()
            above = np.flatnonzero(off.ey[i0:] > limit)
            r["off_max"] = max(r["off_max"], off.ey[i0:].max())
            r["off_above_s"] = max(r["off_above_s"], (above[-1] + 1) * Td if above.size else 0.0)
        out[label] = r

    def resume(r: dict[str, Any]) -> str:
        a, b = min(r["resume"]), max(r["resume"])
        return f"{_d(a, 1)} s" if abs(a - b) < 1e-9 else f"{_d(a, 1)}–{_d(b, 1)} s"

    b, q = out["the built-in circuit"], out["the paper reference"]
    status = " / ".join(f"`{s}`" for s in sorted(b["status"] | q["status"]))
    nan = " or ".join(f"{s:g}" for s in RECOVERY_NAN_S)
    settle = f"{RECOVERY_SETTLE_S:g} s"

    def above(s: float, what: str) -> str:
        return f"was never above 1.5× {what}" if s == 0.0 else f"was above 1.5× {what} for {_d(s, 1)} s"

    undisturbed_max = "the undisturbed run's maximum over the same time"
    text = (
        f"Cascade in a loop with tsmpc's plant, started at the reference's first sample (its pose "
        f"and speed), fed all-NaN samples for the first {nan} s, then exact ones; μ = "
        f"{RECOVERY_MU:g}, {RECOVERY_T_S:g} s; compared with the undisturbed run (exact samples from "
        f"the start); |e_y| the distance to the path (the nearest reference sample's lateral error), "
        f"each figure the worse of the two lengths. The MHE-UIO's status at the first "
        f"clean sample is {status}. From the first clean sample on, max |e_y| is "
        f"{_d(b['ratio'], 2)}× the undisturbed run's over the same time on the built-in circuit and "
        f"{_d(q['ratio'], 2)}× on the paper reference. Over [first clean sample + {settle}, "
        f"{RECOVERY_T_S:g} s] max |e_y| is {_d(b['late'], 5)} m on the built-in circuit (undisturbed: "
        f"{_d(b['late_base'], 5)} m over the same time, {_d(b['late_path'], 5)} m over the same "
        f"stretch of path) and {_d(q['late'], 5)} m on the paper reference ({_d(q['late_base'], 5)} m "
        f"and {_d(q['late_path'], 5)} m); over the first {settle} after the first clean sample "
        f"{_d(b['first'], 5)} m and {_d(q['first'], 5)} m. The reference runs at its own rate again "
        f"{resume(b)} (built-in circuit) and {resume(q)} (paper reference) after the first clean "
        f"sample: the time the car takes from rest to the plan's speed. The blind stop lasted "
        f"{' and '.join(str(n) for n in b['blind'])} calls of {_d(1000 * cfg0.rates.Td, 0)} ms on the "
        f"built-in circuit ({' and '.join(f'{s:g}' for s in RECOVERY_NAN_S)} s of NaN); `recoveries` is "
        f"{'/'.join(str(n) for n in sorted(b['recoveries'] | q['recoveries']))} in every run. "
        f"Without `yaw_rate_bound` the built-in circuit's restart reached {_d(b['off_max'], 4)} m "
        f"from the first clean sample on and "
        f"{above(b['off_above_s'], undisturbed_max)}; on the paper "
        f"reference it reached {_d(q['off_max'], 5)} m (with the bound {_d(q['all'], 5)} m) and "
        f"{above(q['off_above_s'], 'it')}")
    p.add("recovery", "restart", text)
    return p


# -- robustness (docs/sweeps.md) ---------------------------------------------------------------

_SCENARIOS = {
    "nominal": "nominal",
    "ice_patch": "`ice_patch` (30 m of μ = 0.1, tyre grip scaled)",
    "wet_section": "`wet_section` (μ = 0.6 on 40 % of the path)",
    "noise_x10": "`noise_x10`",
    "sensor_dropout": "`sensor_dropout` (0.2 s frozen every 5 s)",
    "nan_bursts": "`nan_bursts` (50 ms of NaN every 7 s)",
    "mass_stiffness_mismatch": "`mass_stiffness_mismatch` (+20 % M, −20 % C)",
    "actuator_lag": "`actuator_lag` (steering servo 50 ms / 0.4 rad/s, force lag 50 ms, applied "
                    "steering measured)",
}


def _sweep_task(ctx: Context, key: str, **params: Any) -> dict[str, Any]:
    """One run as `tsmpc sweep` runs it (a task of a one-point sweep, executed here)."""
    import tomli_w

    from tsmpc.sweep import expand, load_sweep, run_task

    def go() -> dict[str, Any]:
        ctx.progress(key)
        f = ctx.scratch / "sweeps" / f"{abs(hash(key))}.toml"
        f.parent.mkdir(parents=True, exist_ok=True)
        spec = {"name": "docs", "grid": {"method": ["ref"], **{k: [v] for k, v in params.items()}}}
        f.write_text(tomli_w.dumps(spec), encoding="utf-8")
        (task,) = expand(load_sweep(f))
        return run_task(task)

    return ctx.memo(key, go)


def robustness(ctx: Context) -> Produced:
    from tsmpc.sim.compare import load_scenario

    p = Produced()
    rows = []

    def row(label: str, recs: Sequence[dict[str, Any]]) -> list[str]:
        cells = []
        for k in ("x", "y", "v"):
            cells.append(" / ".join(_f(r["metrics"]["rmse"][k]) if r["status"] == "completed" else "—"
                                    for r in recs))
        cells.append(" / ".join(_f(r["metrics"]["max_abs_lateral_m"], 2) if r["status"] == "completed"
                                else "> 5" for r in recs))
        ok = all(r["status"] == "completed" for r in recs)
        return [label, *cells, "yes" if ok else "**no**"]

    for name, label in _SCENARIOS.items():
        rows.append(row(label, [_sweep_task(ctx, f"sweep: builtin {name}", scenario=name)]))
    for track in TRACKS:
        path = str(ctx.track(track))
        rec = _sweep_task(ctx, f"sweep: {track} lap", track=path)
        rows.append(row(f"{track} lap ({_d(rec['metrics']['outer_steps'] * 0.1, 0)} s)", [rec]))
    rows.append(row("sensor noise × 100 (stress)",
                    [_sweep_task(ctx, "sweep: noise x100", noise_scale=100.0)]))
    monza = str(ctx.track("Monza"))
    speed = {}
    for s in (1.2, 1.3):
        recs = [_sweep_task(ctx, f"sweep: builtin speed x{s}", speed_scale=s),
                _sweep_task(ctx, f"sweep: Monza speed x{s}", speed_scale=s, track=monza)]
        speed[s] = recs
        rows.append(row(f"speed × {s:g}, circuit / Monza", recs))
    p.add("robustness", "table", _table(["scenario", "RMSE x [m]", "RMSE y [m]", "RMSE v [m/s]",
                                         "max \\|e_y\\| [m]", "survived"], rows))
    # where the controller stops: the first speed scaling that does not survive
    stops = []
    for s, recs in speed.items():
        if all(r["status"] == "completed" for r in recs):
            continue
        for where, r in zip(("the circuit", "Monza"), recs, strict=True):
            clipped = r["metrics"]["events"]["mpc_scheduling_clipped"]
            end = (f"ends {r['reason']}" if r["status"] != "completed" else "completes")
            stops.append(f"on {where} {clipped} clipped premise samples and the run {end}")
        p.add("robustness", "stops", f"Speed × {s:g}: " + "; ".join(stops) + ".")
        break
    else:
        p.add("robustness", "stops", "Every speed scaling above completes.")
    # actuators: the actuator_lag scenario with other measurement choices
    from tsmpc.config import Config
    from tsmpc.robustness import apply_robustness
    from tsmpc.sim.metrics import compute_metrics
    from tsmpc.vehicle.actuators import Actuators, ForceLag, SteeringServo

    cfg, sc = apply_robustness("actuator_lag", Config(), load_scenario(Config()))
    unmeasured = compute_metrics(_simulate(ctx, "actuator_lag, steering not measured", cfg,
                                           dc_replace(sc, measured_steering=False)))
    force = compute_metrics(_simulate(ctx, "actuator_lag, force measured too", cfg,
                                      dc_replace(sc, measured_force=True)))
    slow = dc_replace(sc, actuators=Actuators(SteeringServo(0.05, 0.4), ForceLag(0.1)))
    log_slow = _simulate(ctx, "actuator_lag, 0.1 s force lag", cfg, slow)
    k40 = min(log_slow.n_outer, int(40.0 / log_slow.Tc))
    v_err = log_slow.ref[:k40, 3] - log_slow.state_outer[:k40, 3]
    sat = float(np.mean(log_slow.saturated[: k40 * round(log_slow.Tc / log_slow.Td)]))
    p.add("robustness", "actuators",
          f"y {_d(unmeasured['rmse']['y'], 3)} m with the steering not measured. Measuring the "
          f"delivered force and giving it to the MHE as well gives RMSE x {_d(force['rmse']['x'], 3)} m, "
          f"v {_d(force['rmse']['v'], 3)} m/s, the inner loop saturated on "
          f"{force['events']['inner_saturated']} steps. With a 0.1 s force lag the first 40 s have "
          f"a v RMSE of {_d(float(np.sqrt(np.mean(v_err ** 2))), 2)} m/s, the inner loop saturated "
          f"{_d(100 * sat, 0)} % of the time ({log_slow.termination})")
    return p


def sweep_example(ctx: Context) -> Produced:
    """`tsmpc sweep examples/sweep.toml`: its figure and how long it takes."""
    p = Produced()
    out = ctx.scratch / "sweep"
    ctx.progress("tsmpc sweep examples/sweep.toml")
    with _timed_child() as t:
        _cli(ctx, "sweep", "examples/sweep.toml", "--out", str(out))
    import pandas as pd

    n = len(pd.read_csv(out / "aggregate.csv"))
    p.add("sweep-example", "count", f"{n} runs")
    p.add("sweep-example", "timing", f"{_d(t['wall'], 0)} s wall on 2 cores at load average "
          f"{_d(load_average(), 1)}, kernels cached", timing=True)
    dst = ctx.figure("sweep_by_scenario.png")
    shutil.copyfile(out / "by_scenario.png", dst)
    p.figures.append(dst)
    return p


# -- Table 5 explained (issue 22's producer) ---------------------------------------------------

def paper_explained(ctx: Context) -> Produced:
    from .paper_explained import generate

    p = Produced()
    rep = generate(ctx.paper_reference, ctx.img_dir if ctx.img_dir is not None else ctx.scratch / "img",
                   progress=ctx.progress)
    for name, body in rep.blocks.items():
        p.add("paper-explained", name, body)
    p.figures += list(rep.figures)
    return p


# -- baselines (issue 26's producers: examples/baseline_table.py, examples/tune_baselines.py) ----

def _example(ctx: Context, name: str) -> Any:
    """An example script as a module (the examples are scripts, not a package)."""
    import importlib.util

    path = ctx.root / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"tsmpc_example_{name}", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses resolve their module's names through sys.modules
    spec.loader.exec_module(mod)
    return mod


def baselines(ctx: Context) -> Produced:
    """Every outer-loop method, the TS-MPC's and the baselines', on five cases (README, baselines.md)."""
    p = Produced()
    ctx.progress("examples/baseline_table.py (6 compares of 8 methods)")
    table = _example(ctx, "baseline_table").baseline_table
    text = table(ctx.scratch / "baselines", max_steps=ctx.max_steps)
    p.add("baselines", "table", text.rstrip("\n"))
    return p


def baseline_tuning(ctx: Context) -> Produced:
    """The search behind the baselines' defaults (docs/baselines.md)."""
    p = Produced()
    ctx.progress("examples/tune_baselines.py (a coordinate search, ≈ 700 runs)")
    p.add("baseline-tuning", "search", _example(ctx, "tune_baselines").tuning_text())
    return p


# -- mismatch, faults and race speeds (issue 21's producers: examples/mismatch_table.py,
# examples/fusion_ablation.py, examples/race_tracks.py) -------------------------------------------

def mismatch(ctx: Context) -> Produced:
    """The mismatch benchmark (examples/mismatch.toml, 135 runs): tables, verdicts, figure."""
    p = Produced()
    ctx.progress("examples/mismatch_table.py (the sweep of examples/mismatch.toml)")
    img = ctx.figure("mismatch.png")
    blocks = _example(ctx, "mismatch_table").mismatch_blocks(ctx.scratch / "mismatch", img=img,
                                                             steps=ctx.max_steps)
    for name, body in blocks.items():
        p.add("mismatch", name, body)
    p.figures.append(img)
    return p


def generalisation(ctx: Context) -> Produced:
    """The generalisation benchmark (issue 35; examples/generalisation.toml and its held-back
    draws, 200 runs): the distribution of the worst-column ratio, the five worst draws of each set."""
    p = Produced()
    ctx.progress("examples/generalisation_table.py (the sweeps of examples/generalisation*.toml)")
    blocks = _example(ctx, "generalisation_table").generalisation_blocks(ctx.scratch / "generalisation",
                                                                         steps=ctx.max_steps)
    for name, body in blocks.items():
        p.add("generalisation", name, body, timing=name == "time")
    return p


def fusion_ablation(ctx: Context) -> Produced:
    """Each fusion switch off in turn under the conditions that motivated it (docs/mismatch.md)."""
    p = Produced()
    ctx.progress("examples/fusion_ablation.py (108 runs)")
    for name, body in _example(ctx, "fusion_ablation").fusion_blocks(ctx.paper_reference,
                                                                      ctx.max_steps).items():
        p.add("fusion-ablation", name, body)
    return p


def mechanisms(ctx: Context) -> Produced:
    """Which default-on mechanisms pay (examples/mechanisms.toml, 1026 runs; docs/mismatch.md)."""
    p = Produced()
    ctx.progress("examples/mechanism_ablation.py (the sweep of examples/mechanisms.toml)")
    for name, body in _example(ctx, "mechanism_ablation").mechanism_blocks(
            ctx.scratch / "mechanisms", workers=2, steps=ctx.max_steps).items():
        p.add("mechanisms", name, body)
    return p


def race_speeds(ctx: Context) -> Produced:
    """The public tracks at 22 and 25 m/s and three S-bends (docs/mismatch.md)."""
    p = Produced()
    ctx.progress("examples/race_tracks.py (13 runs)")
    p.add("race-speeds", "table", _example(ctx, "race_tracks").race_block(ctx.tracks,
                                                                          ctx.max_steps))
    return p


# -- benchmarks (timings) ----------------------------------------------------------------------

def _bench(ctx: Context, name: str, *args: str) -> dict[str, Any]:
    import json

    def go() -> dict[str, Any]:
        ctx.progress(f"benchmarks/{name}.py")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ctx.root / "src"),
                                                            os.environ.get("PYTHONPATH", "")])}
        res = subprocess.run([sys.executable, str(ctx.root / "benchmarks" / f"{name}.py"), "--json",
                              *args], cwd=ctx.root, env=env, capture_output=True, text=True,
                             timeout=3600, check=True)
        return json.loads(res.stdout[res.stdout.index("{"):])

    return ctx.memo(f"bench {name}", go)


def benchmarks(ctx: Context) -> Produced:
    """The timing tables and sentences of README.md and docs/performance.md (never drift-checked)."""
    p = Produced()
    load0 = load_average()
    mpc = _bench(ctx, "mpc_step")
    inner = _bench(ctx, "inner_step")
    plant = _bench(ctx, "plant_step")
    casc = _bench(ctx, "cascade_run", "--methods", "ref,nl")
    step = _bench(ctx, "cascade_step")
    load = 0.5 * (load0 + load_average())
    p.add("benchmarks", "blocks", _render_blocks(mpc, inner, plant, load), timing=True)
    p.add("benchmarks", "run", _render_run(casc), timing=True)
    s = step["results"]
    p.add("benchmarks", "cascade-step", f"measured at load average {_d(step['load_avg_1min'], 1)} on 2 "
          f"cores: median {_d(s['step']['median'], 3)} ms per call, overhead "
          f"{_d(s['overhead']['median'], 4)} ms = {_d(100 * s['overhead_ratio_median'], 0)} %", timing=True)
    # compiling the kernels into an empty cache, then loading them
    with tempfile.TemporaryDirectory() as tmp:
        env = {"NUMBA_CACHE_DIR": tmp}
        ctx.progress("tsmpc warmup (empty kernel cache, then again)")
        with _timed_child() as first:
            _cli(ctx, "warmup", env=env)
        with _timed_child() as again:
            _cli(ctx, "warmup", env=env)
    p.add("benchmarks", "compile", f"{_d(first['wall'], 1)} s wall at load average {_d(load_average(), 1)}; "
          f"a later `tsmpc warmup` process, which only loads them: {_d(again['wall'], 1)} s", timing=True)
    with _timed_child() as cmd:
        _cli(ctx, "compare", "--reference", str(ctx.paper_reference), "--methods", "ref", "--no-plots",
             "--out", str(ctx.scratch / "bench_compare"))
    p.add("benchmarks", "command", f"{_d(cmd['wall'], 1)} s wall ({_d(cmd['cpu'], 1)} s CPU) at load average "
          f"{_d(load_average(), 1)}", timing=True)
    bt = _bench(ctx, "batch_runs", "--python", "0")
    b = bt["batch"]
    p.add("benchmarks", "batch", f"{_d(b['runs_per_s_per_core'], 1)} paper runs per second per core "
          f"batched against {_d(bt['engine']['runs_per_s_per_core'], 1)} one at a time, "
          f"{_d(bt['ratio_batch_over_engine'], 2)}×; largest state difference of a batched run "
          f"{bt['batch_vs_engine_max_state_diff']:.0e} m; load average {_d(bt['load_average'][0], 1)}",
          timing=True)
    p.add("benchmarks", "batch-split", f"Per paper run at B = {bt['B']} the batch's loop takes "
          f"{_d(1e3 * b['loop_s_per_run'], 0)} ms, of which the vectorised plant "
          f"{_d(1e3 * b['plant_s_per_run'], 0)} ms and the window solves "
          f"{_d(1e3 * b['mhe_s_per_run'], 0)} ms "
          f"(the rest: the lanes' own steps — MPC, TS-LQR, the MHE's window bookkeeping, sensors, "
          f"logs); the engine's loop for the run alone: {_d(1e3 * bt['engine']['loop_s_median'], 0)} ms "
          f"(load average {_d(bt['load_average'][0], 1)}).", timing=True)
    sr = _bench(ctx, "sweep_runs", "--baseline")
    p.add("benchmarks", "sweep-runs", f"{_d(sr['batched']['wall_s'], 0)} s wall for "
          f"{sr['batched']['runs']} runs batched, {_d(sr['one_run_per_task']['wall_s'], 0)} s with "
          f"`--batch 1`; load average {_d(sr['load_average'][0], 1)}", timing=True)
    sw = _bench(ctx, "sweep_scaling")
    p.add("benchmarks", "sweep-scaling", f"measured a {_d(sw['speedup_2_over_1'], 2)}× speed-up from 1 to "
          f"2 workers ({sw['runs']} runs, load average {_d(load_average(), 1)})", timing=True)
    return p


def _med(d: dict[str, Any], key: str) -> float:
    return float(d[key]["median"])


def _speedup(a: float, b: float) -> str:
    return f"{_d(b / a, 0)}×" if math.isfinite(b) and a > 0 else "—"


def _render_blocks(mpc: dict[str, Any], inner: dict[str, Any], plant: dict[str, Any], load: float) -> str:
    r, rn = mpc["results"], mpc.get("results_numpy", {})
    def num(d, k):
        return (_med(d, k) if k in d else float("nan"))
    rows = []
    for m in ("FZN", "REF", "ITER"):
        a, b = _med(r, m), num(rn, m)
        rows.append([f"TS-MPC {m}", f"{_d(a, 3)}", _f(b), _speedup(a, b)])
    if "NL" in r:
        nl, ref = _med(r, "NL"), _med(r, "REF")
        extra = f" (numpy REF: {_d(nl / num(rn, 'REF'), 1)}×)" if "REF" in rn else ""
        rows.append(["NL-MPC (IPOPT, warm-started)", f"{_d(nl, 2)}", "—",
                     f"NL/REF {_d(nl / ref, 0)}×{extra}"])
    ir, irn = inner["results"], inner.get("results_numpy", {})
    for key, label, d in (("mhe", "MHE-UIO", 3), ("lqr", "TS-LQR (static reference gain)", 4)):
        a, b = _med(ir, key), num(irn, key)
        rows.append([label, f"{a:.{d}f}", _f(b), _speedup(a, b)])
    blk, blkn = plant["block_10steps_ms"], plant.get("block_10steps_ms_numpy", {})
    kinds = ("pacejka", "linear")
    a = [blk[k] for k in kinds]
    b = [blkn.get(k, float("nan")) for k in kinds]
    rows.append(["plant block, 10 RK4 steps (Pacejka / linear)", " / ".join(f"{_d(x, 4)}" for x in a),
                 " / ".join(_f(x) for x in b),
                 " / ".join(_speedup(x, y) for x, y in zip(a, b, strict=True))])
    return (f"Measured at load average {_d(load, 1)} on the 2-core machine shared with other jobs "
            "(`mpc_step.py`, `inner_step.py`, `plant_step.py`; the NL/REF ratio is measured in the "
            "same run; the paper reports 40–50×):\n\n"
            + _table(["block (median, ms)", "compiled", "numpy", "speed-up"], rows))


def _render_run(casc: dict[str, Any]) -> str:
    ref = casc["results"]["REF"]
    nump = casc.get("results_numpy", {}).get("REF")
    eng = casc.get("results_engine", {}).get("REF")
    ms = ref["ms"]
    part = ", ".join(f"{label} {_d(ms[k]['median'], 4)} / {_d(ms[k]['p99'], 4)}"
                     for k, label in (("mpc", "MPC"), ("mhe", "MHE"), ("lqr", "TS-LQR"),
                                      ("plant_block", "plant block")))
    nl = casc["results"].get("NL")
    engine = ""
    if eng and eng.get("applies"):
        same = eng.get("vs_python", {})
        engine = (f"REF's loop in the compiled run engine takes {_d(eng['loop_s'], 3)} s wall "
                  f"({_d(eng['realtime_factor'], 0)}× real time; median of {len(eng['loop_s_runs'])} "
                  f"runs), its log equal to the Python loop's (largest state difference "
                  f"{same.get('max_abs_state_diff', float('nan')):.1g}, events "
                  f"{'equal' if same.get('events_equal') else 'DIFFERENT'}); ")
    return (f"Whole paper run ({_d(ref['simulated_s'], 1)} s simulated, `cascade_run.py`): {engine}"
            f"the Python loop over the compiled blocks takes {_d(ref['loop_s'], 2)} s wall / "
            f"{_d(ref['simulate_cpu_s'], 2)} s CPU ({_d(ref['realtime_factor'], 0)}× real time"
            + (f"; {_d(nump['loop_s'], 1)} s with the numpy blocks" if nump else "")
            + f"); inside that loop (medians / p99, ms) {part}"
            + (f"; NL's loop {_d(nl['loop_s'], 1)} s" if nl else "") + ".")


# -- the registry ------------------------------------------------------------------------------

PRODUCERS: tuple[Producer, ...] = (
    Producer("quickstart", quickstart, "`tsmpc compare` on the built-in circuit: table, figures"),
    Producer("animation", animation, "the README's GIF (REF of the quick-start run)"),
    Producer("design", design_time, "LMI design time from an empty cache (timing)"),
    Producer("terminal-set", terminal_set, "the terminal set against the paper's S"),
    Producer("ablation", ablation, "the paper preset and the ablation on the paper reference", ci=True),
    Producer("slip-aware", slip_aware, "the outer-loop mechanisms one at a time"),
    Producer("speed-mode", speed_mode, "speed-mode time constants per vertex, figure"),
    Producer("four-methods", four_methods, "FZN, REF, ITER, NL on the paper run"),
    Producer("offset-start", offset_start, "where the four methods differ (offset_start)", ci=True),
    Producer("commonroad", commonroad, "CommonRoad's vehicle models against tsmpc's plant", ci=True),
    Producer("race-tracks", race_tracks, "race tracks at the default plan", ci=True),
    Producer("envelope", envelope, "Monza beyond the default box"),
    Producer("plan-feasibility", plan_feasibility, "the tracks at 30 m/s and 8 m/s² capped; force "
             "limits per kg; a degraded run (7 runs)"),
    Producer("governor", governor, "the speed governor on a road that loses grip (156 runs, ≈ 1–3 min)"),
    Producer("recovery", recovery, "the restart after all-NaN samples ([recovery], 10 Python-loop "
             "runs of 30 s, ≈ 12 s of CPU)"),
    Producer("robustness", robustness, "the robustness scenarios (docs/sweeps.md)"),
    Producer("sweep-example", sweep_example, "the example sweep: figure and time"),
    Producer("paper-explained", paper_explained, "Table 5 explained (≈ 25 runs, 10–15 min)"),
    Producer("mismatch", mismatch, "the mismatch benchmark: 135 runs, 10–20 min"),
    Producer("generalisation", generalisation, "the generalisation benchmark: 100 draws × 2 "
             "controllers, 100 oracle-tuned designs"),
    Producer("fusion-ablation", fusion_ablation, "the fusion switches' ablation (108 runs)"),
    Producer("mechanisms", mechanisms, "which default-on mechanisms pay (1026 runs, ≈ 61 min)"),
    Producer("race-speeds", race_speeds, "the public tracks at 22 and 25 m/s, S-bends"),
    Producer("baselines", baselines, "the baselines against the TS-MPC on five cases (6 compares)"),
    Producer("baseline-tuning", baseline_tuning, "the baselines' tuning search (≈ 700 runs)"),
    Producer("benchmarks", benchmarks, "benchmarks/*.py timing tables (never drift-checked)"),
)


def producer_names() -> list[str]:
    return [p.name for p in PRODUCERS]
