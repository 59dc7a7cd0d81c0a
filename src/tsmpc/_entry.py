"""The ``tsmpc`` console script: the command line needs the ``[cli]`` extra (typer, rich); on a
core install it prints the one line that installs it and exits 2 instead of a traceback."""

from __future__ import annotations

import signal
import sys


def main() -> None:
    """Run :func:`tsmpc.cli.main`, or say which extra the command line needs (exit 2).

    Until the CLI's own handlers are installed (the imports: a second or more on a cold disk), a
    SIGINT or SIGTERM ends the command with 128 + signal and no traceback, as later."""
    early: list[int] = []

    def _early_handler(signum: int, _frame: object) -> None:
        early.append(signum)
        raise KeyboardInterrupt

    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _early_handler)
    try:
        from tsmpc.extras import is_available, missing_message

        for module in ("typer", "rich"):
            if not is_available(module):
                sys.stderr.write(f"error: {missing_message(module, 'the tsmpc command')}\n")
                sys.exit(2)
        from tsmpc.cli import main as cli_main
    except KeyboardInterrupt:
        sys.exit(128 + (early[0] if early else signal.SIGINT))
    cli_main()  # (installs its own handlers first)


if __name__ == "__main__":
    main()
