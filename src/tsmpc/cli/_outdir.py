"""Default output folders: a run without ``--out`` never writes into another run's folder.

``tsmpc compare`` writes into ``results/compare`` when that folder does not exist yet, else into
the first ``results/compare-N`` (N = 2, 3, …) that does not exist; ``tsmpc run`` and
``tsmpc sweep`` likewise under ``results/run`` and ``results/sweep``. The folder is claimed by
creating it (an atomic ``mkdir``), so two runs started at the same time get two folders. Every
command prints the folder it wrote at the end.

A given ``--out`` that holds the *complete* result of an earlier ``tsmpc compare`` / ``tsmpc run``
(nothing but tsmpc's output files, ``metrics.json`` among them, no ``PARTIAL`` marker) is moved
aside before the new run, never deleted (:func:`move_aside`): to ``OUT.prev``, or the first free
``OUT.prev-N`` (N = 2, 3, …) when that exists, so the quick start can be run twice as written and
every earlier result is kept. Any other non-empty folder is refused (docs/outputs.md).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["claim_default_out", "move_aside"]

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


def move_aside(out: Path, limit: int = 10_000) -> Path:
    """Rename the folder ``out`` to ``OUT.prev`` or the first free ``OUT.prev-N``; returns the new
    name. ``os.rename`` never replaces a non-empty folder, so two runs racing for a name cannot
    lose either's files (the loser tries the next name)."""
    for n in range(1, limit + 1):
        target = out.with_name(f"{out.name}.prev" if n == 1 else f"{out.name}.prev-{n}")
        if target.exists() and (not target.is_dir() or any(target.iterdir())):
            continue
        try:
            os.rename(out, target)
        except OSError as err:
            if target.exists():  # taken in the meantime: the next name
                continue
            raise err
        return target
    raise FileExistsError(f"{out}: {limit} folders named {out.name}.prev-N exist; remove old ones")
