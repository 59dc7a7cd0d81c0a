"""Lazy re-exports of a subpackage's public names (PEP 562).

Each subpackage's ``__init__`` lists what users import from it, name → defining submodule, and
imports the submodule only when a name is first read: ``import tsmpc.control`` stays as cheap as
``import tsmpc`` (no numba, no solver), and a submodule never imports its package's ``__init__``
through the re-export, so the re-exports add no import circle. Type checkers and the API reference
read the same names from the ``if TYPE_CHECKING:`` imports beside the table
(``tests/test_api.py`` checks that the two agree).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str]) -> tuple[Callable[[str], Any],
                                                                     Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of ``package`` for ``exports`` (name → submodule name).

    A name is looked up in its submodule at the first access and then kept in the package's
    namespace (later reads are plain attribute reads)."""

    def __getattr__(name: str) -> Any:
        sub = exports.get(name)
        if sub is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{sub}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
