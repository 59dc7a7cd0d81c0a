"""Shared fixtures: the paper config and the location of ../shared data."""

from __future__ import annotations

from pathlib import Path

import pytest

from tsmpc.config import Config

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAPER_REFERENCE = SHARED / "data" / "paper" / "planner_references_100ms.csv"
TRACKS_DIR = SHARED / "data" / "tracks"


@pytest.fixture(scope="session")
def cfg() -> Config:
    return Config()


@pytest.fixture(scope="session")
def paper_reference_path() -> Path:
    if not PAPER_REFERENCE.exists():
        pytest.skip(f"paper reference not found at {PAPER_REFERENCE}")
    return PAPER_REFERENCE


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    if not TRACKS_DIR.is_dir():
        pytest.skip(f"tracks not found at {TRACKS_DIR}")
    return TRACKS_DIR
