"""The compiled whole-run engine behind :func:`~tsmpc.sim.simulator.simulate` (issue 25, item 1).

``simulate()`` loops in Python: every T_d it calls :meth:`Cascade.step
<tsmpc.control.cascade.Cascade.step>` (MHE-UIO and TS-LQR every call, the TS-MPC every T_c/T_d
calls) and the plant. For the runs it can express as data, :func:`run` does the same in one
compiled call (:func:`tsmpc.kernels.engine.run`): the built-in plant, the TS-MPC (FZN, REF, ITER),
the MHE-UIO in its window form and the TS-LQR with the static reference gain, the sample gates,
dead reckoning and the fusion switches of ``cfg.fusion``, the scenario's friction profile,
sensor faults and actuators (steering servo, force lag). It returns the same
:class:`~tsmpc.sim.log.RunLog`, equal to the Python loop's to the last bit (the tests compare
both; the blocks are the same compiled kernels, the glue is ported with the same operations in
the same order).

What this module does:

* :func:`applicability` — the explicit test, with the reason when the engine does not apply
  (foreign plants, NL-MPC and the baselines, the oracle, the ``paper-as-run`` quirks,
  the paper's UIO form of the MHE, friction profiles or sensor faults it has no data form for);
* the data: the run's sensors set up as the Python loop sets them up
  (:class:`~tsmpc.sensors.SensorRun`: its records and the noise, dropout and GNSS draws of the
  whole run), the friction profile as a small program, the blocks' parameters read from a :class:`Cascade`
  built exactly as ``simulate`` builds it;
* the slow paths: where a block's compiled fast path does not decide a step, the kernel returns
  and this module runs that block's Python path on the same state (the MPC's condensed QP / SOCP,
  the MHE's dense QP, the TS-LQR's numpy law, the plant's error message), then resumes it;
* anything the Python loop would meet as an *exception* (a block raising) is not reproduced: the
  engine gives up and ``simulate`` runs the whole run in Python (:class:`EngineFallback`).

Switch it off with ``simulate(..., engine=False)`` or ``TSMPC_ENGINE=0``.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, InnerLaw, Method, MHEForm
from tsmpc.control._clock import N_CC, N_CK, N_CKP, pack_clock
from tsmpc.control.cascade import _MPC_STATUS_CODE, EVENT_NAMES, STATUS_CODE, Cascade, _Window
from tsmpc.control.fusion_block import N_FB, N_FBP, pack_fusion
from tsmpc.control.gates import N_GBK, N_PO, pack_gate_block
from tsmpc.control.inner_block import N_IBK, pack_inner_block
from tsmpc.control.outer_block import N_GBP, N_OBP, OC_GACT, OC_GSTEPS, pack_govern, pack_outer, scratch_size
from tsmpc.control.stiffness_block import N_SA, SA_A, SA_B, SA_CF, SA_CR, SA_HAS, SA_I
from tsmpc.control.ts_lqr import N_LAW, pack_law
from tsmpc.control.ts_mpc import MPCResult, MPCStatus
from tsmpc.errors import NonFiniteError
from tsmpc.estimation.fusion import N_CP, pack_course
from tsmpc.scenarios import Scenario
from tsmpc.sim.log import RunLog
from tsmpc.sim.record_block import LI_TLQR, LI_TMHE, LO_TMPC, Records, new_records, run_log
from tsmpc.sim.start import _start_state, default_plant, tracked_steps
from tsmpc.vehicle.actuators import ActuatorState
from tsmpc.vehicle.plant import rk4_count

if TYPE_CHECKING:
    from tsmpc.control.ts_lqr import TSLQR

__all__ = ["LAST_RUN", "EngineFallback", "applicability", "cached", "enabled", "exact", "run", "warmup"]

#: Event names in the order of :attr:`Cascade.events` (the kernel's counters: kernels/engine.py's
#: EVENT_SLOTS, in this order).
_EVENTS = (*EVENT_NAMES, "stale_rejected", "step_errors", "repeated_rejected", "friction_steps")
assert len(_EVENTS) == 19
_MHE_CODE = STATUS_CODE  # the estimator's status as the kernel's code (the cascade's, one table)
_MPC_CODE = _MPC_STATUS_CODE  # the plan's status as the kernel's code (the cascade's, one table)
#: Outer steps per kernel call when a progress callback is given.
_PROGRESS_CHUNK = 50


class EngineFallback(RuntimeError):
    """The run met a case the engine does not reproduce (a block raised); run it in Python."""


def enabled() -> bool:
    """False when ``TSMPC_ENGINE`` is set to a false value (0, false, no, off)."""
    return os.environ.get("TSMPC_ENGINE", "").strip().lower() not in ("0", "false", "no", "off")


# ------------------------------------------------------------------------------ applicability
def applicability(cfg: Config, method: Method | str, scenario: Scenario, *, oracle: bool = False,
                  plant: Any = None) -> str | None:
    """None when the engine runs ``simulate(cfg, method, scenario, oracle=…, plant=…)``; else
    why not (one line)."""
    from tsmpc import kernels
    from tsmpc.sensors import fault_problem

    if not kernels.enabled():
        return "the compiled kernels are off (TSMPC_NO_JIT)"
    if plant is not None:
        return "a plant object was given (the engine integrates tsmpc's own plant)"
    m = Method.parse(method) if isinstance(method, str) else method
    if not m.is_ts_mpc:
        return f"method {m.value}: the engine runs the TS-MPC (FZN, REF, ITER)"
    if oracle or cfg.lqr.oracle:
        return "the oracle ablation (the inner loop on the true state)"
    if cfg.lqr.true_state_feedback or cfg.lqr.law != InnerLaw.STATIC_GAIN:
        return "the published run's inner law (lqr.law / lqr.true_state_feedback)"
    if cfg.mhe.form != MHEForm.WINDOW:
        return f"mhe.form = {cfg.mhe.form.value!r} (the engine runs the window form)"
    if cfg.rates.inner_steps_per_outer is not None:
        return "rates.inner_steps_per_outer (the published run's time base)"
    why = _actuator_problem(scenario.actuators)
    if why is not None:
        return why
    if _friction_program(scenario.friction) is None:
        return f"friction profile {type(scenario.friction).__name__} (no data form)"
    why = fault_problem(scenario.sensor_fault)
    if why is not None:
        return why
    why = _blinding_fault(cfg, scenario.sensor_fault)
    if why is not None:
        return why
    why = _changed_since_port()
    if why is not None:
        return why
    return _replaced_code()


# ------------------------------------------------------------------------------ what was ported
#: The Python code the kernel reproduces, with the fingerprints of the versions it was ported from
#: (:func:`fingerprint`: the AST without docstrings and comments). When one changes, the engine
#: steps aside (the Python loop runs) until kernels/engine.py follows the change and this table is
#: refreshed (``python -m tsmpc.sim.engine`` prints it; tests/test_engine.py checks it).
_PORTED: dict[str, str] = {
    "tsmpc.sim.simulator:simulate": "ba020e97f0f11213",
    "tsmpc.sim.simulator:_measurement": "fe7e40fc59dbb6d6",
    "tsmpc.control.cascade:Cascade.step": "153443d2b249fd93",
    "tsmpc.control.cascade:Cascade._step": "e0337c96ff327101",
    "tsmpc.control.ts_mpc:TSMPC.step": "d89ccd1d7f4bcc57",
}


def fingerprint(target: str) -> str:
    """Fingerprint of ``"module:qualname"`` (a function, method or class): a hash of its syntax
    tree without docstrings, so comments and documentation may change, code may not."""
    import ast
    import hashlib
    import importlib
    import inspect
    import textwrap

    mod_name, qual = target.split(":")
    obj: Any = importlib.import_module(mod_name)
    for part in qual.split("."):
        obj = getattr(obj, part)
    tree = ast.parse(textwrap.dedent(inspect.getsource(obj)))
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return hashlib.sha256(ast.dump(tree).encode()).hexdigest()[:16]


def stale_ports() -> list[str]:
    """The ported code that changed since the port (targets whose fingerprint differs), empty when
    the engine reproduces the current code."""
    return [t for t, fp in _PORTED.items() if fingerprint(t) != fp]


def _changed_since_port() -> str | None:
    if "stale" not in _PROBES:
        _PROBES["stale"] = stale_ports()
    stale = _PROBES["stale"]
    if stale:
        return (f"{', '.join(stale)} changed since the engine was ported (the Python loop runs; "
                "tests/test_engine.py says what to do)")
    return None


#: Classes whose methods the engine reproduces (a method replaced on one of them — a test's
#: recorder, a user's instrumentation — only acts in the Python loop).
_PORTED_CLASSES = (
    ("tsmpc.control.cascade", "Cascade"), ("tsmpc.control.ts_mpc", "TSMPC"),
    ("tsmpc.estimation.mhe_uio", "MHEUIO"), ("tsmpc.control.ts_lqr", "TSLQR"),
    ("tsmpc.vehicle.plant", "VehiclePlant"), ("tsmpc.vehicle.plant", "Plant"),
    ("tsmpc.sensors", "SensorRun"), ("tsmpc.scenarios", "PaperFriction"),
    ("tsmpc.scenarios", "PatchFriction"), ("tsmpc.scenarios", "ConstantFriction"),
    ("tsmpc.estimation.fusion", "Fusion"), ("tsmpc.estimation.fusion", "CourseFusion"),
    ("tsmpc.scenarios", "EventFriction"), ("tsmpc.scenarios", "ResolvedEvent"),
    ("tsmpc.vehicle.actuators", "ActuatedPlant"), ("tsmpc.vehicle.actuators", "Actuators"),
)
#: Module-level functions the loop calls by name (module, name, where it is defined).
_PORTED_FUNCTIONS = (
    ("tsmpc.sim.simulator", "default_plant", "tsmpc.sim.start"),
    ("tsmpc.sim.simulator", "_start_state", "tsmpc.sim.start"),
    ("tsmpc.sim.simulator", "_measurement", "tsmpc.sim.simulator"),
    ("tsmpc.sim.simulator", "SensorRun", "tsmpc.sensors"),
    ("tsmpc.sim.simulator", "tracked_steps", "tsmpc.sim.start"),
    *(("tsmpc.sim.simulator", name, "tsmpc.sim.record_block") for name in (
        "logged_reference", "new_records", "off_road", "record_inner", "record_outer", "record_plan",
        "run_log", "travelled")),
)


def _replaced_code() -> str | None:
    """Why not, when a method or function the engine reproduces was replaced at run time (its
    ``__qualname__`` or ``__module__`` is not its definition's), or a block kernel the engine
    calls is no longer the one its module exports; else None."""
    import importlib

    for mod_name, cls_name in _PORTED_CLASSES:
        cls = getattr(importlib.import_module(mod_name), cls_name)
        for name, attr in vars(cls).items():
            fn = getattr(attr, "__func__", attr)  # static/class methods
            if callable(fn) and hasattr(fn, "__qualname__") and not (
                    fn.__qualname__ == f"{cls.__qualname__}.{name}" and fn.__module__ == mod_name):
                return f"{cls_name}.{name} was replaced (the Python loop runs the replacement)"
    for mod_name, name, home in _PORTED_FUNCTIONS:
        fn = getattr(importlib.import_module(mod_name), name, None)
        if getattr(fn, "__qualname__", None) != name or getattr(fn, "__module__", None) != home:
            return f"{mod_name}.{name} was replaced (the Python loop runs the replacement)"
    if "mod" in _KERNEL and _KERNEL["mod"] is not None:
        ke = _KERNEL["mod"]
        for block, fn in (("mpc", "guarded_step"), ("plant", "rk4_block")):
            if getattr(importlib.import_module(f"tsmpc.kernels.{block}"), fn) is not getattr(ke, fn):
                return f"tsmpc.kernels.{block}.{fn} was replaced"
        cas = importlib.import_module("tsmpc.control.cascade")
        mb = importlib.import_module("tsmpc.control.mhe_block")  # the MHE block calls the window kernel
        mid = importlib.import_module("tsmpc.control._mid")  # the plan's bookkeeping, the MHE phase
        if (mb.mhe_block is not mid.mhe_block
                or mb.mhe_step is not importlib.import_module("tsmpc.kernels.mhe").mhe_step):
            return "tsmpc.control.mhe_block's block or its kernel was replaced"
        if (ke.cascade_after_plan, ke.cascade_estimate) != (mid.cascade_after_plan, mid.cascade_estimate) or (
                cas.cascade_after_plan is not mid.cascade_after_plan):
            return "tsmpc.control._mid's phase was replaced"
        ts_lqr = importlib.import_module("tsmpc.control.ts_lqr")  # its block calls the law
        if importlib.import_module("tsmpc.kernels.lqr").lqr_step is not ts_lqr.lqr_step:
            return "tsmpc.kernels.lqr.lqr_step was replaced"
        if ts_lqr.inner_step is not importlib.import_module("tsmpc.control.inner_block").inner_step:
            return "tsmpc.control.ts_lqr.inner_step was replaced"
        if importlib.import_module("tsmpc.control.inner_block").inner_block is not importlib.import_module(
                "tsmpc.control._back").inner_block:
            return "tsmpc.control.inner_block.inner_block was replaced"
        ck = importlib.import_module("tsmpc.control._clock")  # the cascade's time
        if (ke.cascade_clock is not ck.cascade_clock or cas.cascade_clock is not ck.cascade_clock
                or cas.cascade_sample is not ck.cascade_sample):
            return "tsmpc.control._clock's phase was replaced"
        fr = importlib.import_module("tsmpc.control._front")  # the phases before the outer loop and the solve
        if (fr.cascade_front, fr.cascade_outer) != (ke.cascade_front, ke.cascade_outer) or (
                cas.cascade_front, cas.cascade_outer) != (fr.cascade_front, fr.cascade_outer) or (
                fr.before_at is not importlib.import_module("tsmpc.control.fusion_block").before_at):
            return "tsmpc.control._front's phase was replaced"
        if (fr.cascade_sample, fr.cascade_time, mid.plan_taken) != (ck.cascade_sample, ck.cascade_time,
                                                                    ck.plan_taken):
            return "tsmpc.control._clock's phase was replaced"
        if importlib.import_module("tsmpc.control.stiffness_block").stiffness_block is not fr.stiffness_block:
            return "tsmpc.control.stiffness_block's block was replaced"
        bk = importlib.import_module("tsmpc.control._back")  # the phase after the MHE
        parts = (bk.back_start, bk.cascade_back, bk.cascade_command)
        if (ke.cascade_back, ke.cascade_command) != parts[1:] or (
                cas.back_start, cas.cascade_back, cas.cascade_command) != parts:
            return "tsmpc.control._back's phase was replaced"
        if importlib.import_module("tsmpc.control.gates").gate_block is not fr.gate_block:  # the gates' glue
            return "tsmpc.control.gates' block was replaced"
        ob = importlib.import_module("tsmpc.control.outer_block")
        if ob.outer_errors is not fr.outer_errors or ob.outer_after is not mid.outer_after:
            return "tsmpc.control.outer_block's block was replaced"
        rb = importlib.import_module("tsmpc.sim.record_block")  # the recorder's and the sensors' blocks
        if any(getattr(rb, f) is not getattr(ke, f) for f in (
                "logged_reference", "off_road", "record_inner", "record_outer", "record_plan", "travelled")):
            return "tsmpc.sim.record_block's block was replaced"
        if importlib.import_module("tsmpc.sensors").sensor_step is not ke.sensor_step:
            return "tsmpc.sensors.sensor_step was replaced"
    return None


# ------------------------------------------------------------------------------ scenario as data
def _friction_program(profile: Any) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                             NDArray[np.float64]] | None:
    """(base program, patches, events) of a friction profile (see ``friction_mu``), None when the
    profile has no data form (a user-defined class)."""
    from tsmpc.scenarios import ConstantFriction, EventFriction, PaperFriction, PatchFriction

    events = np.zeros((0, 5))
    base = profile
    if type(profile) is EventFriction:
        events = profile.table
        base = profile.base
    patches = np.zeros((0, 4))
    if type(base) is ConstantFriction:
        frb = np.array([0.0, float(base.value)])
    elif type(base) is PaperFriction:
        frb = np.array([1.0, base.dry, base.ripple, base.earth, base.ice, base.wet], dtype=float)
    elif type(base) is PatchFriction:
        frb = np.array([2.0, base.base, base.lap_length_m], dtype=float)
        patches = base.table
    else:
        return None
    return frb, patches, events


def _actuator_problem(act: Any) -> str | None:
    """Why the scenario's actuators have no data form (None: none, or servo and lag as data)."""
    from tsmpc.vehicle.actuators import Actuators, ForceLag, SteeringServo

    if act is None:
        return None
    if type(act) is not Actuators or not (
            act.steering is None or type(act.steering) is SteeringServo) or not (
            act.force is None or type(act.force) is ForceLag):
        return f"actuators {type(act).__name__} (no data form)"
    return None


def _actuator_data(plant: Any, Td: float, fp: NDArray[np.float64], ip: NDArray[np.int64]) -> bool:
    """The ActuatedPlant's gains per sub-step into fp/ip (False: its sub-step is no whole number
    of RK4 steps — the Python loop raises the plant's error)."""
    from tsmpc.kernels import engine as ke

    p = plant.params(Td)  # the ActuatedPlant's law, its record (the kernel rebuilds it from the slots)
    h = Td / p.substeps  # ActuatedPlant.step's sub-step, as it computes it
    ip[ke.IP_ACT], ip[ke.IP_ACT_N] = 1, p.substeps
    fp[ke.FP_A_GF], fp[ke.FP_A_GD] = p.force_gain, p.steer_gain
    fp[ke.FP_A_RMAX], fp[ke.FP_A_DOFF] = p.max_steer_step, p.steering_offset
    h_rk = plant.plant.model.h
    n_rk = rk4_count(h, h_rk)  # VehiclePlant.step's RK4 steps per sub-step
    ip[ke.IP_ACT_NRK] = 0 if n_rk is None else n_rk
    return n_rk is not None


def _blinding_fault(cfg: Config, fault: Any) -> str | None:
    """Why not, when the sensor fault can leave the cascade without a usable speed sample for
    ``recovery.blind_after_s`` (the blind stop and recovery run in the Python loop only): a burst
    that long, or dropouts so frequent that such a run of them is not negligible (p > 0.5)."""
    from tsmpc.sensors import DropoutFault, NaNBurstFault, SensorModel, split_fault

    rc = cfg.recovery
    if fault is None or not rc.enabled:
        return None
    model, inner = split_fault(fault)
    if isinstance(inner, DropoutFault | NaNBurstFault) and \
            inner.duration_s + 2.0 * cfg.rates.Td > rc.blind_after_s:
        return (f"a sensor burst of {inner.duration_s:g} s can blind the cascade "
                "(recovery.blind_after_s; the blind stop runs in the Python loop)")
    if type(model) is SensorModel and model.faults.dropout_probability > 0.5:
        return "dropouts with probability > 0.5 can blind the cascade (the Python loop runs)"
    if type(model) is SensorModel:  # a slow speed or yaw-rate sensor: no sample for that long
        for name, rate in (("v", model.params.rate_v), ("omega", model.params.rate_omega)):
            if cfg.rates.Td / rate + 2.0 * cfg.rates.Td > rc.blind_after_s:
                return (f"scenario.sensors.{name}_rate_hz = {rate / cfg.rates.Td:g} Hz can blind the "
                        "cascade (recovery.blind_after_s; the blind stop runs in the Python loop)")
    return None


def _fault_data(cfg: Config, cascade: Cascade, fault: Any, M: int, fp: NDArray[np.float64],
                sf: NDArray[np.float64]) -> Any:
    """The run's sensors (:class:`~tsmpc.sensors.SensorRun`, as the Python loop sets them up) with
    their records packed into fp's and sf's sensor slots."""
    from tsmpc import sensors
    from tsmpc.kernels import engine as ke

    sr = sensors.SensorRun(cfg.noise, cfg.seed, fault, M, cascade.n_inner, cascade.Tc, cascade.Td)
    p = sr.params
    fp[ke.FP_SENS:ke.FP_SENS + sensors.N_SP] = sensors.pack_params(p.burst, p.model if p.has_model else None)
    sf[ke.SF_SENS:ke.SF_SENS + sensors.N_SS] = sensors.pack_state(sr.burst, None)
    return sr


def _restore_fault(r: _Run, n_calls: int) -> None:
    """Leave the scenario's fault objects as the Python loop would have left them (a comparison
    runs its next method on the same objects): the run's sensor states out of the slots,
    :meth:`~tsmpc.sensors.SensorRun.finish`."""
    from tsmpc import sensors
    from tsmpc.kernels import engine as ke

    sr = r.sensors
    sr.burst, sr.model = sensors.unpack_state(r.a.sf[ke.SF_SENS:ke.SF_SENS + sensors.N_SS], r.a.fifo)
    sr.finish(n_calls)


# ------------------------------------------------------------------------------ exactness probes
_PROBES: dict[str, Any] = {}


def _hypot_exact(ke: Any) -> bool:
    """Does the kernel's hypot reproduce this interpreter's ``math.hypot``?"""
    if "hypot" not in _PROBES:
        rng = np.random.default_rng(20251)
        v = rng.normal(size=(200, 2)) * np.array([[1.0], [1e3]]).repeat(100, axis=0)
        _PROBES["hypot"] = all(ke.hypot_py(float(a), float(b)) == math.hypot(a, b) for a, b in v)
    return bool(_PROBES["hypot"])


def exact() -> bool | None:
    """Whether the last engine run's glue reproduces this interpreter's rounding to the bit (None
    before any run): ``math.hypot`` of CPython ≤ 3.11."""
    if "hypot" not in _PROBES:
        return None
    return bool(_PROBES["hypot"])


# ------------------------------------------------------------------------------ the kernel
_KERNEL: dict[str, Any] = {}
#: Facts of the last engine run in this process: ``slow_paths`` (steps whose MPC, MHE, TS-LQR or
#: plant step the Python path decided), ``loop_s``, ``compile_s`` (diagnostics and tests).
LAST_RUN: dict[str, Any] = {}


def _load_kernel() -> Any:
    """The engine's kernel module (compiled on first use, then loaded from numba's cache), or
    None when the compiled kernels are unavailable."""
    if "mod" in _KERNEL:
        return _KERNEL["mod"]
    from tsmpc import kernels

    mod: Any = None  # the kernel module, once loaded (numba's dispatchers: untyped)
    if kernels.load("mpc") is not None:  # sets NUMBA_CACHE_DIR before numba is imported
        folder = kernels._tree_folder(kernels.numba_cache_dir())
        for attempt in range(2):  # a cache entry numba cannot load: deleted, compiled again, once
            try:
                _forget_stale_machine_code(folder)
                if not kernels.in_cache("engine.run"):
                    print("tsmpc: compiling the run engine (first run only)…", file=sys.stderr,
                          flush=True)
                from tsmpc.kernels import engine as mod

                mod.warm()
                break
            except Exception as err:  # a broken cache or compiler: the Python loop runs
                mod = None
                sys.modules.pop("tsmpc.kernels.engine", None)
                removed = 0
                if attempt == 0:
                    try:
                        for q in folder.glob("engine.*.nb[ic]"):
                            q.unlink()
                            removed += 1
                    except OSError:
                        removed = 0
                if removed:
                    print(f"tsmpc: the run engine's cache in {folder} could not be loaded "
                          f"({type(err).__name__}); compiling it again…", file=sys.stderr, flush=True)
                    continue
                print(f"tsmpc: run engine unavailable ({type(err).__name__}: {err}); using the "
                      "Python loop", file=sys.stderr)
                break
    _KERNEL["mod"] = mod
    return mod


def _forget_stale_machine_code(folder: Any, prefix: str = "engine",
                               sources: tuple[str, ...] = ("mpc", "mhe", "lqr", "plant"),
                               stamp_name: str = "engine.blocks-sha256") -> None:
    """The engine's cache entries ``<prefix>.*`` deleted when the sources compiled into them
    changed (:func:`tsmpc.kernels.forget_stale`; the batch kernel uses it with its sources)."""
    from tsmpc import kernels
    from tsmpc.kernels.jit import BLOCK_MODULES

    kernels.forget_stale(folder, prefix, sources, stamp_name, BLOCK_MODULES)


def _compiled(ke: Any, args: tuple[Any, ...]) -> bool:
    """Compile (or load from numba's cache) ``run`` for these arrays by a call that runs no
    step. A cache entry numba cannot load is deleted and compiled again, once; False (the Python
    loop runs) when that fails too."""
    from numba.core.errors import NumbaError

    from tsmpc import kernels

    for attempt in range(2):
        try:
            with kernels.compile_lock("engine"):  # another process compiling it: wait, then load
                ke.run_borrowed(0, *args)
            return True
        except NumbaError:  # a typing or lowering error is a bug of the kernel: say so loudly
            raise
        except Exception as err:
            folder = kernels._tree_folder(kernels.numba_cache_dir())
            print(f"tsmpc: the run engine's cache in {folder} could not be loaded "
                  f"({type(err).__name__}){'; compiling it again…' if attempt == 0 else ''}",
                  file=sys.stderr, flush=True)
            if attempt == 0:
                try:
                    for p in folder.glob("engine.*.nb[ic]"):
                        p.unlink()
                except OSError:
                    break
    _KERNEL["mod"] = None  # not again in this process: the Python loop runs
    return False


# ------------------------------------------------------------------------------ the run
@dataclass
class _Arrays:
    """Everything the kernel reads and writes, in its argument order (see ``run``)."""

    x: NDArray[np.float64]
    fp: NDArray[np.float64]
    ip: NDArray[np.int64]
    sf: NDArray[np.float64]
    si: NDArray[np.int64]
    sc: NDArray[np.float64]
    ev: NDArray[np.int64]
    noise: NDArray[np.float64]
    u_drop: NDArray[np.float64]
    gnss: NDArray[np.float64]
    fifo: NDArray[np.float64]
    frb: NDArray[np.float64]
    patches: NDArray[np.float64]
    events: NDArray[np.float64]
    ref_x: NDArray[np.float64]
    ref_y: NDArray[np.float64]
    ref_th: NDArray[np.float64]
    ref_v: NDArray[np.float64]
    ref_w: NDArray[np.float64]
    th_tan: NDArray[np.float64]
    mv: NDArray[np.float64]
    mw: NDArray[np.float64]
    gate: NDArray[np.float64]
    cur: NDArray[np.float64]
    ivs: NDArray[np.float64]
    mass_v: NDArray[np.float64]
    mY: NDArray[np.float64]
    mW: NDArray[np.float64]
    mU: NDArray[np.float64]
    mXS: NDArray[np.float64]
    mA: NDArray[np.float64]
    mB: NDArray[np.float64]
    mX: NDArray[np.float64]
    mp: NDArray[np.float64]
    ls: NDArray[np.float64]
    Kv: NDArray[np.float64]
    zlo: NDArray[np.float64]
    zhi: NDArray[np.float64]
    bits: NDArray[np.bool_]
    prm: NDArray[np.float64]
    mints: NDArray[np.int64]
    mprm: NDArray[np.float64]
    mPS: NDArray[np.float64]
    prevX: NDArray[np.float64]
    prevU: NDArray[np.float64]
    pX: NDArray[np.float64]
    pU: NDArray[np.float64]
    cst: NDArray[np.float64]
    lo: NDArray[np.float64]
    loi: NDArray[np.int64]
    lxp: NDArray[np.float64]
    li: NDArray[np.float64]
    lstat: NDArray[np.int8]
    lsat: NDArray[np.bool_]

    def args(self) -> tuple[Any, ...]:
        return tuple(getattr(self, f) for f in self.__dataclass_fields__)


def _f64(a: Any) -> NDArray[np.float64]:
    """A writable C-ordered float64 copy (numba compiles one signature for these)."""
    return np.array(a, dtype=np.float64, order="C")


def _static_lqr(cascade: Cascade) -> TSLQR:
    """The cascade's TS-LQR: the engine reproduces the static-gain law only (:func:`applicability`
    sends lqr.law = as-run to the Python loop)."""
    from tsmpc.control.ts_lqr import TSLQR

    lqr = cascade.lqr
    if not isinstance(lqr, TSLQR):
        raise TypeError(f"the run engine reproduces TSLQR, not {type(lqr).__name__}")
    return lqr


def _parameters(cfg: Config, cascade: Cascade, scenario: Scenario, plant: Any,
                ke: Any) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The kernel's float and integer parameters (``fp``, ``ip``) of a reset cascade."""
    fp, ip = np.zeros(ke.N_FP), np.zeros(ke.N_IP, dtype=np.int64)
    ref, n_in, N = cascade.reference, cascade.n_inner, cfg.mpc.N
    mhe, lqr, fu = cascade.mhe, _static_lqr(cascade), cascade._fusion
    fs = cfg.fusion
    fp[ke.FP_TD], fp[ke.FP_TC], fp[ke.FP_H] = cascade.Td, cascade.Tc, plant.model.h
    fp[ke.FP_MU_NOM], fp[ke.FP_MG] = plant.vehicle.mu_nominal, plant._mg
    fp[ke.FP_GBK:ke.FP_GBK + N_GBK] = pack_gate_block(cascade._gate_p)  # the gate block's (Cascade._gate_p)
    fp[ke.FP_CP:ke.FP_CP + N_CP] = pack_course(cascade._fb_p.cp)  # the course fusion's (Cascade._fb_p.cp)
    fp[ke.FP_MHE_MASS] = mhe.vehicle.mass
    bound = scenario.divergence_bound_m or cfg.divergence_bound_m
    fp[ke.FP_BOUND] = math.inf if bound is None else float(bound)
    law = lqr._law  # the TS-LQR's law (its arrays are passed as they are: _prepare)
    assert law is not None  # run() checked lqr._kern
    # the inner block's record (Cascade._ib, whose TS-LQR part is TSLQR._inner: _blocks_problem)
    # and the law's scalars (TSLQR._law), packed by their own
    fp[ke.FP_IBK:ke.FP_IBK + N_IBK] = pack_inner_block(cascade._ib)
    fp[ke.FP_LAW:ke.FP_LAW + N_LAW] = pack_law(law)
    ip[ke.IP_NIN], ip[ke.IP_N] = n_in, N
    ip[ke.IP_NSUB] = rk4_count(cascade.Td, plant.model.h) or 0  # (run() checked it)
    ip[ke.IP_NW], ip[ke.IP_REFLEN] = cfg.mhe.N, len(ref)
    ip[ke.IP_ANYCOURSE] = fu.any_course
    ip[ke.IP_CSPEED] = fs.course_speed
    ip[ke.IP_STIFF] = fs.stiffness_estimate
    # the fusion block's records (Cascade._fb_p, the steering-offset fit's parameters as the config
    # gives them; the kernel rebuilds them from these slots)
    fp[ke.FP_FB:ke.FP_FB + N_FBP] = pack_fusion(cascade._fb_p, fu.steer_p)
    ip[ke.IP_MFORCE], ip[ke.IP_MSTEER] = scenario.measured_force, scenario.measured_steering
    # the outer block's records (Cascade._ob_p, _gov_p; the kernel rebuilds them from these slots)
    fp[ke.FP_OB:ke.FP_OB + N_OBP] = pack_outer(cascade._ob_p)
    fp[ke.FP_GB:ke.FP_GB + N_GBP] = pack_govern(cascade._gov_p)
    fp[ke.FP_CK:ke.FP_CK + N_CKP] = pack_clock(cascade._clock_p)  # the cascade's time's (Cascade._clock_p)
    return fp, ip


def _state(cascade: Cascade, ke: Any) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64],
                                               NDArray[np.float64]]:
    """The kernel's float and integer state (``sf``, ``si``) and the course fusion's intervals
    (``ivs``, ``cur``): the cascade's after reset(x0)."""
    sf, si = np.zeros(ke.N_SF), np.zeros(ke.N_SI, dtype=np.int64)
    mhe = cascade.mhe
    sf[ke.SF_IB:ke.SF_IB + ke.N_IB] = cascade._ib_state  # the inner block's (friction step, mass fit)
    sf[ke.SF_POSE:ke.SF_POSE + N_PO] = cascade._pose  # the gate block's pose record (gates.PO_*)
    # recovery: the run of poses rejected as jumps (the blind stop is not reproduced:
    # applicability() keeps runs that can blind the cascade in Python, and the kernel returns
    # BLINDED, the run given up, when the blind stop begins all the same)
    sf[ke.SF_GS:ke.SF_GS + ke.N_GS] = cascade._gs  # the gate block's (the jump run, the repeat guard)
    sf[ke.SF_UPREV:ke.SF_UPREV + 2] = cascade._up  # the MPC's previous input
    sf[ke.SF_CK:ke.SF_CK + N_CK] = cascade._ck  # the cascade's time's (no call yet, not blind)
    sf[ke.SF_CMD:ke.SF_CMD + ke.N_CM] = cascade._cmd  # the command record (_back.CM_*)
    sf[ke.SF_SA:ke.SF_SA + ke.N_SA] = cascade._sa  # the stiffnesses given (a reset cascade: none)
    # the fusion block's (the yaw-rate, steering-offset and course fits, the servo)
    sf[ke.SF_FB:ke.SF_FB + N_FB] = cascade._fb
    ivs, cur = cascade._ivs.copy(), cascade._cur.copy()
    # the MHE's records as its reset left them (kernels.mhe: [x̂, F̂, x̄_0, the yaw-model margin],
    # [samples, rejected, failed])
    sf[ke.SF_MX:ke.SF_MX + ke.N_MS] = mhe._ms
    si[ke.SI_NY:ke.SI_NY + ke.N_MI] = mhe._mi
    sf[ke.SF_OB:ke.SF_OB + ke.N_OB] = cascade._ob  # the outer block's (held pose, offset, governor, …)
    return sf, si, ivs, cur


def _counters(cascade: Cascade, ke: Any) -> NDArray[np.int64]:
    """The kernel's event counters (``ev``): the cascade's after reset(x0) — its time's, its
    step errors, the gate, inner and outer blocks' counters."""
    ev = np.zeros(ke.N_EVENTS, dtype=np.int64)
    ev[ke.EV_TIME_REJ:ke.EV_TIME_REJ + N_CC] = cascade._cc
    ev[ke.EV_STEP_ERR] = cascade._events["step_errors"]
    ev[ke.EV_GATES:ke.EV_INNER] = cascade._gate_count
    ev[ke.EV_INNER:ke.EV_OUTER] = cascade._ib_count
    ev[ke.EV_OUTER:ke.N_EVENTS] = cascade._oc
    return ev


def _blocks_problem(cascade: Cascade) -> str | None:
    """Why the kernel does not run this cascade's blocks, None when it does: the TS-MPC, the MHE-UIO
    and the TS-LQR as these classes (:func:`applicability` says which configurations build them;
    the kernel reads their arrays)."""
    from tsmpc.control.ts_lqr import TSLQR
    from tsmpc.control.ts_mpc import TSMPC
    from tsmpc.estimation.mhe_uio import MHEUIO

    if (type(cascade.mpc), type(cascade.mhe), type(cascade.lqr)) != (TSMPC, MHEUIO, TSLQR):
        return "the cascade's blocks are not the engine's (TSMPC, MHEUIO, TSLQR)"
    return None


def _start_problem(cascade: Cascade) -> str | None:
    """Why the kernel cannot start from this reset cascade, None when it can. It reads every other
    state from the cascade and its blocks (:func:`_state`, :func:`_counters`, :func:`_prepare`);
    these it cannot hold: a start from the first measurement (no x0), a last command or plan
    before the first call (the kernel's "no command yet" is the command record's, and it keeps the
    cascade's last plan and the MPC's as one)."""
    if cascade._x0 is None or cascade._pose is None:
        return "the cascade starts from its first measurement"
    if cascade._last is not None or cascade._plan is not None or cascade.mpc._prev is not None:
        return "the reset cascade has a last command or plan"
    return None


def _prepare(cfg: Config, cascade: Cascade, scenario: Scenario, plant: Any, K: int,
             x0: NDArray[np.float64], ke: Any) -> tuple[_Arrays, Any]:
    """The kernel's arrays from a reset cascade, the plant (a VehiclePlant, or the ActuatedPlant
    around one) and the scenario."""
    plant = plant if scenario.actuators is None else plant.plant
    n_in, N = cascade.n_inner, cfg.mpc.N
    M = K * n_in
    mpc, mhe, lqr = cascade.mpc, cascade.mhe, _static_lqr(cascade)
    fp, ip = _parameters(cfg, cascade, scenario, plant, ke)
    sf, si, ivs, cur = _state(cascade, ke)
    law = lqr._law
    assert law is not None  # run() checked lqr._kern
    Kv, zlo, zhi, bits, prm = law.Kv, law.zlo, law.zhi, law.bits, law.prm
    mp = mhe._mp.copy()  # the MHE block's parameters (C_f, C_r change with the stiffness fit)
    sr = _fault_data(cfg, cascade, scenario.sensor_fault, M, fp, sf)  # the sensors (tsmpc.sensors.SensorRun)
    noise, u_drop, gnss = sr.draws
    prog = _friction_program(scenario.friction)
    assert prog is not None
    frb, patches, events = prog
    # the outer block's reference (Cascade._refs: the reference's signals, its tangent, the MPC's
    # v and ω; the block reads windows past the end as Reference.window does)
    rx, ry, rth, rv, rw, rtan, mv, mw = (_f64(a) for a in cascade._refs)
    n_sc = ke.N_SC + 2 * (N + 1) + scratch_size(N, cascade._gov_p.preview)
    return _Arrays(
        x=_f64(x0), fp=fp, ip=ip, sf=sf, si=si, sc=np.zeros(n_sc),
        ev=_counters(cascade, ke), noise=noise, u_drop=_f64(u_drop),
        gnss=_f64(gnss), fifo=sr.model.fifo, frb=frb, patches=_f64(patches), events=_f64(events),
        ref_x=rx, ref_y=ry, ref_th=rth, ref_v=rv, ref_w=rw, th_tan=rtan, mv=mv, mw=mw,
        gate=cascade._gate_poses.copy(), cur=cur, ivs=ivs, mass_v=cascade._ib_ring.copy(),
        mY=mhe._Y, mW=mhe._W, mU=mhe._U, mXS=mhe._XS, mA=mhe._Ab, mB=mhe._Bb, mX=mhe._Xb, mp=mp,
        ls=lqr._s, Kv=Kv, zlo=zlo, zhi=zhi, bits=bits, prm=prm,
        mints=mpc._ints, mprm=mpc._prm, mPS=mpc._PS,
        prevX=np.zeros((N + 1, 3)), prevU=np.zeros((N, 2)), pX=np.zeros((N + 1, 3)),
        pU=np.zeros((N, 2)), cst=plant.model._cst, **new_records(K, n_in, N)._asdict()), sr


class _Run:
    """One engine run: the kernel calls and the Python slow paths between them."""

    def __init__(self, cfg: Config, cascade: Cascade, scenario: Scenario, plant: Any, K: int,
                 x0: NDArray[np.float64], ke: Any) -> None:
        self.cfg, self.cascade, self.scenario, self.plant, self.K, self.ke = (
            cfg, cascade, scenario, plant, K, ke)
        self.n_in, self.N = cascade.n_inner, cfg.mpc.N
        self.a, self.sensors = _prepare(cfg, cascade, scenario, plant, K, x0, ke)
        self.args = self.a.args()
        self.sec_mpc: dict[int, float] = {}
        self.sec_mhe: dict[int, float] = {}
        self.sec_lqr: dict[int, float] = {}
        self.slow = {"mpc": 0, "mhe": 0, "lqr": 0, "plant": 0}  # steps the Python paths decided

    # -- slow paths --------------------------------------------------------------------------
    def _mpc(self) -> None:
        """TSMPC.step in Python (its fast path declined): the condensed QP / SOCP path."""
        a, ke, N, mpc = self.a, self.ke, self.N, self.cascade.mpc
        if a.si[ke.SI_HASPREV]:
            mpc._prev = MPCResult(u=a.prevU[0].copy(), x_pred=a.prevX.copy(), u_pred=a.prevU.copy(),
                                  du=np.zeros((N, 2)), cost=math.nan, status=MPCStatus.OPTIMAL,
                                  iterations=0, qp_iterations=0, solve_time_s=0.0, n_clipped=0)
        else:
            mpc._prev = None
        o = ke.N_SC  # the window the outer block made (at the governed time once the governor acted)
        window = _Window(a.sc[o:o + N + 1].copy(), a.sc[o + N + 1:o + 2 * (N + 1)].copy())
        e = a.sc[ke.SC_EMEAS:ke.SC_EMEAS + 3].copy()
        t0 = time.perf_counter()
        try:
            plan = mpc.step(e, a.sf[ke.SF_UPREV:ke.SF_UPREV + 2].copy(), window)
        except Exception as err:  # the cascade would catch it: not reproduced here
            raise EngineFallback(f"MPC raised {type(err).__name__}") from err
        self.sec_mpc[int(a.si[ke.SI_M]) // self.n_in] = time.perf_counter() - t0
        a.pX[:] = np.asarray(plan.x_pred)[: N + 1]
        a.pU[:] = plan.u_pred
        a.sc[ke.SC_PU:ke.SC_PU + 2] = plan.u
        a.si[ke.SI_PSTAT] = _MPC_CODE[plan.status]
        a.si[ke.SI_PIT], a.si[ke.SI_PQPIT] = plan.iterations, plan.qp_iterations
        a.si[ke.SI_PCLIP] = plan.n_clipped

    def _mhe(self) -> None:
        """The MHE block's dense QP (a state bound is active in the window): MHEUIO.dense_step on
        the estimator's state as the kernel left it."""
        a, ke, mhe = self.a, self.ke, self.cascade.mhe
        mhe._ms[:] = a.sf[ke.SF_MX:ke.SF_MX + ke.N_MS]
        mhe._mi[:] = a.si[ke.SI_NY:ke.SI_NY + ke.N_MI]
        mhe._uk[:] = a.sc[ke.SC_UK:ke.SC_UK + 2]
        own = mhe._mp.copy()  # the run's parameters (the yaw-model margin's weight, the fits') in
        mhe._mp[:] = a.mp
        t0 = time.perf_counter()
        try:
            est = mhe.dense_step(bool(a.si[ke.SI_MHEOK]), int(a.si[ke.SI_MHEN]), float(a.sc[ke.SC_ESTFR]), t0)
        except Exception as err:
            raise EngineFallback(f"MHE raised {type(err).__name__}") from err
        finally:  # and back: the margin's update of the dense window into the run's
            a.mp[:] = mhe._mp
            mhe._mp[:] = own
        self.sec_mhe[int(a.si[ke.SI_M])] = time.perf_counter() - t0
        a.sf[ke.SF_MX:ke.SF_MX + ke.N_MS] = mhe._ms
        a.si[ke.SI_NY:ke.SI_NY + ke.N_MI] = mhe._mi
        a.sc[ke.SC_EST:ke.SC_EST + 3] = est.x
        a.sc[ke.SC_ESTF], a.sc[ke.SC_ESTFR] = est.F_fr, est.F_fr_raw
        a.si[ke.SI_ESTSTAT] = _MHE_CODE[est.status]

    def _lqr(self) -> None:
        """TSLQR's numpy law (the compiled one found N̄ singular)."""
        from tsmpc.control.inner_block import count_step

        a, ke, lqr = self.a, self.ke, _static_lqr(self.cascade)
        sa = a.sf[ke.SF_SA:ke.SF_SA + N_SA].tolist()
        if sa[SA_HAS]:  # the numpy law reads the lateral model from its vehicle
            lqr.model_stiffness(sa[SA_CF], sa[SA_CR], sa[SA_I], sa[SA_A], sa[SA_B])
        v, al, om = a.sc[ke.SC_EST:ke.SC_EST + 3].tolist()
        t0 = time.perf_counter()
        try:  # as Cascade._back: the block's compensation and residual, the numpy law, the events
            out = lqr._numpy_step(v, al, om, float(a.sc[ke.SC_VREF]), float(a.sc[ke.SC_WREF]),
                                  float(a.sc[ke.SC_COMP]), float(a.sc[ke.SC_LOWF]))
        except Exception as err:
            raise EngineFallback(f"TS-LQR raised {type(err).__name__}") from err
        self.sec_lqr[int(a.si[ke.SI_M])] = time.perf_counter() - t0
        count_step(a.ev[ke.EV_INNER:ke.EV_INNER + ke.N_IC], int(a.si[ke.SI_ESTSTAT]), bool(out.saturated))
        a.sc[ke.SC_OF], a.sc[ke.SC_OD] = out.F_xR, out.delta
        a.sc[ke.SC_LOWF] = out.F_low_speed
        a.sc[ke.SC_SAT] = 1.0 if out.saturated else 0.0

    def _plant(self) -> str | None:
        """The plant's non-finite step in Python: its error message, or (rounding of the float
        closure) a finite state to continue from."""
        a, ke = self.a, self.ke
        self.plant.reset(a.x.copy())
        actuated = self.scenario.actuators is not None
        if actuated and a.si[ke.SI_ACTHAS]:  # the actuators where the step started
            self.plant._s = ActuatorState(float(a.sf[ke.SF_ACT]), float(a.sf[ke.SF_ACT + 1]))
        try:
            x_next = self.plant.step(np.array([a.sc[ke.SC_OF], a.sc[ke.SC_OD]]), self.cascade.Td,
                                     float(a.sc[ke.SC_MU]))
            if not np.all(np.isfinite(x_next)):
                raise NonFiniteError(f"plant: non-finite state {x_next}")
        except NonFiniteError as err:
            k = int(a.si[ke.SI_M]) // self.n_in
            return f"plant diverged at t = {k * self.cascade.Tc:.2f} s: {err}"
        a.x[:] = x_next
        if actuated:
            a.sf[ke.SF_ACT], a.sf[ke.SF_ACT + 1] = self.plant._s.F, self.plant._s.delta
            a.si[ke.SI_ACTHAS] = 1
        a.sf[ke.SF_PLANTU:ke.SF_PLANTU + 2] = self.plant.applied_input
        return None

    def blinded(self) -> None:
        """The blind stop began (recovery): the run is the Python loop's."""
        raise EngineFallback("the cascade went blind (the blind stop and the restart run in the Python loop)")

    # -- the loop ----------------------------------------------------------------------------
    def diverged(self, m: int) -> tuple[str, int, int, int]:
        """(termination, outer steps done, inner rows logged, sensor samples taken) of a run the
        kernel stopped at inner step ``m`` for |e_y| beyond its bound (the Python loop's words)."""
        a, ke, k = self.a, self.ke, m // self.n_in
        e_y, bound = abs(float(a.sc[ke.SC_EY])), a.fp[ke.FP_BOUND]
        return (f"diverged: |e_y| = {e_y:.2f} m > {bound:g} m at t = {k * self.cascade.Tc:.1f} s",
                k + 1, m, m + 1)

    def loop(self, progress: Callable[[int, int], None] | None) -> tuple[str, int, int, int]:
        """Run to the end; (termination, outer steps done, inner rows logged, sensor samples
        taken)."""
        a, ke, K, n_in = self.a, self.ke, self.K, self.n_in
        M = K * n_in
        chunk = M if progress is None else _PROGRESS_CHUNK * n_in
        reported = 0
        while True:
            m_end = min(M, (int(a.si[ke.SI_M]) // chunk + 1) * chunk)
            try:
                code = ke.run_borrowed(m_end, *self.args)
            except Exception as err:  # e.g. a float division by zero the cascade would catch
                raise EngineFallback(f"the kernel raised {type(err).__name__}: {err}") from err
            m = int(a.si[ke.SI_M])
            if code == ke.DONE:
                if progress is not None:
                    for k in range(reported, m // n_in):
                        progress(k + 1, K)
                    reported = m // n_in
                if m >= M:
                    return "completed", K, M, M
            elif code == ke.NEED_MPC:
                self.slow["mpc"] += 1
                self._mpc()
            elif code == ke.NEED_MHE:
                self.slow["mhe"] += 1
                self._mhe()
            elif code == ke.NEED_LQR:
                self.slow["lqr"] += 1
                self._lqr()
            elif code == ke.NEED_PLANT:
                self.slow["plant"] += 1
                why = self._plant()
                if why is not None:
                    return why, m // n_in + 1, m + 1, m + 1
            elif code == ke.DIVERGED:
                return self.diverged(m)
            elif code == ke.BLINDED:
                self.blinded()
            else:  # pragma: no cover (a kernel/caller mismatch)
                raise RuntimeError(f"run engine: unknown code {code}")


def run(cfg: Config, method: Method | str, scenario: Scenario, *, kinematic_design: Any = None,
        dynamic_design: Any = None, progress: Callable[[int, int], None] | None = None,
        max_steps: int | None = None) -> RunLog | None:
    """``simulate(cfg, method, scenario, …)`` by the compiled engine; None when the blocks'
    kernels are not all active (the caller runs the Python loop). Check :func:`applicability`
    first. Raises :class:`EngineFallback` when the run meets a block exception."""
    ke = _load_kernel()
    if ke is None:
        return None
    cascade = Cascade(cfg, method, scenario.reference, kinematic_design=kinematic_design,
                      dynamic_design=dynamic_design)
    if _blocks_problem(cascade) is not None:
        return None
    mhe, lqr, mpc = cascade.mhe, _static_lqr(cascade), cascade.mpc
    if mpc._kern is None or mhe._kern is None or not mhe._kargs[-1] or lqr._kern is None:
        return None
    ref, N, Td = cascade.reference, cfg.mpc.N, cfg.rates.Td
    K = tracked_steps(ref, N)
    if K < 1:
        return None  # simulate raises the ConfigError
    K = K if max_steps is None else min(K, int(max_steps))
    plant: Any = default_plant(cfg, scenario)  # a VehiclePlant, or the ActuatedPlant around one
    vp = plant if scenario.actuators is None else plant.plant  # the VehiclePlant
    if vp.model._kern is None or rk4_count(Td, vp.model.h) is None:  # (VehiclePlant.step raises)
        return None
    x0 = _start_state(ref, scenario.initial_error)
    plant.reset(x0)
    cascade.reset(x0)
    if _start_problem(cascade) is not None:
        return None
    _hypot_exact(ke)
    t_start = time.perf_counter()
    r = _Run(cfg, cascade, scenario, plant, K, x0, ke)
    if scenario.actuators is not None and not _actuator_data(plant, Td, r.a.fp, r.a.ip):
        return None
    t_compile = time.perf_counter()
    if not _compiled(ke, r.args):
        return None
    t_compile = time.perf_counter() - t_compile
    t_loop, tick0 = time.perf_counter(), ke.ticks()
    termination, done, rows, n_calls = r.loop(progress)
    wall, ticks = time.perf_counter() - t_loop, ke.ticks() - tick0
    LAST_RUN.clear()
    LAST_RUN.update(slow_paths=dict(r.slow), loop_s=wall, compile_s=t_compile, exact=exact())
    _restore_fault(r, n_calls)
    return _log(r, cascade.method.value, scenario, done, rows, termination,
                ticks / wall if wall > 0 and ticks > 0 else 0.0,
                time.perf_counter() - t_start - t_compile)


def _log(r: _Run, method: str, scenario: Scenario, done: int, rows: int, termination: str,
         ticks_per_s: float, wall_s: float) -> RunLog:
    """The :class:`RunLog` ``simulate`` would have returned (the recorder block's
    :func:`~tsmpc.sim.record_block.run_log`, the blocks' cycle counts in seconds)."""
    a, ke, cfg = r.a, r.ke, r.cfg
    ref = r.cascade.reference
    o, i = slice(0, done), slice(0, rows)
    scale = 1.0 / ticks_per_s if ticks_per_s > 0 else 0.0
    mpc_t, mhe_t, lqr_t = a.lo[o, LO_TMPC] * scale, a.li[i, LI_TMHE] * scale, a.li[i, LI_TLQR] * scale
    for d, arr in ((r.sec_mpc, mpc_t), (r.sec_mhe, mhe_t), (r.sec_lqr, lqr_t)):
        for idx, sec in d.items():  # the steps a Python path decided: its own clock
            if idx < arr.size:
                arr[idx] = sec
    gov = r.cascade.governor is not None
    events = {name: int(a.ev[slot]) for name, slot in zip(_EVENTS, ke.EVENT_SLOTS, strict=True)}
    if gov:
        events["governor_actions"] = int(a.ev[ke.EV_OUTER + OC_GACT])
        events["governor_steps"] = int(a.ev[ke.EV_OUTER + OC_GSTEPS])
    return run_log(
        Records(a.lo, a.loi, a.lxp, a.li, a.lstat, a.lsat), method=method, scenario=scenario.name,
        Tc=cfg.rates.Tc, Td=cfg.rates.Td, t0=float(ref.t[0]), done=done, rows=rows,
        times=(mpc_t, mhe_t, lqr_t), wall_s=wall_s, termination=termination, events=events,
        meta={"oracle": False, "seed": cfg.seed, **scenario.meta, "final_state": a.x.tolist(),
              **({"planned_v": ref.v[:done].tolist(), "plan_delay_s": float(a.sf[ke.SF_TOFF])}
                 if gov else {})})


def cached() -> bool | None:
    """Whether the engine's machine code is in numba's cache (a run loads it rather than compiles
    it); None when the engine is unavailable (off, or no compiled kernels). Loads the engine's
    kernel module, which says "compiling the run engine (first run only)…" on a cold cache."""
    from tsmpc import kernels

    if not enabled() or _load_kernel() is None:
        return None
    return kernels.in_cache("engine.run")


def warmup() -> bool:
    """Compile (or load from numba's cache) the engine's machine code now, by one MPC step of the
    default cascade on the built-in circuit (``tsmpc warmup``; the designs of the default config
    are solved if the cache has none). True when the engine is available."""
    from tsmpc.blas import limit_blas_threads
    from tsmpc.planning.circuit import builtin_circuit

    if not enabled() or _load_kernel() is None:
        return False
    limit_blas_threads()  # as simulate() before a run
    cfg = Config()
    scenario = Scenario("warmup", builtin_circuit(dt=cfg.rates.Tc))
    if applicability(cfg, Method.REF, scenario) is None:  # (run() by itself, not via simulate():
        try:                                              # the simulator sits above the engine)
            run(cfg, Method.REF, scenario, max_steps=1)
        except EngineFallback:
            pass  # a block raised in the first step: the machine code is compiled all the same
    return True


if __name__ == "__main__":  # the table of _PORTED for the current code (after a port)
    for _target in _PORTED:
        print(f'    "{_target}": "{fingerprint(_target)}",')
