"""Command-line interface: a thin typer shell over the library.

Each command lives in its own module of this package and calls one public library function;
this module only assembles the application.
"""

from __future__ import annotations

from tsmpc.cli._app import app


def _register() -> None:
    # Each module adds its commands to ``app``; heavy imports stay inside the command bodies.
    from tsmpc.cli import animate, compare, data, demo, design, plan, sweep, warmup  # noqa: F401


_register()


def main() -> None:
    """The ``tsmpc`` entry point: ``app`` with SIGINT/SIGTERM handled from the first moment (an
    interrupt at any time exits 128 + signal, never 0 or 1) and a closed or full stdout reported
    in one line (never a second error at interpreter exit)."""
    import atexit
    import contextlib
    import os
    import signal
    import sys

    from tsmpc.cli import _common, _memory, _watchdog

    _common.install_signal_handlers()
    # registered first, run last of the exit functions: a signal during the shutdown still counts
    atexit.register(_common.final_signal_check)
    _watchdog.enable()  # a signal ends the command within a bounded time (docs/outputs.md)
    problem = _memory.early_problem(sys.argv[1:])  # a ulimit -v too low for the imports: refuse
    if problem is not None:
        with contextlib.suppress(Exception):
            sys.stderr.write(f"error: {problem}\n")
        sys.exit(2)
    code: str | int | None = 0
    try:
        try:
            app()
        finally:
            # From here to the exit, signals are only recorded, then blocked (the interpreter's
            # shutdown restores the default handlers: a signal then would kill the process
            # without a word) and read as pending.
            _common.record_signals_only()
    except SystemExit as exc:
        code = exc.code
    except KeyboardInterrupt:
        code = 130
    except ImportError as exc:  # an optional dependency a command needs: the extra to install
        from tsmpc.extras import from_import_error

        hint = from_import_error(exc)
        code = 2
        if hint is None and "failed to map segment" in str(exc):  # the address space ran out
            hint, code = _common.out_of_memory(exc), 1
        if hint is None or os.environ.get("TSMPC_DEBUG"):
            raise
        with contextlib.suppress(Exception):
            sys.stderr.write(f"error: {hint}\n")
    except Exception as exc:  # the last net: one line, never a traceback (TSMPC_DEBUG=1 shows it)
        if os.environ.get("TSMPC_DEBUG"):
            raise
        if isinstance(exc, OSError):
            what = f"cannot write{' ' + str(exc.filename) if exc.filename else ''}: {exc.strerror or exc}"
        elif isinstance(exc, MemoryError):  # a failed allocation is not a bug of tsmpc
            what = _common.out_of_memory(exc)
        else:
            what = f"internal error {type(exc).__name__}: {' '.join(str(exc).split())[:500]}"
        with contextlib.suppress(Exception):
            sys.stderr.write(f"error: {what}\n")
        code = 1
    pending: set[int] = set()
    with contextlib.suppress(AttributeError, OSError, ValueError):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        pending = {int(s) for s in signal.sigpending()}
    sig = _common.first_signal() or (min(pending) if pending else None)
    if sig is not None:
        code = 128 + sig
        _common.late_interrupt(sig)
    try:
        if sys.stdout is not None:
            sys.stdout.flush()
    except (OSError, ValueError):
        with contextlib.suppress(Exception):
            fd = os.open(os.devnull, os.O_WRONLY)
            if sys.stdout is not None:
                os.dup2(fd, sys.stdout.fileno())
        if code in (0, None):
            with contextlib.suppress(Exception):
                sys.stderr.write("error: cannot write to stdout (closed or full)\n")
            code = 1
    if code is None:
        code = 0
    elif not isinstance(code, int):  # sys.exit("message"): Python prints it and exits 1
        with contextlib.suppress(Exception):
            sys.stderr.write(f"{code}\n")
        code = 1
    _common.exit_with(code)


__all__ = ["app", "main"]
