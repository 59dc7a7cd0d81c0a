"""Default output folders: a run without ``--out`` never writes into another run's folder.

``tsmpc compare`` writes into ``results/compare`` when that folder does not exist yet, else into
the first ``results/compare-N`` (N = 2, 3, …) that does not exist; ``tsmpc run`` and
``tsmpc sweep`` likewise under ``results/run`` and ``results/sweep``. The folder is claimed by
creating it (an atomic ``mkdir``), so two runs started at the same time get two folders. Every
command prints the folder it wrote at the end.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["claim_default_out"]

#: Where default output folders go, relative to the working directory.
RESULTS = Path("results")


def claim_default_out(command: str, root: Path = RESULTS, limit: int = 10_000) -> Path:
    """Create and return a new folder ``root/command`` or ``root/command-N`` (the first free N)."""
    root.mkdir(parents=True, exist_ok=True)
    for n in range(1, limit + 1):
        path = root / (command if n == 1 else f"{command}-{n}")
        try:
            os.mkdir(path)
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"{root}: {limit} folders named {command}-N exist; pass --out")
