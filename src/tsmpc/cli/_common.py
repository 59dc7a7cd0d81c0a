"""Helpers shared by the CLI commands: config loading, error reporting, output-folder checks,
interrupts and the status line shown while LMI designs are solved.

Exit codes (README "Exit codes"): 0 done, 1 a run diverged or failed, 2 invalid input (reported
before any work starts), 128 + signal number when interrupted (130 SIGINT, 143 SIGTERM).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import typer

from tsmpc.config import Config, load_config
from tsmpc.errors import ConfigError, TsmpcError

__all__ = [
    "EXIT_INVALID",
    "PARTIAL_MARKER",
    "Interrupted",
    "check_interrupted",
    "check_out_dir",
    "check_out_file",
    "design_status",
    "fail",
    "finite",
    "handle_interrupts",
    "load_config_or_exit",
    "mark_partial",
]

#: Exit code of invalid input (configs, files, option values).
EXIT_INVALID = 2
#: File left in an output folder whose run did not finish (interrupted or in progress).
PARTIAL_MARKER = "PARTIAL"


def fail(err: Exception | str, code: int = EXIT_INVALID) -> None:
    """Print one error line on stderr and exit with ``code``."""
    text = " ".join(str(err).split("\n")) if code == EXIT_INVALID else str(err)
    typer.secho(f"error: {text}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code)


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


# -- output locations ----------------------------------------------------------------------
def _probe_writable(folder: Path, option: str) -> None:
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tsmpc-probe-")
        os.close(fd)
        os.unlink(tmp)
    except OSError as err:
        fail(ConfigError(f"{option} {folder}: cannot write there ({err.strerror or err})"))


def _check_parents(path: Path, option: str) -> Path:
    """The nearest existing ancestor of ``path`` (exits if an ancestor is a file)."""
    anc = path.absolute()
    for parent in [anc, *anc.parents]:
        if parent.exists():
            if not parent.is_dir() and parent != anc:
                fail(ConfigError(f"{option} {path}: {parent} is a file, not a folder"))
            return parent
    return Path("/")


def check_out_dir(out: Path, *, overwrite: bool, option: str = "--out") -> None:
    """Before any work: ``out`` must be a folder we can create and write, and empty unless
    ``overwrite`` (then tsmpc's outputs of a previous run in it are removed, nothing else).
    Exits with code 2 naming the problem."""
    _check_parents(out, option)
    if out.exists() and not out.is_dir():
        fail(ConfigError(f"{option} {out}: exists and is a file; give a folder"))
    if out.is_dir():
        entries = [p for p in out.iterdir() if not p.name.startswith(".tsmpc-probe-")]
        if entries and not overwrite:
            fail(ConfigError(f"{option} {out}: folder is not empty ({len(entries)} entries); choose "
                             "another folder or pass --overwrite to replace tsmpc's outputs in it"))
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
    """Write (or update) the PARTIAL marker of an unfinished run in ``out``."""
    from tsmpc.sim.log import atomic_write_text

    body = {"status": status, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **info,
            "note": "this folder holds an unfinished tsmpc run: its files are incomplete"}
    with contextlib.suppress(OSError):
        atomic_write_text(out / PARTIAL_MARKER, json.dumps(body, indent=1) + "\n")


# -- interrupts ----------------------------------------------------------------------------
class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (not an error: a request to stop). ``code`` = 128 + signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.code = 128 + signum


_pending: list[int] = []


def _handler(signum: int, _frame: Any) -> None:
    first = not _pending
    _pending.append(signum)
    if first:
        raise Interrupted(signum)


def check_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal arrived that a solver swallowed (CasADi/IPOPT
    catch SIGINT during a solve and return a failed status): called after every MPC step."""
    if _pending:
        raise Interrupted(_pending[0])


@contextlib.contextmanager
def handle_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` (once; later signals are recorded only,
    so clean-up is not cut short) and are remembered for :func:`check_interrupted`."""
    _pending.clear()
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        _pending.clear()


# -- status while designs are solved -------------------------------------------------------
def design_status(cfg: Config) -> tuple[Any, Any]:
    """Load or solve the kinematic and dynamic LMI designs of ``cfg``, one status line on stderr
    before ("solving…") and one after the certificates hold ("certified … margin …")."""
    from rich.console import Console

    from tsmpc.sim.experiment import solve_designs

    console = Console(stderr=True, highlight=False, soft_wrap=True)
    return solve_designs(cfg, lambda text: console.print(text, markup=False))
