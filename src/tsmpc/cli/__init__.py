"""Command-line interface: a thin typer shell over the library.

Each command lives in its own module of this package and calls one public library function;
this module only assembles the application.
"""

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


def _register() -> None:
    # Each module adds its commands to ``app``; heavy imports stay inside the command bodies.
    from tsmpc.cli import animate, compare, demo, design, plan, sweep, warmup  # noqa: F401


_register()

__all__ = ["app"]
