"""A bound on how long SIGINT/SIGTERM can take to end a command (issue 38 item 2).

The CLI's handlers only record a signal inside compiled code (numba kernels, BLAS, solvers) and act
on it at the next check, so a command stuck in compiled code would never end. Two rules bound it:

* **watchdog**: the first signal starts a thread that, if the process has not exited within
  :data:`GRACE_S` seconds (``TSMPC_SIGNAL_GRACE_S`` overrides it, 0.5 to 3600), writes one line
  (``error: interrupted; still busy in compiled code after N s, exiting``) and ends the process with
  ``os._exit(128 + signal)``;
* **second signal**: a second SIGINT/SIGTERM ends the process at once the same way.

The hard exit skips clean-up: the results are written atomically (a file is complete or absent)
and the output folder keeps its ``PARTIAL`` marker, rewritten to ``interrupted`` just before the
exit, so only the unfinished run is lost.
Limit: the watchdog is a Python thread, so it needs the interpreter lock; compiled code that holds
it for good (a library constructor spinning inside ``import``) is not bounded by it — the memory
check (:mod:`tsmpc.cli._memory`) refuses the low ``ulimit -v`` that caused such a spin.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
from collections.abc import Callable

__all__ = ["ENV_GRACE", "GRACE_S", "enable", "grace_s", "on_signal"]

#: Seconds a command has, after its first SIGINT/SIGTERM, to end by itself.
GRACE_S = 10.0
#: Environment variable overriding :data:`GRACE_S` (seconds, 0.5 to 3600).
ENV_GRACE = "TSMPC_SIGNAL_GRACE_S"

_first: list[int] = []
_enabled = [False]
_before_exit: list[Callable[[int], None]] = []


def enable() -> None:
    """Arm the rules for the rest of the process: the ``tsmpc`` entry point calls it (never a
    library user, nor a test calling the handlers in its own process)."""
    _enabled[0] = True


def grace_s() -> float:
    """:data:`GRACE_S`, or ``TSMPC_SIGNAL_GRACE_S`` when it is a number in [0.5, 3600]."""
    text = os.environ.get(ENV_GRACE, "").strip()[:40]
    try:
        value = float(text) if text else GRACE_S
    except ValueError:
        return GRACE_S
    return value if math.isfinite(value) and 0.5 <= value <= 3600 else GRACE_S


def _hard_exit(signum: int, why: str) -> None:
    """The last words (the caller's ``before_exit``: the CLI marks its folder ``interrupted``),
    one line on stderr (a raw write: no lock, no Python stream) and the exit, skipping clean-up."""
    if _before_exit:
        with contextlib.suppress(Exception):
            _before_exit[0](signum)
    with contextlib.suppress(OSError):
        os.write(2, f"error: interrupted ({signal.Signals(signum).name}); {why}, exiting\n".encode())
    os._exit(128 + signum)


def _watch(signum: int, seconds: float) -> None:
    threading.Event().wait(seconds)
    _hard_exit(signum, f"still busy in compiled code after {seconds:g} s")


def on_signal(signum: int, before_exit: Callable[[int], None] | None = None) -> None:
    """Called by the CLI's handler for every SIGINT/SIGTERM: the first starts the watchdog, a
    second one exits at once with the first signal's code; ``before_exit(signal)`` runs just before
    a hard exit. Nothing before :func:`enable`."""
    if not _enabled[0]:
        return
    if before_exit is not None and not _before_exit:
        _before_exit.append(before_exit)
    if _first:
        _hard_exit(_first[0], "a second signal arrived")
    _first.append(signum)
    seconds = grace_s()
    threading.Thread(target=_watch, args=(signum, seconds), name="tsmpc-signal-watchdog",
                     daemon=True).start()
