"""The curated public API (issue 34 item 4): each subpackage re-exports what users import, the
type checkers see the same names as the runtime, and importing a subpackage stays cheap."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import tsmpc

SRC = Path(tsmpc.__file__).resolve().parent
#: The subpackages with a curated ``__all__`` (tsmpc.kernels is implementation; tsmpc.cli is the shell).
CURATED = sorted(p.parent.name for p in SRC.glob("*/__init__.py")
                 if "lazy_exports(" in p.read_text(encoding="utf-8"))
#: Loaded on first use only: a deployment imports the controllers without them.
HEAVY = ("numba", "cvxpy", "matplotlib", "casadi", "dask", "pandas", "scipy")


def _type_checking_imports(pkg: str) -> dict[str, str]:
    """name → submodule, from the ``if TYPE_CHECKING:`` imports of ``pkg``'s ``__init__``."""
    tree = ast.parse((SRC / pkg / "__init__.py").read_text(encoding="utf-8"))
    out: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom) and imp.module, ast.dump(imp)
                prefix = f"tsmpc.{pkg}."
                assert imp.module.startswith(prefix), imp.module
                for a in imp.names:
                    assert a.asname is None, a.asname
                    out[a.name] = imp.module.removeprefix(prefix)
    return out


def test_every_subpackage_but_the_kernels_and_the_shell_is_curated() -> None:
    assert set(CURATED) == {"control", "estimation", "models", "planning", "report", "sim", "synthesis",
                            "vehicle"}


@pytest.mark.parametrize("pkg", CURATED)
def test_all_the_table_and_the_type_checkers_view_agree(pkg: str) -> None:
    mod = importlib.import_module(f"tsmpc.{pkg}")
    table = mod._EXPORTS
    assert sorted(mod.__all__) == sorted(table), "__all__ and _EXPORTS differ"
    # a submodule's import binds its name in the package, over a re-exported function of that name
    clash = {n for n in table if (SRC / pkg / f"{n}.py").exists()}
    assert not clash, f"re-exported names that are also submodules of tsmpc.{pkg}: {clash}"
    assert len(set(mod.__all__)) == len(mod.__all__), "a name twice in __all__"
    assert _type_checking_imports(pkg) == table, "the TYPE_CHECKING imports and _EXPORTS differ"


@pytest.mark.parametrize("pkg", CURATED)
def test_every_exported_name_is_the_submodules_own_and_documented(pkg: str) -> None:
    mod = importlib.import_module(f"tsmpc.{pkg}")
    for name in mod.__all__:
        sub = importlib.import_module(f"tsmpc.{pkg}.{mod._EXPORTS[name]}")
        value = getattr(mod, name)
        assert value is getattr(sub, name), name
        assert name in getattr(sub, "__all__", [name]), f"{sub.__name__} does not list {name} in __all__"
        if callable(value) and not name.isupper():
            assert (value.__doc__ or "").strip(), f"tsmpc.{pkg}.{name} has no docstring"
    assert set(mod.__all__) <= set(dir(mod))
    with pytest.raises(AttributeError, match=f"tsmpc.{pkg}' has no attribute 'no_such_name'"):
        mod.no_such_name  # noqa: B018


def test_importing_the_subpackages_loads_no_heavy_dependency_until_a_name_is_used() -> None:
    code = ("import sys\n"
            f"import {', '.join(f'tsmpc.{p}' for p in CURATED)}\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
            "from tsmpc.models import KinematicTS\n"
            "print('tsmpc.models.kinematic' in sys.modules, 'tsmpc.models.dynamic' in sys.modules)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    loaded, lazily = res.stdout.splitlines()
    assert loaded == "[]", f"importing the subpackages loaded {loaded}"
    assert lazily == "True False", "a name should load its own submodule and no other"
