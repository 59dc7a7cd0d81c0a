"""Reference windows with closed-form geometry for the geometric baselines' tests, and where the
tests find the paper's reference and the race tracks (not a test module)."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

#: The repository's docs/ folder: the documentation generator and the Table 5 study live there
#: (package ``generator``), project tooling outside the installed package.
DOCS = Path(__file__).resolve().parents[1] / "docs"


def tooling_on_path() -> None:
    """Make the project's tooling importable: the repository's docs/ folder on ``sys.path``, so
    ``import generator.published`` (the docs generator), ``generator.blocks`` and the Table 5 study
    (``generator.paper_explained``, ``generator.paper_explained_runs``) work. Called once, by
    conftest.py."""
    if str(DOCS) not in sys.path:
        sys.path.append(str(DOCS))


def circle_window(R: float, v: float, Tc: float, n: int, *, left: bool = True,
                  tangent_convention: bool = True) -> SimpleNamespace:
    """n samples of a circle of radius R driven at speed v from the origin heading east (centre
    (0, ±R)). ``tangent_convention``: θ_d is the heading of the step *into* each sample (the paper
    planner's convention, SPEC §10; the path tangent is θ_d + ω_d T_c / 2), else the tangent itself."""
    sgn = 1.0 if left else -1.0
    ds = v * Tc
    phi = np.arange(n) * ds / R
    x, y = R * np.sin(phi), sgn * R * (1.0 - np.cos(phi))
    tangent = sgn * phi
    dphi = sgn * ds / R
    theta = tangent - 0.5 * dphi if tangent_convention else tangent
    return SimpleNamespace(x=x, y=y, theta=theta, v=np.full(n, v), omega=np.full(n, sgn * v / R),
                           kappa=np.full(n, sgn / R))


def straight_window(v: float, Tc: float, n: int) -> SimpleNamespace:
    """n samples of the x-axis driven eastwards at speed v."""
    x = np.arange(n) * v * Tc
    z = np.zeros(n)
    return SimpleNamespace(x=x, y=z.copy(), theta=z.copy(), v=np.full(n, v), omega=z.copy(), kappa=z.copy())


# -- the data the tests read (issue 37) ------------------------------------------------------
#: Set to 1 (CI, which has ../shared): a test whose data is missing FAILS instead of skipping.
REQUIRE_DATA_ENV = "TSMPC_REQUIRE_DATA"
#: The checkout's ../shared/data, searched after tsmpc's own folders (a non-editable install of
#: tsmpc does not know the checkout; the tests do).
CHECKOUT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_roots() -> list[tuple[str, Path]]:
    """tsmpc's resolver order ($TSMPC_DATA_DIR, the cache, ../shared of a checkout), then the
    tests' own checkout's ../shared/data."""
    from tsmpc import datasets

    roots = datasets.data_roots()
    if all(root != CHECKOUT_DATA for _label, root in roots):
        roots.append(("the tests' ../shared", CHECKOUT_DATA))
    return roots


def need_data(name: str) -> Path:
    """The path of dataset ``name`` (``paper``, ``tracks``, ``monza``…); when it is missing the
    test skips with the command that downloads it, or fails under ``TSMPC_REQUIRE_DATA=1``."""
    import pytest

    from tsmpc import datasets

    path = datasets.find(name, data_roots())
    if path is not None:
        return path
    where = "; ".join(f"{label} {root}" for label, root in data_roots())
    msg = f"dataset {name!r} not found (searched {where}): run `{datasets.fetch_command(name)}`"
    if os.environ.get(REQUIRE_DATA_ENV, "") not in ("", "0"):
        pytest.fail(f"{msg} ({REQUIRE_DATA_ENV} is set: missing data fails)")
    pytest.skip(msg)


def console_script(name: str) -> str:
    """The console script ``name`` of this interpreter's environment (CI may not have it on
    PATH)."""
    import pytest

    here = Path(sys.executable).parent / name
    found = str(here) if here.is_file() else shutil.which(name)
    if found is None:
        pytest.fail(f"{name!r} not found next to {sys.executable} or on PATH")
    return found
