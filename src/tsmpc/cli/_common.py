"""Helpers shared by the CLI commands: config loading and error reporting."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.config import Config, load_config
from tsmpc.errors import TsmpcError

__all__ = ["fail", "load_config_or_exit"]


def fail(err: Exception, code: int = 2) -> None:
    """Print an error message on stderr and exit with ``code``."""
    typer.secho(f"error: {err}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code)


def load_config_or_exit(path: Path | None, preset: str | None = None) -> Config:
    """Load the config at ``path`` (defaults if None) on top of ``preset``; a bad file or an
    unknown preset exits with a clear message."""
    try:
        return load_config(path, preset)
    except TsmpcError as err:
        fail(err)
        raise  # unreachable, for type checkers
