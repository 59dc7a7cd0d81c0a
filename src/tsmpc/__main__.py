"""``python -m tsmpc`` runs the command-line interface."""

from tsmpc.cli import app

app()
