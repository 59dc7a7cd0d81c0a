"""Memory bound of a command (issue 38 item 2): an estimate made before any work, checked against a
documented, configurable limit; above it the command refuses with exit 2 naming both.

Two quantities are estimated and checked:

* **resident** memory (what the machine must hold): the measured resident baseline of a run
  (interpreter, numpy/scipy, numba kernels, the LMI designs) plus the arrays that grow with the run;
  checked against :func:`memory_limit` — :data:`ENV_LIMIT` (MB) when set, else
  :data:`DEFAULT_FRACTION` of the smaller of the physical memory and the cgroup's ``memory.max``;
* **virtual** address space, checked against the ``RLIMIT_AS`` soft limit (``ulimit -v``) when one
  is set: numba/llvmlite, two OpenBLAS copies (numpy's and scipy's, each reserving a buffer per
  thread) and CasADi map far more than they touch, so a low ``ulimit -v`` fails inside a library
  constructor — OpenBLAS then retries its allocation for ever instead of failing. Refusing
  beforehand is the only clean ending.

The arrays that grow with a run (per MPC step K and per inner step M = K·T_c/T_d, N the horizon):
the engine's preallocated logs (``sim/engine.py`` ``_prepare``: 15 + 4 outer columns, (N+1)·3
predictions, 19 inner columns, the noise draws of 5 columns built twice), the
:class:`~tsmpc.sim.log.RunLog` copy of each method (21 float + 3 integer outer columns, (N+1)·3
predictions, a 16-character status; 20 float inner columns, a flag, a 16-character status), kept
for every method of a compare; doubled for the writers' and metrics' temporaries. A reference costs
its samples (16 float columns with the engine's look-ahead copy) and, while a file is parsed,
about :data:`READ_BYTES_FACTOR` times its size (Python lists of floats).
"""

from __future__ import annotations

import math
import os
import resource
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from tsmpc.errors import TsmpcError
from tsmpc.textfile import read_bytes

__all__ = [
    "DEFAULT_FRACTION",
    "ENV_LIMIT",
    "MemoryEstimate",
    "address_space_floor_mb",
    "address_space_limit_mb",
    "early_problem",
    "estimate_run",
    "experiment_problem",
    "memory_limit",
    "memory_problem",
    "reference_problem",
    "reference_samples_upper",
]

#: Environment variable overriding the resident-memory limit [MB] (a positive number).
ENV_LIMIT = "TSMPC_MEMORY_LIMIT_MB"
#: Default limit: this fraction of the physical memory (or the cgroup's limit, if lower).
DEFAULT_FRACTION = 0.8
_MB = 1024 * 1024

# Baselines measured on `tsmpc run --duration 3 --no-plots` (cached designs, 2 cores, Linux x86-64,
# /usr/bin/time -v and /proc/self/status): max RSS 254 MB, VmPeak 749 MB; `tsmpc compare --methods
# ref,nl` (CasADi loaded): RSS 274 MB, VmPeak 1029 MB. Rounded up with a margin; the virtual part
# grows with OpenBLAS's threads (a 32 MB buffer per thread in each of its two copies, and stacks).
#: Resident memory of any run before its arrays [MB].
RESIDENT_BASE_MB = 320.0
#: Extra resident memory when the NL-MPC (CasADi + IPOPT) runs [MB].
RESIDENT_NL_MB = 60.0
#: Virtual address space of any run before its arrays, without the per-core part [MB].
VIRTUAL_BASE_MB = 700.0
#: Virtual address space per core (OpenBLAS thread buffers) [MB]: VmPeak 667 MB with
#: OPENBLAS_NUM_THREADS=1, 749 MB with 2 threads.
VIRTUAL_PER_CORE_MB = 80.0
#: Extra virtual address space when the NL-MPC (CasADi + IPOPT) runs [MB].
VIRTUAL_NL_MB = 350.0
#: Bytes a reference file costs while it is parsed, per byte of the file (measured: lines, lists
#: of Python floats, the array).
READ_BYTES_FACTOR = 16.0


@dataclass(frozen=True)
class MemoryEstimate:
    """What a command will need [MB]: resident (held in RAM) and virtual (address space)."""

    resident_mb: float
    virtual_mb: float
    what: str


def _cores() -> int:
    """The threads OpenBLAS starts at import: ``OPENBLAS_NUM_THREADS`` when set, else the cores."""
    text = os.environ.get("OPENBLAS_NUM_THREADS", "").strip()[:6]
    if text.isdigit() and int(text) > 0:
        return int(text)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def address_space_floor_mb(*, nl: bool = False) -> float:
    """The virtual address space any run needs before its arrays [MB] (measured, see above)."""
    return VIRTUAL_BASE_MB + VIRTUAL_PER_CORE_MB * _cores() + (VIRTUAL_NL_MB if nl else 0.0)


def estimate_run(*, outer_steps: int, inner_per_outer: int, horizon: int, methods: Sequence[str],
                 reference_samples: int, file_bytes: int = 0) -> MemoryEstimate:
    """The memory a ``run``/``compare`` of ``methods`` over ``outer_steps`` MPC steps needs."""
    K = max(int(outer_steps), 0)
    M = K * max(int(inner_per_outer), 1)
    P = 3 * (max(int(horizon), 0) + 1)
    n = max(len(methods), 1)
    engine = 8 * K * (15 + 4 + P) + M * (8 * 19 + 2 + 2 * 8 * 5)
    runlog = K * (8 * (21 + 3 + P) + 64) + M * (8 * 20 + 1 + 64)
    arrays = 2 * (engine + n * runlog)  # the writers' and the metrics' temporaries
    ref = 8 * 16 * max(int(reference_samples), 0) + READ_BYTES_FACTOR * max(int(file_bytes), 0)
    nl = any(str(m).strip().lower() == "nl" for m in methods)
    grow = (arrays + ref) / _MB
    resident = RESIDENT_BASE_MB + (RESIDENT_NL_MB if nl else 0.0) + grow
    virtual = address_space_floor_mb(nl=nl) + grow
    return MemoryEstimate(resident, virtual, f"{K} MPC steps of {n} method{'s' * (n > 1)}")


def _physical_mb() -> float:
    total = math.inf
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / _MB
    except (ValueError, OSError, AttributeError):
        pass
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        if not os.path.isfile(path):
            continue
        try:
            text = read_bytes(path, "cgroup memory limit", limit=4096, head=True).decode().strip()
        except (TsmpcError, OSError, UnicodeDecodeError):
            continue
        if text.isdigit() and int(text) < 1 << 60:  # "max" or a huge number: no limit
            total = min(total, int(text) / _MB)
    return total


def memory_limit() -> tuple[float, str]:
    """The resident-memory limit [MB] and where it comes from. :data:`ENV_LIMIT` wins; a value
    that is not a positive finite number raises ``ValueError`` naming it."""
    text = os.environ.get(ENV_LIMIT)
    if text is not None and text.strip():
        try:
            value = float(text.strip()[:40])
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{ENV_LIMIT}={text[:40]!r}: must be a positive number of MB")
        return value, ENV_LIMIT
    phys = _physical_mb()
    return DEFAULT_FRACTION * phys, (f"{DEFAULT_FRACTION:.0%} of the memory ({phys:.0f} MB); "
                                     f"{ENV_LIMIT} sets it")


def address_space_limit_mb() -> float | None:
    """The ``RLIMIT_AS`` soft limit (``ulimit -v``) [MB], None when unlimited."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY or soft < 0 else soft / _MB


def memory_problem(est: MemoryEstimate) -> str | None:
    """One line when ``est`` exceeds a limit (the address space first: it fails hardest)."""
    space = address_space_limit_mb()
    if space is not None and est.virtual_mb > space:
        return (f"not enough memory: {est.what} need about {est.virtual_mb:.0f} MB of address space, "
                f"the limit (ulimit -v, RLIMIT_AS) is {space:.0f} MB; raise it or shorten the run "
                f"(--duration)")
    try:
        limit, source = memory_limit()
    except ValueError as err:
        return str(err)
    if est.resident_mb > limit:
        return (f"not enough memory: {est.what} need about {est.resident_mb:.0f} MB, the limit is "
                f"{limit:.0f} MB ({source}); shorten the run (--duration, --window) or raise the limit")
    return None


def reference_samples_upper(path: Path) -> tuple[int, bool]:
    """An upper bound of a reference file's samples without parsing it, and whether it reads as a
    paper-format file (at most 8 lines: 6 rows, one sample a column): the larger of its lines (a
    planned CSV: one sample a row) and its commas / 6. Counting a 237 MB file takes about a
    second. Read through the safe reader (regular file, size cap): its errors propagate."""
    data = read_bytes(path, "reference")
    lines, commas = data.count(b"\n"), data.count(b",")
    return max(lines + 1, commas // 6), lines <= 8


#: Commands that load numpy/scipy/numba and solve or run: refused under a too low ``ulimit -v``.
HEAVY_COMMANDS = frozenset({"run", "compare", "sweep", "design", "plan", "demo", "warmup", "animate"})


def early_problem(argv: Sequence[str]) -> str | None:
    """At the entry point, before any heavy import: a ``RLIMIT_AS`` below the address space every
    run needs (:func:`address_space_floor_mb`) is refused for the heavy commands — with less, the
    imports fail with a traceback or OpenBLAS's start-up spins for ever (issue 38)."""
    args = [a for a in argv if not a.startswith("-")]
    if not args or args[0] not in HEAVY_COMMANDS or "--help" in argv:
        return None
    space = address_space_limit_mb()
    floor = address_space_floor_mb()
    if space is None or space >= floor:
        return None
    return (f"not enough memory: tsmpc {args[0]} needs at least {floor:.0f} MB of address space "
            f"(numpy, scipy, numba, OpenBLAS), the limit (ulimit -v, RLIMIT_AS) is {space:.0f} MB; "
            f"raise it")


def reference_problem(path: Path | None, *, methods: Sequence[str], duration: float | None,
                      window: tuple[int, int] | None, laps: int, Tc: float, Td: float,
                      horizon: int) -> str | None:
    """Before a reference file is parsed: its parsing and the run it implies (its samples, bounded
    by ``--window``, ``--duration`` and a paper file's default window) must fit the limits — an
    8-million-row file is refused in a second instead of parsed for minutes (issue 38)."""
    if path is None:
        return None
    try:
        if not Path(path).is_file():
            return None  # not a regular file: the reader says what is wrong
        size = Path(path).stat().st_size
        samples, paper = reference_samples_upper(Path(path))
    except (OSError, TsmpcError):
        return None  # the reader says what is wrong
    steps = samples * max(int(laps), 1)
    if window is not None:
        steps = min(steps, (window[1] - window[0] + 1) * max(int(laps), 1))
    elif paper:
        steps = min(steps, PAPER_WINDOW_COLUMNS)
    if duration is not None:
        steps = min(steps, math.ceil(duration / Tc) + 1)
    est = estimate_run(outer_steps=steps, inner_per_outer=max(1, round(Tc / Td)), horizon=horizon,
                       methods=methods, reference_samples=samples, file_bytes=size)
    problem = memory_problem(est)
    return None if problem is None else f"--reference {path}: {problem}"


#: Columns of the paper-run window a paper-format file uses by default (5..1316).
PAPER_WINDOW_COLUMNS = 1312


def experiment_problem(exp: object) -> str | None:
    """After :func:`tsmpc.sim.experiment.prepare` (nothing solved yet): the exact run's estimate
    (its steps, horizon, methods and reference) against the limits."""
    from tsmpc.sim.start import tracked_steps

    cfg = exp.config  # type: ignore[attr-defined]
    ref = exp.scenario.reference  # type: ignore[attr-defined]
    steps = tracked_steps(ref, cfg.mpc.N)
    if exp.max_steps is not None:  # type: ignore[attr-defined]
        steps = min(steps, int(exp.max_steps))  # type: ignore[attr-defined]
    est = estimate_run(outer_steps=steps, inner_per_outer=max(1, round(cfg.rates.Tc / cfg.rates.Td)),
                       horizon=cfg.mpc.N, methods=[m.value for m in exp.methods],  # type: ignore[attr-defined]
                       reference_samples=len(ref))
    return memory_problem(est)
