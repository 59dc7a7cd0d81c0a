"""``python -m tsmpc`` runs the command-line interface."""

import signal
import sys

_early: list[int] = []


def _early_handler(signum: int, _frame: object) -> None:
    # Until the CLI's own handlers are installed (a fraction of a second of imports): an
    # interrupt still ends with 128 + signal, not a traceback. tsmpc._entry.main has the same
    # guard for the console script; this one is here too because it must be in place before
    # `import tsmpc` (≈ 0.3 s), which importing tsmpc._entry runs first.
    _early.append(signum)
    raise KeyboardInterrupt


for _s in (signal.SIGINT, signal.SIGTERM):
    signal.signal(_s, _early_handler)
try:
    from tsmpc._entry import main  # (says which extra to install when typer/rich are missing)
except KeyboardInterrupt:
    sys.exit(128 + (_early[0] if _early else signal.SIGINT))

main()
