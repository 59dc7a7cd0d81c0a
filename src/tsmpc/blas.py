"""One BLAS thread for every simulating process (threadpoolctl).

The online blocks multiply matrices of a few dozen rows: a multi-threaded BLAS only adds
synchronisation, and on a busy machine (other processes, Dask workers — one per core) its
spinning threads cost far more than the work (measured on the 2-core CI machine: one MHE step
2–4.6 ms of CPU instead of 0.18 ms, a REF paper run 29–218 s instead of 3.5 s). So
:func:`simulate`, the CLI commands that simulate and the sweep's Dask tasks call
:func:`limit_blas_threads` first.

``TSMPC_BLAS_THREADS`` overrides it: a number of threads, or ``default`` to leave the BLAS
library's own setting alone (e.g. for a big offline design computation in the same process).
"""

from __future__ import annotations

import os
from typing import Any

__all__ = ["blas_threads_setting", "limit_blas_threads"]

_LIMITER: Any = None
_APPLIED: int | None = None


def blas_threads_setting() -> int | None:
    """Threads requested by ``TSMPC_BLAS_THREADS`` (default 1); None = leave the library alone.
    An unreadable value falls back to 1 (this runs inside simulations: it must not raise)."""
    text = os.environ.get("TSMPC_BLAS_THREADS", "1").strip().lower()
    if text in ("default", "auto", "none", ""):
        return None
    try:
        n = int(text)
    except ValueError:
        return 1
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
