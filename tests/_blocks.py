"""A module's blocks as Python or compiled (a plain njit of the same source, as the engine
compiles them), for the tests that check both ways answer alike."""

from __future__ import annotations

from types import ModuleType
from typing import Any

import pytest

_COMPILED: dict[tuple[str, str], Any] = {}


def compiled(fn: Any) -> Any:
    """``fn`` compiled once per test process (numba's own cache is off: a test compiles the source
    it sees)."""
    key = (fn.__module__, fn.__qualname__)
    if key not in _COMPILED:
        from numba import njit

        _COMPILED[key] = njit(cache=False)(fn)
    return _COMPILED[key]


class Blocks:
    """The functions ``names`` of ``module``, as attributes, each Python or compiled."""

    def __init__(self, module: ModuleType, names: tuple[str, ...], compile_them: bool) -> None:
        for name in names:
            fn = getattr(module, name)
            setattr(self, name, compiled(fn) if compile_them else fn)

    def __getattr__(self, name: str) -> Any:  # (for the type checkers: the blocks are set above)
        raise AttributeError(name)


@pytest.fixture(params=["python", "compiled"])
def way(request: pytest.FixtureRequest) -> Any:
    """A block as its Python caller runs it (``TSMPC_NO_JIT`` or a Python class) or compiled, as the
    engine runs it: ``way(fn)``. Import it into a test module to parametrise its tests both ways."""
    if request.param == "python":
        return lambda fn: fn
    from tsmpc import kernels

    if kernels.load("plant") is None:
        pytest.skip("compiled kernels unavailable")
    return compiled
