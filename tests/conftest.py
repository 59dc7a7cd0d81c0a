"""Shared fixtures: the paper config and the location of ../shared data.

The paper's reference and the race tracks live in ``../shared/data`` (never bundled). When they
are missing the tests that need them FAIL (CI must not go green by skipping them); set
``TSMPC_ALLOW_MISSING_SHARED=1`` to skip them instead on a machine without the data.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tsmpc.config import Config

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAPER_REFERENCE = SHARED / "data" / "paper" / "planner_references_100ms.csv"
TRACKS_DIR = SHARED / "data" / "tracks"
ALLOW_MISSING = os.environ.get("TSMPC_ALLOW_MISSING_SHARED", "") not in ("", "0")


def _missing(what: str, path: Path) -> None:
    msg = (f"{what} not found at {path} (the tests read ../shared/data next to the repository; "
           "set TSMPC_ALLOW_MISSING_SHARED=1 to skip these tests instead)")
    if ALLOW_MISSING:
        pytest.skip(msg)
    pytest.fail(msg)


@pytest.fixture(scope="session")
def cfg() -> Config:
    return Config()


@pytest.fixture(scope="session")
def paper_reference_path() -> Path:
    if not PAPER_REFERENCE.exists():
        _missing("paper reference", PAPER_REFERENCE)
    return PAPER_REFERENCE


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    if not TRACKS_DIR.is_dir():
        _missing("race tracks", TRACKS_DIR)
    return TRACKS_DIR
