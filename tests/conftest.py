"""Shared fixtures: the paper config and the data the tests read.

The paper's reference and the race tracks are never bundled: :func:`_paths.need_data` finds them
with tsmpc's resolver (``$TSMPC_DATA_DIR``, the cache filled by ``tsmpc data fetch``, then
``../shared/data`` beside the checkout). A test whose data is missing SKIPS, its reason naming the
fetch command; with ``TSMPC_REQUIRE_DATA=1`` (CI, which has ../shared) it FAILS instead, so CI
cannot go green by skipping.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from _paths import need_data, tooling_on_path
from tsmpc.config import Config

tooling_on_path()  # the docs generator and the Table 5 study (docs/generator) for the tests


@pytest.fixture(scope="session")
def cfg() -> Config:
    return Config()


@pytest.fixture(scope="session")
def paper_reference_path() -> Path:
    return need_data("paper")


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    return need_data("tracks")
