"""Optional dependencies: which extra of pyproject.toml brings each one, and the one-line install
hint printed when a feature needs one that is missing.

The core install (``pip install -e .``) is what a deployment needs: the models, the LMI designs,
the controllers, the estimators, the planner and :class:`tsmpc.control.cascade.Cascade`. Each
optional dependency is imported inside the function that needs it (or at the top of a module
only its feature imports), so the core never loads it. tsmpc is installed from a checkout (it is
not on a package index), so every hint says ``pip install -e ".[EXTRA]"``, run in the checkout.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from tsmpc.errors import TsmpcError

__all__ = ["EXTRAS", "MissingExtraError", "from_import_error", "install_hint", "is_available",
           "missing_message", "require"]

#: Top-level module -> (pip package, extra of pyproject.toml that installs it).
EXTRAS: dict[str, tuple[str, str]] = {
    "typer": ("typer", "cli"),
    "rich": ("rich", "cli"),
    "casadi": ("casadi", "nl"),
    "dask": ("dask[distributed]", "sweep"),
    "distributed": ("dask[distributed]", "sweep"),
    "pandas": ("pandas", "sweep"),
    "pyarrow": ("pyarrow", "sweep"),
    "matplotlib": ("matplotlib", "report"),
    "PIL": ("pillow", "report"),
    "imageio_ffmpeg": ("imageio-ffmpeg", "video"),
    "vehiclemodels": ("commonroad-vehicle-models", "commonroad"),
    "pooch": ("pooch", "data"),
}


class MissingExtraError(TsmpcError, ImportError):
    """A feature needs an optional dependency that is not installed; the message says which extra
    installs it (:func:`install_hint`)."""


def install_hint(extra: str) -> str:
    """The command that installs ``extra`` from a tsmpc checkout (tsmpc is not on PyPI)."""
    return f'pip install -e ".[{extra}]" in the tsmpc checkout (or ".[all]": everything a user runs)'


def missing_message(module: str, feature: str) -> str:
    """One line: ``feature`` needs ``module``, which extra brings it and how to install it."""
    top = module.split(".")[0]
    package, extra = EXTRAS.get(top, (top, "all"))
    return f"{feature} needs {package} (the [{extra}] extra): {install_hint(extra)}"


def is_available(module: str) -> bool:
    """Whether ``module`` can be imported (it is imported, so a broken install counts as missing)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def require(module: str, feature: str) -> ModuleType:
    """``module`` imported, or :class:`MissingExtraError` naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise MissingExtraError(missing_message(module, feature)) from err


def from_import_error(err: ImportError) -> str | None:
    """The install line for an ``ImportError`` of an optional dependency (its ``name``), or None
    when the missing module is not one of :data:`EXTRAS` (a bug, not a missing extra)."""
    name = getattr(err, "name", None) or ""
    if name.split(".")[0] not in EXTRAS:
        return None
    return missing_message(name, "this command")
