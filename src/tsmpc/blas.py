"""One BLAS thread for every simulating process (threadpoolctl).

The online blocks multiply matrices of a few dozen rows: a multi-threaded BLAS only adds
synchronisation, and on a busy machine (other processes, Dask workers — one per core) its
spinning threads cost far more than the work (measured on the 2-core CI machine: one MHE step
2–4.6 ms of CPU instead of 0.18 ms, a REF paper run 29–218 s instead of 3.5 s). So
:func:`simulate`, the CLI commands that simulate and the sweep's Dask tasks call
:func:`limit_blas_threads` first.

``TSMPC_BLAS_THREADS`` overrides it: a number of threads, or ``default`` to leave the BLAS
library's own setting alone (e.g. for a big offline design computation in the same process).
More threads than the process may use cores are capped at that count, with a one-line warning
(issue 24: 3 … 100000 threads on 2 cores made a 3 s run spin for minutes in ``expm``); an
unreadable value falls back to 1 with a warning (the CLI refuses it: :func:`blas_threads_problem`).
"""

from __future__ import annotations

import os
import sys
from typing import Any

__all__ = ["blas_threads_problem", "blas_threads_setting", "cores", "limit_blas_threads"]

_LIMITER: Any = None
_APPLIED: int | None = None
_WARNED: set[str] = set()


def cores() -> int:
    """CPU cores this process may run on (its affinity mask, else the machine's count)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return max(os.cpu_count() or 1, 1)


def _warn(text: str) -> None:
    if text not in _WARNED:
        _WARNED.add(text)
        print(f"tsmpc: warning: {text}", file=sys.stderr)


def blas_threads_problem() -> str | None:
    """None when ``TSMPC_BLAS_THREADS`` is unset, ``default`` or a whole number >= 1; else one
    line naming it (for the CLI's checks before any work)."""
    text = os.environ.get("TSMPC_BLAS_THREADS")
    if text is None or text.strip().lower() in ("default", "auto", "none", ""):
        return None
    t = text.strip()
    if not (t.isascii() and t.isdigit() and 1 <= int(t[:12]) and len(t) <= 12):
        return (f"TSMPC_BLAS_THREADS={text[:40]!r}: must be a whole number of threads >= 1 (at most "
                f"{cores()} here) or 'default'")
    return None


def blas_threads_setting() -> int | None:
    """Threads requested by ``TSMPC_BLAS_THREADS`` (default 1), at most :func:`cores`; None =
    leave the library alone. An unreadable value falls back to 1 with a warning (this runs
    inside simulations: it must not raise)."""
    text = os.environ.get("TSMPC_BLAS_THREADS", "1").strip().lower()
    if text in ("default", "auto", "none", ""):
        return None
    if blas_threads_problem() is not None:
        _warn(f"TSMPC_BLAS_THREADS={text[:40]!r} is not a number of threads: using 1")
        return 1
    n, limit = int(text), cores()
    if n > limit:
        _warn(f"TSMPC_BLAS_THREADS={n} is more than the {limit} cores this process may use: "
              f"using {limit}")
        return limit
    return max(n, 1)


def limit_blas_threads(threads: int | None = -1) -> int | None:
    """Limit the BLAS libraries loaded in this process to ``threads`` (-1: the
    ``TSMPC_BLAS_THREADS`` setting, by default 1; None: no limit). Idempotent and cheap after the
    first call; returns the limit in force (None when none was applied)."""
    global _LIMITER, _APPLIED
    n = blas_threads_setting() if threads == -1 else threads
    if n is None or n == _APPLIED:
        return n
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional at run time: the environment variables still work
        return None
    _LIMITER = threadpool_limits(limits=n, user_api="blas")
    _APPLIED = n
    return n
