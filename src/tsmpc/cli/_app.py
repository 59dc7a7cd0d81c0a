"""The typer application the commands register on (its own module, so the command modules
import it without importing the package that imports them)."""

from __future__ import annotations

import typer

from tsmpc import __version__

app = typer.Typer(
    name="tsmpc",
    help="TS-MPC trajectory tracking for autonomous vehicles (Alcalá, Puig, Quevedo).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # Help texts carry units in brackets ("[m/s]"): not rich markup.
    rich_markup_mode=None,
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"tsmpc {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version."
    ),
) -> None:
    """TS-MPC trajectory tracking for autonomous vehicles."""
    from tsmpc.cli._common import safe_stdio

    safe_stdio()  # a closed stdout is refused here, before any work (exit 2)


__all__ = ["app"]
