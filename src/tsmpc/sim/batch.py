"""Batched runs (issue 25 item 2): many runs that differ in their seed and plant parameters,
stepped together by one compiled call (:func:`tsmpc.kernels.batch.advance`).

Each run ("lane") is set up exactly as the run engine sets up one run (:mod:`tsmpc.sim.engine`:
a reset :class:`~tsmpc.control.cascade.Cascade`, the plant, the noise drawn beforehand, the
kernel's arrays); the lanes' arrays are stacked along a first axis and the kernel advances all of
them step by step, the MHE window solves and the plant's RK4 blocks of all lanes vectorised. Where
a lane needs a block's Python path (the engine's slow paths) the kernel returns, that lane's
arrays go back to its own objects, the engine's handler runs (``_Run._mpc`` etc.) and the kernel
resumes. Each run's :class:`~tsmpc.sim.log.RunLog` is assembled by the engine's own code.

Results: the MHE window solves are the engine's to the bit. The plant's right-hand side uses
polynomial transcendentals (≤ 2 ulp, see :mod:`tsmpc.kernels.batch`) instead of libm, so states
differ from the engine's by amplified rounding (tests/test_batch.py bounds it);
``exact_plant=True`` integrates each lane with the engine's scalar plant kernel instead, and then
the logs equal the engine's bit for bit.

Runs the batch does not cover — where :func:`tsmpc.sim.engine.applicability` says the engine does
not apply, where the engine's own set-up declines, or a lane whose block raised
(:class:`~tsmpc.sim.engine.EngineFallback`) — are run by :func:`~tsmpc.sim.simulator.simulate`
one by one, so the answer is always complete.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from tsmpc.config import Config, Method, replace
from tsmpc.sim.log import RunLog
from tsmpc.sim.simulator import Scenario

__all__ = ["LAST_BATCH", "simulate_batch", "warmup"]

#: Facts of the last batch in this process (diagnostics, tests, the benchmark): lanes batched,
#: lanes run one by one and why, Python slow paths taken, kernel calls, loop seconds.
LAST_BATCH: dict[str, Any] = {}

#: The engine's arrays that the kernel only reads (never synchronised back from Python) and its
#: logs (copied back once, at the end).
_READ_ONLY = {"noise", "u_drop", "gnss", "frb", "patches", "events", "ref_x", "ref_y", "ref_th",
              "ref_v", "ref_w", "th_tan", "mv", "mw", "Kv", "zlo", "zhi", "bits"}
_LOGS = {"lo", "loi", "lxp", "li", "lstat", "lsat"}
_KERNEL: dict[str, Any] = {}


def _load_kernel() -> Any:
    """tsmpc.kernels.batch (compiled or loaded from numba's cache), None when the compiled kernels
    are unavailable."""
    if "mod" in _KERNEL:
        return _KERNEL["mod"]
    import tsmpc.sim.engine as eng
    from tsmpc import kernels

    mod: Any = None  # the kernel module, once loaded (numba's dispatchers: untyped)
    if eng._load_kernel() is not None:  # the engine and the blocks (and NUMBA_CACHE_DIR) first
        folder = kernels._tree_folder(kernels.numba_cache_dir())
        # its machine code holds the engine's step and the block kernels: stale when one changes
        eng._forget_stale_machine_code(folder, "batch", ("engine", "mpc", "mhe", "lqr", "plant",
                                                         "batch"), "batch.sources-sha256")
        try:
            from tsmpc.kernels import batch as mod
        except Exception as err:  # a broken compiler: every run goes to simulate()
            print(f"tsmpc: batched runs unavailable ({type(err).__name__}: {err})", file=sys.stderr)
            mod = None
    _KERNEL["mod"] = mod
    return mod


def _advance(kb: Any, first: bool, *args: Any) -> int:
    """One call of the batch kernel. The first compiles or loads its machine code, under the
    kernel's compile lock (one process at a time), and raises :class:`_KernelUnavailable` when
    numba cannot (nothing has run yet)."""
    if not first:
        return int(kb.advance(*args))
    from tsmpc import kernels

    try:
        with kernels.compile_lock("batch"):
            if not kernels.in_cache("batch.advance"):
                print("tsmpc: compiling the batched-run kernel (first run only, about a minute)…",
                      file=sys.stderr, flush=True)
            return int(kb.advance(*args))
    except Exception as err:
        raise _KernelUnavailable(err) from err


class _KernelUnavailable(Exception):
    """The batch kernel's first call failed: numba could not load or compile it."""


def _rebuilt(err: BaseException | None) -> Any:
    """After the kernel's first call failed (e.g. a corrupt or truncated cache entry): its cache
    entries deleted and the module imported afresh, once per process, with one line saying so.
    None when that was tried already or nothing could be deleted."""
    from tsmpc import kernels

    if _KERNEL.get("rebuilt"):
        _give_up(err)
        return None
    _KERNEL["rebuilt"] = True
    folder = kernels._tree_folder(kernels.numba_cache_dir())
    try:
        removed = list(folder.glob("batch.*.nb[ic]"))
        for p in removed:
            p.unlink()
    except OSError:
        removed = []
    if not removed:
        _give_up(err)
        return None
    print(f"tsmpc: the batched-run kernel's cache in {folder} could not be loaded "
          f"({type(err).__name__}); compiling it again…", file=sys.stderr, flush=True)
    sys.modules.pop("tsmpc.kernels.batch", None)
    try:
        from tsmpc.kernels import batch as mod
    except Exception as again:
        _give_up(again)
        return None
    _KERNEL["mod"] = mod
    return mod


def _give_up(err: BaseException | None) -> None:
    print(f"tsmpc: batched runs unavailable ({type(err).__name__}: {err}); running them one by "
          "one", file=sys.stderr, flush=True)
    _KERNEL["mod"] = None


class _Lane:
    """One run of the batch: the engine's set-up of it (``_Run``) and what the loop learns."""

    def __init__(self, index: int, cfg: Config, scenario: Scenario, run: Any, K: int) -> None:
        self.index, self.cfg, self.scenario, self.run, self.K = index, cfg, scenario, run, K
        self.ended: str | None = None  # termination decided in Python (a plant error)
        self.fallback: str | None = None  # a block raised: simulate() runs it


def _set_up(index: int, cfg: Config, method: Method, scenario: Scenario, designs: tuple[Any, Any],
            max_steps: int | None, ke: Any) -> _Lane | str:
    """The engine's preparation of one run (as :func:`tsmpc.sim.engine.run` does it, without
    running it), or why the engine would decline it."""
    import tsmpc.sim.engine as eng
    from tsmpc.control.cascade import Cascade
    from tsmpc.sim.start import _start_state, default_plant, tracked_steps

    cascade = Cascade(cfg, method, scenario.reference, kinematic_design=designs[0],
                      dynamic_design=designs[1])
    why = eng._blocks_problem(cascade)
    if why is not None:
        return why
    mhe, lqr, mpc = cascade.mhe, eng._static_lqr(cascade), cascade.mpc
    if mpc._kern is None or mhe._kern is None or not mhe._kargs[-1] or lqr._kern is None:
        return "a block's compiled kernel is off"
    ref, N, Td = cascade.reference, cfg.mpc.N, cfg.rates.Td
    K = tracked_steps(ref, N)
    if K < 1:
        return "the reference is shorter than the horizon"
    K = K if max_steps is None else min(K, int(max_steps))
    plant: Any = default_plant(cfg, scenario)  # a VehiclePlant, or the ActuatedPlant around one
    vp = plant if scenario.actuators is None else plant.plant
    n_sub = round(Td / vp.model.h)
    if vp.model._kern is None or abs(n_sub * vp.model.h - Td) > 1e-9 * max(1.0, Td):
        return "T_d is no whole number of plant steps"
    if cfg.mhe.N > 126:
        return "an MHE window beyond the batch workspace (126 intervals)"
    x0 = _start_state(ref, scenario.initial_error)
    plant.reset(x0)
    cascade.reset(x0)
    why = eng._start_problem(cascade)
    if why is not None:
        return why
    eng._hypot_exact(ke)
    run = eng._Run(cfg, cascade, scenario, plant, K, x0, ke)
    if scenario.actuators is not None and not eng._actuator_data(plant, Td, run.a.fp, run.a.ip):
        return "actuator sub-steps that are no whole number of plant steps"
    return _Lane(index, cfg, scenario, run, K)


def _signature(lane: _Lane) -> tuple[Any, ...]:
    """Lanes with equal signatures stack into one batch (same array shapes and types)."""
    a = lane.run.a
    return tuple((f, getattr(a, f).shape, getattr(a, f).dtype.str) for f in a.__dataclass_fields__)


def simulate_batch(cfg: Config, method: Method | str, scenarios: Scenario | Sequence[Scenario],
                   seeds: Sequence[int] | None = None, *, kinematic_design: Any = None,
                   dynamic_design: Any = None, max_steps: int | None = None,
                   exact_plant: bool = False) -> list[RunLog]:
    """``simulate(replace(cfg, seed=seeds[i]), method, scenarios[i], …)`` for every i, the runs
    the engine applies to stepped together (see the module docstring). ``scenarios``: one
    scenario for all runs or one per run (e.g. differing in ``plant_vehicle``, the plant's
    parameters); ``seeds``: one noise seed per run (None: ``cfg.seed`` for every run). The
    controller (``cfg`` but its seed) and so the designs are shared. ``exact_plant``: integrate
    the plant with the engine's scalar kernel (bit-identical logs, slower). Returns the logs in
    the runs' order."""
    import tsmpc.sim.engine as eng
    from tsmpc.blas import limit_blas_threads
    from tsmpc.sim.simulator import simulate

    limit_blas_threads()
    m = Method.parse(method) if isinstance(method, str) else method
    if isinstance(scenarios, Scenario):
        n = len(seeds) if seeds is not None else 1
        scs = [scenarios] * n
    else:
        scs = list(scenarios)
        n = len(scs)
    if seeds is not None and len(seeds) != n:
        raise ValueError(f"simulate_batch: {len(seeds)} seeds for {n} scenarios")
    cfgs = [cfg] * n if seeds is None else [replace(cfg, seed=int(s)) for s in seeds]
    if kinematic_design is None or dynamic_design is None:
        from tsmpc.synthesis.cache import load_or_design_dynamic, load_or_design_kinematic

        kinematic_design = kinematic_design or load_or_design_kinematic(cfg)
        dynamic_design = dynamic_design or load_or_design_dynamic(cfg)
    designs = (kinematic_design, dynamic_design)
    logs: list[RunLog | None] = [None] * n
    single: dict[int, str] = {}
    groups: dict[tuple[Any, ...], list[_Lane]] = {}
    kb = _load_kernel() if eng.enabled() else None
    ke = eng._load_kernel() if kb is not None else None
    t_setup = time.perf_counter()
    for i in range(n):
        why = "the batch kernel is unavailable" if kb is None else eng.applicability(cfgs[i], m, scs[i])
        lane = why if why is not None else _set_up(i, cfgs[i], m, scs[i], designs, max_steps, ke)
        if isinstance(lane, str):
            single[i] = lane
        else:
            groups.setdefault(_signature(lane), []).append(lane)
    t_setup = time.perf_counter() - t_setup
    LAST_BATCH.clear()
    LAST_BATCH.update(setup_s=t_setup, logs_s=0.0, batched=0, single=dict(single),
                      slow_paths={"mpc": 0, "mhe": 0, "lqr": 0, "plant": 0},
                      calls=0, loop_s=0.0, mhe_lanes=0, plant_lanes=0)
    for lanes in groups.values():
        try:
            group_logs: list[RunLog | None] | None = _run_group(kb, ke, m, lanes, exact_plant)
        except _KernelUnavailable as err:
            kb = _rebuilt(err.__cause__)
            try:
                group_logs = _run_group(kb, ke, m, lanes, exact_plant) if kb is not None else None
            except _KernelUnavailable as again:
                _give_up(again.__cause__)
                group_logs = None
        if group_logs is None:  # these runs (and any later batch) by simulate()
            kb = None
            for lane in lanes:
                single[lane.index] = "the batch kernel is unavailable"
            continue
        for lane, log in zip(lanes, group_logs, strict=True):
            if log is None:
                single[lane.index] = f"fell back: {lane.fallback}"
            logs[lane.index] = log
        LAST_BATCH["batched"] += sum(1 for lane in lanes if lane.fallback is None)
    LAST_BATCH["single"] = dict(single)
    for i in single:
        logs[i] = simulate(cfgs[i], m, scs[i], kinematic_design=designs[0],
                           dynamic_design=designs[1], max_steps=max_steps)
    return [log for log in logs if log is not None]


def _run_group(kb: Any, ke: Any, method: Method, lanes: list[_Lane], exact_plant: bool
               ) -> list[RunLog | None]:
    """Step one group of lanes (equal signatures) to the end; their logs (None: fell back)."""
    import tsmpc.sim.engine as eng

    fields = list(lanes[0].run.a.__dataclass_fields__)
    B = len(lanes)
    st = {}
    for f in fields:
        first = getattr(lanes[0].run.a, f)
        if f in _LOGS:  # zero-filled by the engine; calloc'ed here, pages touched only when written
            st[f] = np.zeros((B, *first.shape), dtype=first.dtype)
        else:
            st[f] = np.empty((B, *first.shape), dtype=first.dtype)
            for j, ln in enumerate(lanes):
                st[f][j] = getattr(ln.run.a, f)
    st["ip"][:, ke.IP_DEFER] = 1  # the plant and the MHE window wait for advance() (kernels.batch)
    n_in = lanes[0].run.n_in
    M = lanes[0].K * n_in
    nw = lanes[0].cfg.mhe.N
    state = np.zeros(B, dtype=np.int64)
    need = np.zeros(B, dtype=np.int64)
    tally = np.zeros(4, dtype=np.int64)
    pw = np.zeros(kb.PW_ROWS * kb.LANES)
    mws = kb.mhe_workspace(nw)
    akey = np.full((B, nw), np.nan)
    asin, acos = np.zeros((B, nw)), np.zeros((B, nw))
    scratch = np.zeros(kb.LANES, dtype=np.int64)
    args = [st[f] for f in fields]
    sync = [f for f in fields if f not in _READ_ONLY and f not in _LOGS]
    slow = LAST_BATCH["slow_paths"]
    t0, tick0 = time.perf_counter(), ke.ticks()
    first = True
    while True:
        LAST_BATCH["calls"] += 1
        waiting = _advance(kb, first, M, exact_plant, state, need, tally, pw, mws, akey, asin, acos,
                           scratch, *args)
        first = False
        if waiting == 0:
            break
        for b in np.flatnonzero(state == kb.NEEDS_PYTHON):
            lane, code = lanes[b], int(need[b])
            r = lane.run
            for f in sync:  # the lane's arrays back to its objects (they share them)
                getattr(r.a, f)[...] = st[f][b]
            try:
                if code == ke.NEED_MPC:
                    slow["mpc"] += 1
                    r._mpc()
                elif code == ke.NEED_MHE:
                    slow["mhe"] += 1
                    r._mhe()
                elif code == ke.NEED_LQR:
                    slow["lqr"] += 1
                    r._lqr()
                elif code == ke.NEED_PLANT:
                    slow["plant"] += 1
                    lane.ended = r._plant()
                elif code == ke.BLINDED:  # the blind stop: the lane is the Python loop's
                    r.blinded()
                else:  # pragma: no cover (a kernel/caller mismatch)
                    raise RuntimeError(f"batched runs: unknown code {code}")
            except eng.EngineFallback as err:
                lane.fallback = str(err)
            for f in sync:
                st[f][b] = getattr(r.a, f)
            state[b] = kb.FINISHED if lane.ended is not None or lane.fallback else kb.READY
    wall, ticks = time.perf_counter() - t0, ke.ticks() - tick0
    LAST_BATCH["loop_s"] += wall
    LAST_BATCH["mhe_lanes"] += int(tally[0])
    LAST_BATCH["plant_lanes"] += int(tally[1])
    ticks_per_s = ticks / wall if wall > 0 and ticks > 0 else 0.0
    if ticks_per_s > 0:
        LAST_BATCH["mhe_s"] = LAST_BATCH.get("mhe_s", 0.0) + float(tally[2]) / ticks_per_s
        LAST_BATCH["plant_s"] = LAST_BATCH.get("plant_s", 0.0) + float(tally[3]) / ticks_per_s
    t_logs = time.perf_counter()
    out: list[RunLog | None] = []
    for j, lane in enumerate(lanes):
        if lane.fallback is not None:
            out.append(None)
            continue
        r = lane.run
        for f in sync:
            getattr(r.a, f)[...] = st[f][j]
        for f in _LOGS:  # the batch's log rows become the lane's logs (views, no copy)
            setattr(r.a, f, st[f][j])
        termination, done, rows, n_calls = _termination(lane, int(need[j]), ke)
        eng._restore_fault(r, n_calls)
        out.append(eng._log(r, method.value, lane.scenario, done, rows, termination, ticks_per_s,
                            wall / B))
    LAST_BATCH["logs_s"] += time.perf_counter() - t_logs
    return out


def _termination(lane: _Lane, code: int, ke: Any) -> tuple[str, int, int, int]:
    """(termination, outer steps done, inner rows logged, sensor samples taken) of a finished
    lane, worded as the engine's loop words them."""
    a, n_in, K = lane.run.a, lane.run.n_in, lane.K
    m = int(a.si[ke.SI_M])
    if lane.ended is not None:  # the plant's error (NEED_PLANT decided in Python)
        return lane.ended, m // n_in + 1, m + 1, m + 1
    if code == ke.DIVERGED:
        return lane.run.diverged(m)
    M = K * n_in
    return "completed", K, M, M


def warmup() -> bool:
    """Compile (or load from numba's cache) the batch kernel's machine code now, by one step of
    one default run on the built-in circuit (``tsmpc warmup``, and a local sweep before its
    workers start). True when batched runs are available."""
    import tsmpc.sim.engine as eng
    from tsmpc.planning.circuit import builtin_circuit

    if not eng.enabled() or _load_kernel() is None:
        return False
    cfg = Config()
    simulate_batch(cfg, Method.REF, Scenario("warmup", builtin_circuit(dt=cfg.rates.Tc)),
                   max_steps=1)
    return LAST_BATCH.get("batched", 0) == 1
