"""Helpers shared by the CLI commands: config loading, error reporting, output-folder checks,
interrupts and the status line shown while LMI designs are solved.

Exit codes (docs/outputs.md "Exit codes"): 0 done, 1 a run diverged or failed, 2 invalid input
(reported before any work starts; also a configuration no LMI design exists for), 3 a run completed
but degraded (tsmpc.sim.health.degradation), 128 + signal number when interrupted (130 SIGINT,
143 SIGTERM).

Mechanisms against hostile inputs and environments (issue 24):

* every message is one line of bounded length (:func:`fail`), printed literally (never as rich
  markup: :func:`console` makes consoles without markup, highlighting or emoji);
* an option whose value would be ignored is refused (:func:`refuse_ineffective`, which asks click
  whether the user gave the option);
* output paths are checked for over-long names before anything is created (:func:`check_path_text`);
* the work on an output folder runs inside :func:`guarded_run`: an interrupt, a design failure,
  a failed write (disk full, a closed stdout) or any unexpected error ends with one line, a
  non-zero exit and the PARTIAL marker saying ``interrupted`` or ``failed`` with the reason;
* signals: the handler raises at once only in plain Python phases; inside
  :func:`deferred_interrupts` (the simulation loops, whose blocks call compiled numba code) it only
  records the signal, and the loop checks the flag between steps (:func:`check_interrupted`).
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import typer

from tsmpc.config import Config, load_config
from tsmpc.errors import ConfigError, DesignError, TsmpcError
from tsmpc.io import new_private_file

__all__ = [
    "EXIT_DEGRADED",
    "EXIT_FAILED",
    "EXIT_INVALID",
    "MAX_LAPS",
    "PARTIAL_MARKER",
    "Interrupted",
    "check_environment",
    "check_interrupted",
    "check_laps",
    "check_out_dir",
    "check_out_file",
    "check_path_text",
    "console",
    "data_path",
    "deferred_interrupts",
    "design_status",
    "fail",
    "finite",
    "guarded_run",
    "handle_interrupts",
    "install_signal_handlers",
    "late_interrupt",
    "load_config_or_exit",
    "mark_partial",
    "out_of_memory",
    "pending_signal",
    "record_signals_only",
    "refuse_ineffective",
    "safe_stdio",
    "solve_design",
]

#: Exit code of invalid input (configs, files, option values).
EXIT_INVALID = 2
#: Exit code of a run that failed (diverged, a write failed, an unexpected error).
EXIT_FAILED = 1
#: Exit code of a run that completed beyond its health bounds (tsmpc.sim.health.degradation):
#: its results are written, but the car could not do what the plan asked.
EXIT_DEGRADED = 3
#: File left in an output folder whose run did not finish (interrupted or in progress).
PARTIAL_MARKER = "PARTIAL"
#: Most characters of one error message (a 10 MB name is not echoed back).
MAX_MESSAGE_CHARS = 2000
#: Most laps of ``run``/``compare``/``plan`` (``--laps``).
MAX_LAPS = 1000
#: Longest file-name component [bytes] (the common file systems' NAME_MAX).
NAME_MAX = 255


def _bounded(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` cut to about ``limit`` characters: its start and its end (where a count of the
    problems left out is) around a note of how much was left out."""
    if len(text) <= limit:
        return text
    tail = min(300, limit // 4)
    return f"{text[:limit - tail]} … ({len(text) - limit} characters left out) … {text[-tail:]}"


def fail(err: Exception | str, code: int = EXIT_INVALID) -> NoReturn:
    """Print one error line (at most :data:`MAX_MESSAGE_CHARS`) on stderr and exit with ``code``."""
    text = _bounded(" ".join(str(err).split("\n")))
    with contextlib.suppress(OSError, ValueError):  # a closed stderr must not hide the exit code
        typer.secho(f"error: {text}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code)


def console(*, stderr: bool = False, width: int | None = None) -> Any:
    """A rich console that prints text literally: no markup (``[/]`` in a user's path or sweep
    name is text), no highlighting (a 10 MB name cannot stall the highlighter), no emoji codes.
    Styles are passed explicitly (``style=``, :class:`rich.text.Text`)."""
    from rich.console import Console

    con = Console(stderr=stderr, markup=False, highlight=False, emoji=False)
    if width is None and not con.is_terminal:  # piped to a file or CI log: do not squeeze tables
        width = 140
    if width is not None:
        con = Console(stderr=stderr, markup=False, highlight=False, emoji=False, width=width)
    return con


def safe_stdio() -> None:
    """A terminal that cannot encode a character gets a replacement character, never a
    ``UnicodeEncodeError`` (``PYTHONIOENCODING=ascii``, a latin-1 terminal). A closed stdout
    (``>&-``: Python then has no ``sys.stdout``) is refused before any work: every result line
    would be lost without a word."""
    if sys.stdout is None:
        fail(ConfigError("stdout is closed: tsmpc's results could not be shown; redirect it to a "
                         "file or to /dev/null"))
    for stream in (sys.stdout, sys.stderr):
        enc = (getattr(stream, "encoding", None) or "").lower().replace("-", "")
        if enc != "utf8" and hasattr(stream, "reconfigure"):
            with contextlib.suppress(Exception):
                stream.reconfigure(errors="replace")  # pyright: ignore[reportAttributeAccessIssue]


def check_environment(*, kernels: bool = True) -> None:
    """Before any work: the environment variables tsmpc reads name usable things, else exit 2
    naming the variable — ``TSMPC_CACHE_DIR`` and ``NUMBA_CACHE_DIR`` writable folders (never
    silently bypassed), ``TSMPC_BLAS_THREADS`` a number or ``default`` (above the core count it
    is capped, with a warning: :mod:`tsmpc.blas`)."""
    from tsmpc.blas import blas_threads_problem
    from tsmpc.paths import folder_problem

    env = os.environ.get("TSMPC_CACHE_DIR")
    if env:
        problem = folder_problem(Path(env))
        if problem:
            fail(ConfigError(f"TSMPC_CACHE_DIR {env}: {problem}; fix or unset it"))
    problem = blas_threads_problem()
    if problem:
        fail(ConfigError(problem))
    if kernels:
        from tsmpc import kernels as k

        problem = k.cache_problem()
        if problem:
            fail(ConfigError(problem))


def check_laps(laps: int, option: str = "--laps") -> None:
    """1 <= laps <= :data:`MAX_LAPS` (exit 2 otherwise)."""
    if not 1 <= laps <= MAX_LAPS:
        fail(ConfigError(f"{option} = {_bounded(str(laps), 40)}: must be 1 to {MAX_LAPS}"))


def check_scenario_options(scenario: Any, *, reference: Path | None, laps: int, plant: str) -> None:
    """``run``/``compare``: refuse the options the loaded scenario would ignore (issue 24).
    (``--duration`` beyond the reference is an upper bound, not an ignored option: kept.)"""
    paper = bool(scenario.meta.get("paper_format"))
    refuse_ineffective({
        "window": (reference is None, "the built-in circuit has no columns or rows to choose; "
                   "give a --reference"),
        "laps": (reference is None and laps != 1, "--laps repeats a closed lap of a --reference "
                 "(a planned track); the built-in circuit is one open path"),
        "dt": (not paper, "--dt is the column period of a paper-format --reference (a planned CSV "
               "carries its own time column; the built-in circuit is sampled at Tc)"),
        "cr_vehicle": (plant.strip().lower() == "tsmpc",
                       "it picks the vehicle of --plant commonroad-st or commonroad-mb"),
    })


def _click_context() -> Any:
    """The running command's click context (typer >= 0.26 runs its own copy of click)."""
    import importlib

    try:  # (by name: which of the two modules exists depends on typer's version)
        globals_ = importlib.import_module("typer._click.globals")
    except ImportError:  # an older typer on the public click
        globals_ = importlib.import_module("click")
    return globals_.get_current_context(silent=True)


def refuse_ineffective(rules: dict[str, tuple[bool, str]]) -> None:
    """Refuse options the user gave whose value would be ignored: ``rules`` maps a parameter name
    to (ineffective?, why). Only options given on the command line are refused (click's
    parameter source), so defaults never trip it."""
    ctx = _click_context()
    for name, (ineffective, why) in rules.items():
        if not ineffective:
            continue
        given = True
        if ctx is not None:
            src = ctx.get_parameter_source(name)
            given = src is not None and src.name in ("COMMANDLINE", "ENVIRONMENT")
        if given:
            opt = "--" + name.replace("_", "-")
            if ctx is not None:
                for p in ctx.command.params:
                    if p.name == name and getattr(p, "opts", None):
                        opt = p.opts[0]
            fail(ConfigError(f"{opt} has no effect here: {why}"))


def load_config_or_exit(path: Path | None, preset: str | None = None) -> Config:
    """Load the config at ``path`` (defaults if None) on top of ``preset``; a bad file or an
    unknown preset exits with a clear message."""
    try:
        return load_config(path, preset)
    except TsmpcError as err:
        fail(err)
        raise  # unreachable, for type checkers


def finite(name: str, value: float | None, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False) -> float | None:
    """Check a numeric CLI option: finite and within [lo, hi] (``lo_open``: > lo); else exit 2."""
    if value is None:
        return None
    bad = not math.isfinite(value)
    if lo is not None and (value <= lo if lo_open else value < lo):
        bad = True
    if hi is not None and value > hi:
        bad = True
    if bad:
        if hi is None and lo is not None:
            rng = f"{'>' if lo_open else '>='} {lo:g}"
        else:
            rng = (f"in {'(' if lo_open else '['}{'-inf' if lo is None else f'{lo:g}'}, "
                   f"{'inf' if hi is None else f'{hi:g}'}]")
        fail(ConfigError(f"{name} = {value!r}: must be a finite number {rng}"))
    return value


def data_path(path: Path | None, option: str) -> Path | None:
    """An input that may name a dataset (issue 37): an existing path is used as given; otherwise a
    dataset or track name (``paper``, ``monza``: :mod:`tsmpc.datasets`) is resolved to its file.
    A dataset not downloaded exits 2 naming ``tsmpc data fetch …``."""
    from tsmpc import datasets

    if path is None or os.path.lexists(path) or not datasets.is_dataset_name(path):
        return path
    try:
        found = datasets.resolve(str(path))
    except datasets.DataNotFoundError as err:
        fail(ConfigError(f"{option} {path}: {err}"))
    if found.is_dir():
        fail(ConfigError(f"{option} {path}: names every race track; give one of "
                         f"{', '.join(n for n in datasets.names() if n not in datasets.DATASETS)}"))
    return found


# -- output locations ----------------------------------------------------------------------
def check_path_text(path: Path, option: str) -> None:
    """A path the OS can take: no NUL byte, no component longer than :data:`NAME_MAX` bytes
    (ENAMETOOLONG would otherwise surface deep inside a write). Exits 2 naming the option."""
    text = str(path)
    if "\x00" in text:
        fail(ConfigError(f"{option}: the path contains a NUL byte"))
    for part in path.parts:
        n = len(os.fsencode(part))
        if n > NAME_MAX:
            fail(ConfigError(f"{option} {_bounded(text, 120)}: a name component is {n} bytes long; "
                             f"at most {NAME_MAX}"))
    if len(os.fsencode(text)) > 4000:
        fail(ConfigError(f"{option}: the path is {len(text)} characters long; at most 4000"))


def _probe_writable(folder: Path, option: str) -> None:
    tmp: list[Path] = []
    try:
        try:  # (the probe's name is known before it exists: an interrupt cannot leave it behind)
            os.close(new_private_file(folder, ".tsmpc-probe-", "", tmp))
        finally:
            if tmp:
                tmp[0].unlink(missing_ok=True)
    except OSError as err:
        fail(ConfigError(f"{option} {folder}: cannot write there ({err.strerror or err})"))


def _check_parents(path: Path, option: str) -> Path:
    """The nearest existing ancestor of ``path`` (exits if an ancestor is a file)."""
    check_path_text(path, option)
    anc = path.absolute()
    for parent in [anc, *anc.parents]:
        try:
            exists = parent.exists()
        except OSError as err:
            fail(ConfigError(f"{option} {path}: cannot inspect {parent} ({err.strerror or err})"))
        if exists:
            if not parent.is_dir() and parent != anc:
                fail(ConfigError(f"{option} {path}: {parent} is a file, not a folder"))
            return parent
    return Path("/")


def check_out_dir(out: Path, *, overwrite: bool, option: str = "--out",
                  hint: str = "pass --overwrite to replace tsmpc's outputs in it") -> None:
    """Before any work: ``out`` must be a folder we can create and write, and empty unless
    ``overwrite`` (then tsmpc's outputs of a previous run in it are removed, nothing else).
    Exits with code 2 naming the problem and ``hint`` (an option the command has)."""
    _check_parents(out, option)
    if out.exists() and not out.is_dir():
        fail(ConfigError(f"{option} {out}: exists and is a file; give a folder"))
    if out.is_dir():
        try:
            entries = [p for p in out.iterdir() if not p.name.startswith(".tsmpc-probe-")]
        except OSError as err:
            fail(ConfigError(f"{option} {out}: cannot list the folder ({err.strerror or err})"))
        if entries and not overwrite:
            fail(ConfigError(f"{option} {out}: folder is not empty ({len(entries)} entries); choose "
                             f"another folder or {hint}"))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        fail(ConfigError(f"{option} {out}: cannot create the folder ({err.strerror or err})"))
    _probe_writable(out, option)


def check_out_file(out: Path, *, overwrite: bool = True, option: str = "--out") -> None:
    """Before any work: the file ``out`` can be written (its folder exists or can be made,
    it is not a folder; an existing file only with ``overwrite``). Exits with code 2."""
    _check_parents(out, option)
    if out.is_dir():
        fail(ConfigError(f"{option} {out}: is a folder; give a file name"))
    if out.exists() and not overwrite:
        fail(ConfigError(f"{option} {out}: file exists; pass --overwrite to replace it"))
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        fail(ConfigError(f"{option} {out}: cannot create {out.parent} ({err.strerror or err})"))
    _probe_writable(out.parent, option)


def mark_partial(out: Path, status: str, **info: Any) -> None:
    """Write (or update) the PARTIAL marker of an unfinished run in ``out``. When the atomic
    write fails (a full disk has no block for the new file) the existing marker is rewritten in
    place (it owns its block), so it still says ``failed`` or ``interrupted``."""
    from tsmpc.io import atomic_write_text, overwrite_in_place

    info = {k: _bounded(v, 500) if isinstance(v, str) else v for k, v in info.items()}
    body = {"status": status, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **info,
            "note": "this folder holds an unfinished tsmpc run: its files are incomplete"}
    text = json.dumps(body, indent=1) + "\n"
    try:
        atomic_write_text(out / PARTIAL_MARKER, text)
    except OSError:
        with contextlib.suppress(OSError):
            overwrite_in_place(out / PARTIAL_MARKER, text.encode("utf-8"))


# -- interrupts ----------------------------------------------------------------------------
class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (not an error: a request to stop). ``code`` = 128 + signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.code = 128 + signum


_pending: list[int] = []
_seen: list[int] = []  # every signal of the process (the entry point's exit code)
_defer = [0]  # depth of deferred_interrupts()
_raised = [False]


def _handler(signum: int, _frame: Any) -> None:
    import tsmpc.cli._watchdog as _watchdog  # a bound on the time to the exit (armed by the entry point)

    _watchdog.on_signal(signum, _mark_hard_exit)
    _pending.append(signum)
    _seen.append(signum)
    if _defer[0] == 0 and not _raised[0]:
        _raised[0] = True
        raise Interrupted(signum)


def _mark_hard_exit(signum: int) -> None:
    """Before the watchdog's hard exit (:mod:`tsmpc.cli._watchdog`): an unfinished guarded folder
    says ``interrupted``, as after a clean interrupt."""
    if _guarded_out and (_guarded_out[-1] / PARTIAL_MARKER).exists():
        mark_partial(_guarded_out[-1], "interrupted", signal=signal.Signals(signum).name,
                     after="the command was still busy: it exited without its clean-up")


def pending_signal() -> int | None:
    """The first signal received inside the current :func:`handle_interrupts`, or None."""
    return _pending[0] if _pending else None


def first_signal() -> int | None:
    """The first signal this process received (for the entry point's exit code), or None."""
    return _seen[0] if _seen else None


def check_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal arrived: called between the blocks of a loop (after
    every MPC step) and between phases — a signal recorded inside :func:`deferred_interrupts`, or
    one a solver swallowed (CasADi/IPOPT catch SIGINT and return a failed status)."""
    if _pending:
        _raised[0] = True
        raise Interrupted(_pending[0])


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Inside, SIGINT/SIGTERM only set the flag (never raise inside compiled numba code, where an
    exception from a signal handler surfaces as ``SystemError``); the code inside calls
    :func:`check_interrupted` between blocks. On leaving, a recorded signal is raised."""
    _defer[0] += 1
    try:
        yield
    finally:
        _defer[0] -= 1
    check_interrupted()


_exit_code: list[int] = [0]  # the code the entry point exits with (final_signal_check)


def exit_with(code: int) -> NoReturn:
    """The entry point's exit: ``code``, read again by :func:`final_signal_check` during the
    interpreter's shutdown."""
    _exit_code[0] = code
    sys.exit(code)


def final_signal_check() -> None:
    """The process's last look at SIGINT/SIGTERM (an ``atexit`` function the entry point registers
    first, so it runs after every other one a command registered: the cluster's, the thread
    pools'): a signal that arrived after the entry point's own check — during the interpreter's
    shutdown, with the signals blocked — would be dropped at the exit and the command would exit 0.
    It ends the process with 128 + signal instead (the folder's files are complete, marked as in
    :func:`late_interrupt`). What remains is the interpreter's last module clean-up after this."""
    if _exit_code[0] >= 128:
        return
    pending: set[int] = set()
    with contextlib.suppress(AttributeError, OSError, ValueError):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        pending = {int(s) for s in signal.sigpending()}
    sig = first_signal() or (min(pending) if pending else None)
    if sig is None:
        return
    with contextlib.suppress(Exception):
        late_interrupt(sig)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            if stream is not None:
                stream.flush()
    os._exit(128 + sig)


def record_signals_only() -> None:
    """From now on the handlers record signals and raise nothing (the entry point's last steps)."""
    _raised[0] = True


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM are recorded (and raise :class:`Interrupted` outside deferred regions)
    for the rest of the process: the entry point calls this first, so an interrupt at any moment
    ends with 128 + signal."""
    for s in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError):  # not the main thread
            signal.signal(s, _handler)


@contextlib.contextmanager
def handle_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` (once; later signals are recorded only,
    so clean-up is not cut short; inside :func:`deferred_interrupts` they are only recorded) and
    are remembered for :func:`check_interrupted`."""
    _pending.clear()
    _raised[0] = False
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        _pending.clear()


def _as_interrupt(err: BaseException) -> Interrupted | None:
    """The interrupt behind ``err``: itself, or — when a signal is pending — whatever the
    signal broke on its way (e.g. a ``SystemError`` from a library that got the exception)."""
    if isinstance(err, Interrupted):
        return err
    if isinstance(err, KeyboardInterrupt):  # Python's own SIGINT handler was in place
        return Interrupted(signal.SIGINT)
    sig = pending_signal()
    return Interrupted(sig) if sig is not None else None


def _quiet_broken_stdout(err: OSError) -> None:
    """After EPIPE/ENOSPC on stdout, point it at /dev/null so the interpreter's final flush does
    not print a second error."""
    if err.errno in (errno.EPIPE, errno.ENOSPC, errno.EIO, errno.EBADF):
        with contextlib.suppress(Exception):
            sys.stdout.flush()
        with contextlib.suppress(Exception):
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, sys.stdout.fileno())
            os.close(fd)


def _output_problem(err: OSError) -> str:
    name = f" {err.filename}" if getattr(err, "filename", None) else ""
    if not name:  # rich and print name no file: stdout (or a file whose name got lost)
        name = " (to stdout or an output file)"
    what = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
            errno.EPIPE: "the output was closed (broken pipe)",
            errno.ENAMETOOLONG: "a file name is too long", errno.EROFS: "read-only file system",
            errno.EACCES: "permission denied"}.get(err.errno or -1, err.strerror or str(err))
    return f"cannot write{name}: {what}"


_guarded_out: list[Path] = []


def out_of_memory(err: BaseException) -> str:
    """One line for a failed allocation (``MemoryError``: numpy, numba, Python itself)."""
    detail = " ".join(str(err).split())[:200]
    return ("out of memory" + (f" ({detail})" if detail else "")
            + ": free memory, shorten the run (--duration) or use fewer --workers")


def _extra_hint(err: BaseException) -> str | None:
    """The install line when ``err`` is a missing optional dependency (tsmpc.extras), else None."""
    from tsmpc.extras import MissingExtraError, from_import_error

    if isinstance(err, MissingExtraError):
        return str(err)
    return from_import_error(err) if isinstance(err, ImportError) else None


def late_interrupt(signum: int) -> None:
    """A signal that arrived after the guarded work had finished (its PARTIAL removed): the
    process exits 128 + signal all the same, so the folder says so too — its files are complete
    (the entry point calls this)."""
    # A folder removed since (a sweep's empty folder on interrupt) is not made again.
    if _guarded_out and _guarded_out[-1].is_dir() and not (_guarded_out[-1] / PARTIAL_MARKER).exists():
        mark_partial(_guarded_out[-1], "interrupted", signal=signal.Signals(signum).name,
                     after="the run had finished when the signal arrived: its files are complete")


@contextlib.contextmanager
def guarded_run(out: Path, *, what: str = "run", on_interrupt: str | None = None) -> Iterator[None]:
    """The work that fills the output folder ``out``: every way it can end that is not success
    ends with one line on stderr, a non-zero exit and the PARTIAL marker saying why.

    * SIGINT/SIGTERM (or any error while one is pending): PARTIAL ``interrupted``, exit 128 + signal;
    * :class:`~tsmpc.errors.DesignError` (no LMI design for this config): PARTIAL ``failed``, exit 2;
    * another :class:`TsmpcError`: PARTIAL ``failed``, exit 1;
    * ``OSError`` (disk full, name too long, stdout closed or full): PARTIAL ``failed``, exit 1;
    * ``MemoryError`` (a failed allocation): PARTIAL ``failed``, exit 1, "out of memory";
    * any other exception: PARTIAL ``failed``, exit 1, the exception's one-line summary
      (``TSMPC_DEBUG=1`` re-raises it, with its traceback).
    """
    _guarded_out.append(out)
    with handle_interrupts():
        try:
            yield
        except typer.Exit:
            raise
        except BaseException as err:
            sig = _as_interrupt(err)
            if sig is not None:
                mark_partial(out, "interrupted", signal=str(sig))
                hint = on_interrupt or f"{out} holds a partial {what} (see {out / PARTIAL_MARKER})"
                with contextlib.suppress(OSError, ValueError):
                    typer.secho(_bounded(f"interrupted ({sig}): {hint}"), err=True,
                                fg=typer.colors.RED)
                raise typer.Exit(sig.code) from None
            if isinstance(err, SystemExit) and err.code not in (0, None):
                # rich ends the program with SystemExit(1) when stdout is closed (broken pipe)
                msg = f"{what} failed: the output was closed (broken pipe)"
                mark_partial(out, "failed", reason=msg)
                fail(f"{msg} ({out} is incomplete, see {out / PARTIAL_MARKER})", EXIT_FAILED)
            if not isinstance(err, Exception):  # GeneratorExit, SystemExit(0): not ours to map
                raise
            extra = _extra_hint(err)
            if extra is not None:  # an optional dependency is missing: the extra that brings it
                mark_partial(out, "failed", reason=extra)
                fail(extra, EXIT_INVALID)
            if isinstance(err, DesignError):
                mark_partial(out, "failed", reason=str(err))
                fail(err, EXIT_INVALID)
            if isinstance(err, TsmpcError):
                mark_partial(out, "failed", reason=str(err))
                fail(err, EXIT_FAILED)
            if isinstance(err, MemoryError):  # numpy's _ArrayMemoryError too: no traceback
                msg = f"{what} failed: {out_of_memory(err)}"
                mark_partial(out, "failed", reason=msg)
                fail(f"{msg} ({out} is incomplete, see {out / PARTIAL_MARKER})", EXIT_FAILED)
            if isinstance(err, OSError):
                msg = f"{what} failed: {_output_problem(err)}"
                _quiet_broken_stdout(err)
                mark_partial(out, "failed", reason=msg)
                fail(f"{msg} ({out} is incomplete, see {out / PARTIAL_MARKER})", EXIT_FAILED)
            if os.environ.get("TSMPC_DEBUG"):
                raise
            msg = f"{what} failed: internal error {type(err).__name__}: {err}"
            mark_partial(out, "failed", reason=msg)
            fail(f"{msg} (please report it; TSMPC_DEBUG=1 shows the traceback)", EXIT_FAILED)


# -- status while designs are solved -------------------------------------------------------
def solve_design(kind: str, fn: Callable[[Config], Any], cfg: Config) -> Any:
    """``fn(cfg)`` (a ``load_or_design_*``); any exception it raises — the solver's own
    (``cvxpy.error.SolverError``, ``ValueError: Problem data contains NaN or Inf``) or tsmpc's —
    becomes :class:`~tsmpc.errors.DesignError` naming the likely field (a signal that broke it
    stays an interrupt)."""
    from tsmpc.diagnose import explain_design_failure

    try:
        return fn(cfg)
    except Exception as err:
        sig = pending_signal()
        if sig is not None:
            raise Interrupted(sig) from None
        raise DesignError(explain_design_failure(kind, cfg, err)) from None


def design_status(cfg: Config) -> tuple[Any, Any]:
    """Load or solve the kinematic and dynamic LMI designs of ``cfg``, one status line on stderr
    before ("solving…") and one after the certificates hold ("certified … margin …"). No design
    for this config — whatever the solver raised — is a :class:`~tsmpc.errors.DesignError`
    naming the field most likely responsible (:func:`tsmpc.diagnose.explain_design_failure`)."""
    from rich.console import Console

    from tsmpc.sim.experiment import solve_designs

    console = Console(stderr=True, highlight=False, soft_wrap=True)
    try:
        return solve_designs(cfg, lambda text: console.print(text, markup=False))
    except Exception:
        sig = pending_signal()  # a signal that broke the solver stays an interrupt
        if sig is not None:
            raise Interrupted(sig) from None
        raise
