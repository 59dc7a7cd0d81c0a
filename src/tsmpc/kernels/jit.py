"""One definition per block, run two ways (issue 34): as Python from :class:`Cascade
<tsmpc.control.cascade.Cascade>`, compiled inside the run engine and the batch.

A block's per-step logic is written once, as a pure function over named records (``NamedTuple``
parameters and state, the new state returned), in the block's own module, and decorated with
:func:`jitable`. Called from Python it *is* that Python function (no dispatcher: typing a record
argument costs numba's dispatcher ≈ 6 µs, more than the block's own work); called from compiled
code (``tsmpc.kernels.engine.run``, the batch's lanes) numba compiles it into the caller. So the
engine and the Python loop run the same source, and a change to it reaches both: there is nothing
to port and nothing to keep in step.

Rules for a ``@jitable`` function: numba's nopython subset (floats, ints, bools, tuples,
``NamedTuple`` records, ``math``), no allocation of Python objects, Python's ``min``/``max``
(numba's have the same NaN semantics), :func:`exact_hypot` instead of ``math.hypot`` (libm's
rounds differently from CPython's), and the module listed in :data:`BLOCK_MODULES` — numba keys a
cached kernel by its own file only, so the engine's cache carries a hash of these sources and is
rebuilt when one changes (:func:`tsmpc.sim.engine._forget_stale_machine_code`).

With ``TSMPC_NO_JIT=1`` (or without numba) :func:`jitable` returns the function unchanged and
numba is not imported.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["BLOCK_MODULES", "cpython_hypot", "exact_hypot", "jitable", "jitable_inline"]

F = TypeVar("F", bound=Callable[..., Any])

#: The modules that define ``@jitable`` blocks (their sources are part of the engine's cache key;
#: tests/test_blocks.py checks the list is complete).
BLOCK_MODULES = (
    "tsmpc.control._back",
    "tsmpc.control._clock",
    "tsmpc.control._front",
    "tsmpc.control._mid",
    "tsmpc.control.fusion_block",
    "tsmpc.control.gates",
    "tsmpc.control.governor",
    "tsmpc.control.inner_block",
    "tsmpc.control.mhe_block",
    "tsmpc.control.stiffness_block",
    "tsmpc.control.offset_free",
    "tsmpc.control.outer_block",
    "tsmpc.control.slip_aware",
    "tsmpc.control.ts_lqr",
    "tsmpc.estimation.friction_step",
    "tsmpc.estimation.fusion",
    "tsmpc.estimation.mhe_margin",
    "tsmpc.kernels.jit",
    "tsmpc.sim.record_block",
    "tsmpc.scenarios",
    "tsmpc.sensors",
    "tsmpc.vehicle.actuators",
    "tsmpc.vehicle.single_track",
)


def _numba_ready() -> bool:
    """True when numba may be imported for compiled blocks: the kernels are on, and numba's cache
    folder is set before its first import (numba reads ``NUMBA_CACHE_DIR`` once)."""
    import sys

    from tsmpc.kernels import cache_problem, enabled, numba_cache_dir

    if not enabled():
        return False
    if "numba" not in sys.modules:
        if cache_problem() is not None:  # the kernels refuse it too (tsmpc.kernels.load)
            return False
        os.environ.setdefault("NUMBA_CACHE_DIR", str(numba_cache_dir()))
    try:
        import numba.extending  # noqa: F401
    except Exception:  # no numba on this platform: the blocks run as Python
        return False
    return True


def jitable(fn: F) -> F:
    """Mark ``fn`` as a block's one definition: plain Python when called from Python, compiled
    into compiled callers (numba's ``register_jitable``)."""
    if not _numba_ready():
        return fn
    from numba.extending import register_jitable

    return register_jitable(fn)


def jitable_inline(fn: F) -> F:
    """:func:`jitable`, inlined into its compiled callers by numba (``inline='always'``): a block
    that composes others passes its records down by value, and the run engine calls it every step
    (a call layer with records of arrays costs the engine about 1 %)."""
    if not _numba_ready():
        return fn
    from numba.extending import register_jitable

    return register_jitable(inline="always")(fn)


_VELTKAMP = 134217729.0  # 2**27 + 1: splits a double into two halves with exact products
_DBL_MIN = 2.2250738585072014e-308  # the smallest normal double (sys.float_info.min)


@jitable
def cpython_hypot(a: float, b: float) -> float:
    """``math.hypot(a, b)`` of CPython ≤ 3.11 to the last bit (libm's hypot rounds differently):
    the arguments scaled by a power of two, squared exactly through Veltkamp splits into
    compensated sums, the root corrected once by the residual (CPython's ``vector_norm``)."""
    x0, x1 = abs(a), abs(b)
    if math.isinf(x0) or math.isinf(x1):
        return math.inf
    if x0 != x0 or x1 != x1:
        return math.nan
    mx = x1 if x1 > x0 else x0
    if mx == 0.0:
        return mx
    e = math.frexp(mx)[1]
    post = 1.0
    if e < -1023:  # ldexp(1, -e) would overflow: the subnormals made normal first, as CPython
        x0, x1, mx = x0 / _DBL_MIN, x1 / _DBL_MIN, mx / _DBL_MIN
        e = math.frexp(mx)[1]
        post = _DBL_MIN
    scale = math.ldexp(1.0, -e)
    csum, f1, f2, f3 = 1.0, 0.0, 0.0, 0.0
    for i in range(2):
        x = (x0 if i == 0 else x1) * scale
        t = x * _VELTKAMP
        hi = t - (t - x)
        lo = x - hi
        x = hi * hi
        old = csum
        csum += x
        f1 += (old - csum) + x
        x = 2.0 * hi * lo
        old = csum
        csum += x
        f2 += (old - csum) + x
        f3 += lo * lo
    h = math.sqrt(csum - 1.0 + (f1 + f2 + f3))
    t = h * _VELTKAMP
    hi = t - (t - h)
    lo = h - hi
    x = -hi * hi
    old = csum
    csum += x
    f1 += (old - csum) + x
    x = -2.0 * hi * lo
    old = csum
    csum += x
    f2 += (old - csum) + x
    x = -lo * lo
    old = csum
    csum += x
    f3 += (old - csum) + x
    x = csum - 1.0 + (f1 + f2 + f3)
    return post * ((h + x / (2.0 * h)) / scale)


def exact_hypot(a: float, b: float) -> float:
    """``math.hypot(a, b)``; compiled, CPython's own algorithm to the last bit
    (:func:`cpython_hypot`), so a gate decides the same in both loops."""
    return math.hypot(a, b)


if _numba_ready():
    from numba.extending import overload

    @overload(exact_hypot)  # compiled into its callers (and their cache entries)
    def _exact_hypot_compiled(a, b):  # numba matches the signatures
        def impl(a, b):  # pragma: no cover - compiled
            return cpython_hypot(a, b)

        return impl
