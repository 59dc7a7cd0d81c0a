"""The ``tsmpc`` console script: the command line needs the ``[cli]`` extra (typer, rich); on a
core install it prints the one line that installs it and exits 2 instead of a traceback."""

from __future__ import annotations

import sys


def main() -> None:
    """Run :func:`tsmpc.cli.main`, or say which extra the command line needs (exit 2)."""
    from tsmpc.extras import is_available, missing_message

    for module in ("typer", "rich"):
        if not is_available(module):
            sys.stderr.write(f"error: {missing_message(module, 'the tsmpc command')}\n")
            sys.exit(2)
    from tsmpc.cli import main as cli_main

    cli_main()


if __name__ == "__main__":
    main()
