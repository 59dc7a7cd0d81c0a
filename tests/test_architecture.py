"""Architecture rules (issue 14 item 8): one Method enum, the runtime protocol, typed metrics, no
import circles, no plotting in core modules, synthesis independent of the simulator."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tsmpc.config import Config, Method, SchedulingMode, load_config, replace
from tsmpc.control.cascade import Cascade
from tsmpc.control.ts_mpc import MPCStatus, shifted_plan
from tsmpc.errors import ConfigError
from tsmpc.planning.circuit import builtin_circuit
from tsmpc.runtime import RuntimeBlock
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import (
    compute_metrics,
    errors_from_arrays,
    run_metrics,
    tracking_errors,
    tracking_metrics,
)
from tsmpc.sim.simulator import simulate

SRC = Path(__file__).resolve().parents[1] / "src" / "tsmpc"


def test_method_and_scheduling_mode_are_one_enum(tmp_path: Path) -> None:
    assert SchedulingMode is Method
    assert Method("ref") is Method.REF and Method.parse(" Iter ") is Method.ITER
    with pytest.raises(ConfigError, match="allowed: fzn, ref, iter, nl"):
        Method.parse("mpc")
    p = tmp_path / "c.toml"
    p.write_text("[mpc]\nmode = 'fzn'\n")
    assert load_config(p).mpc.mode is Method.FZN  # old lower-case configs load
    p.write_text("[mpc]\nmode = 'nl'\n")
    with pytest.raises(ConfigError, match=r"mpc\.mode: .*fzn, ref or iter"):
        load_config(p)
    cfg = replace(Config(), mpc=replace(Config().mpc, mode="iter"))
    assert load_config(_toml(tmp_path, cfg)) == cfg


def _toml(tmp_path: Path, cfg: Config) -> Path:
    p = tmp_path / "round.toml"
    p.write_text(cfg.to_toml())
    return p


def test_every_online_block_has_dt_and_reset(cfg: Config) -> None:
    cas = Cascade(cfg, Method.REF, builtin_circuit(dt=cfg.rates.Tc))
    for block, dt in ((cas, cfg.rates.Td), (cas.mpc, cfg.rates.Tc), (cas.mhe, cfg.rates.Td),
                      (cas.lqr, cfg.rates.Td)):
        assert isinstance(block, RuntimeBlock) and block.dt == dt, type(block).__name__


def test_shared_fallback_holds_or_shifts() -> None:
    up, x0 = np.array([5.0, 0.1]), np.array([0.1, np.nan, 0.0])
    r = shifted_plan(None, x0, up, 4, 0.0, 1, 2, 3)
    assert r.status == MPCStatus.FALLBACK and np.all(r.u_pred == up) and np.all(np.isfinite(r.x_pred))
    r2 = shifted_plan(r, x0, up, 4, 0.0, 0, 0, 0)
    assert r2.u_pred.shape == (4, 2) and np.all(r2.du == 0.0)


def test_metrics_are_typed_and_computable_from_plain_arrays(cfg: Config) -> None:
    log = simulate(cfg, Method.REF, load_scenario(cfg), max_steps=40)
    m = run_metrics(log)
    d = m.to_dict()
    assert d == compute_metrics(log)  # the dict form is the typed result's

    def rms(a: np.ndarray) -> float:  # the numbers are the run's, recomputed from the raw arrays
        return float(np.sqrt(np.mean(np.square(a))))

    e = log.errors
    expected = {"x": rms(e[:, 0]), "y": rms(e[:, 1]), "theta": rms(e[:, 2]),
                "v": rms(log.ref[:, 3] - log.state_outer[:, 3]),
                "omega": rms(log.ref[:, 4] - log.state_outer[:, 5])}
    for k, v in expected.items():
        assert d["rmse"][k] == pytest.approx(v, rel=1e-12, abs=1e-15), k
        assert getattr(m.tracking.rmse, k) == d["rmse"][k]
    assert d["max_abs_lateral_m"] == pytest.approx(float(np.max(np.abs(e[:, 1]))), rel=1e-12)
    assert d["mpc_ms"]["median"] == pytest.approx(1e3 * float(np.median(log.mpc_time_s)), rel=1e-12)
    assert d["outer_steps"] == log.n_outer == 40
    ref_e = tracking_errors(log)
    arr_e = errors_from_arrays(log.state_outer, log.ref)
    for k in ref_e:
        np.testing.assert_allclose(arr_e[k], ref_e[k], rtol=0, atol=1e-12)
    assert tracking_metrics(log.state_outer, log.ref) == m.tracking


def _module(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported_names(path: Path, name: str) -> set[str]:
    """Every name ``path`` (module ``name``) imports, anywhere in it — module level, inside
    functions and methods, under ``if TYPE_CHECKING`` — with relative imports resolved, plus the
    string literals given to ``importlib.import_module``. ``from a.b import c`` yields both
    ``a.b`` and ``a.b.c`` (c may be a submodule)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # from .x import y / from .. import z
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, *([node.module] if node.module else [])])
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) or getattr(node.func, "id", None)) == "import_module"):
            out.add(node.args[0].value)
    return {m for m in out if m == "tsmpc" or m.startswith("tsmpc.")}


def _graph() -> dict[str, set[str]]:
    """Module → the package's modules it imports (a name that is not a module resolves to the
    module defining it: ``from tsmpc.x import y`` → ``tsmpc.x``)."""
    mods = {_module(p): p for p in SRC.rglob("*.py")}
    g: dict[str, set[str]] = {}
    for name, p in mods.items():
        deps = set()
        for d in _imported_names(p, name):
            while d not in mods and "." in d:
                d = d.rsplit(".", 1)[0]
            if d in mods and d != name:
                deps.add(d)
        g[name] = deps
    return g


def _circles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``g`` with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for root in sorted(g):
        if root in index:
            continue
        work = [(root, iter(sorted(g[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(g[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_circle_finder_sees_function_local_relative_and_importlib_imports(tmp_path: Path) -> None:
    """The finder itself, on a scratch package: a circle closed only by an import inside a
    function, a relative import and an ``importlib.import_module`` literal are all found."""
    pkg = tmp_path / "tsmpc"
    (pkg / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "a.py": "def f():\n    from tsmpc.sub import b\n",
        "sub/__init__.py": "",
        "sub/b.py": "from . import c\n",
        "sub/c.py": "import importlib\nclass K:\n    def m(self):\n"
                    "        return importlib.import_module('tsmpc.a')\n",
        "d.py": "from tsmpc.a import f\n",
    }
    for rel, text in files.items():
        (pkg / rel).write_text(text, encoding="utf-8")
    g = {_module_in(p, tmp_path): set() for p in pkg.rglob("*.py")}
    for p in pkg.rglob("*.py"):
        name = _module_in(p, tmp_path)
        for d in _imported_names(p, name):
            while d not in g and "." in d:
                d = d.rsplit(".", 1)[0]
            if d != name:
                g[name].add(d)
    assert _circles(g) == [["tsmpc.a", "tsmpc.sub.b", "tsmpc.sub.c"]]


def _module_in(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_no_import_circle() -> None:
    """No two modules of the package import each other, directly or through others, counting the
    imports inside functions (a function-local import hides a circle, it does not remove it)."""
    circles = _circles(_graph())
    assert not circles, "import circles (strongly connected components):\n" + "\n".join(
        " <-> ".join(c) for c in circles)


def test_layering_sweep_plots_synthesis() -> None:
    full = _graph()
    assert "tsmpc.sweep" not in full["tsmpc.report.sweep_plots"]
    for name, deps in full.items():
        if name.startswith("tsmpc.synthesis"):
            assert not any(d.startswith("tsmpc.sim") for d in deps), (name, deps)


def test_core_modules_do_not_import_matplotlib() -> None:
    code = ("import sys, tsmpc.sim.compare, tsmpc.sweep, tsmpc.sim.simulator, tsmpc.control.cascade, "
            "tsmpc.robustness; print('matplotlib' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={"PYTHONPATH": str(SRC.parent), "PATH": ""})
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


#: No function in src/ is longer than this many lines (its ``def`` to its last line; issue 34).
MAX_FUNCTION_LINES = 100

#: The numeric kernels allowed past it: numba nopython arithmetic over flat arrays, where a split
#: costs a call per inner step or per lane and the operations' order is the bit-identity contract.
#: Each entry must still be over the limit (a stale entry fails the test).
LONG_KERNELS: set[str] = set()  # (the engine's run() is within it since its phases are functions)


def _function_lengths(root: Path) -> dict[str, int]:
    """``path::qualname`` -> lines from ``def`` to the last line, for every function (methods and
    nested functions included) of every module under ``root``."""
    out: dict[str, int] = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        todo: list[tuple[ast.AST, str]] = [(ast.parse(path.read_text(encoding="utf-8")), "")]
        while todo:
            node, prefix = todo.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                    name = prefix + child.name
                    if not isinstance(child, ast.ClassDef):
                        out[f"{rel}::{name}"] = (child.end_lineno or child.lineno) - child.lineno + 1
                    todo.append((child, name + "."))
                else:
                    todo.append((child, prefix))
    return out


def test_function_length_finder(tmp_path: Path) -> None:
    (tmp_path / "m.py").write_text("class C:\n    def f(self):\n        def g():\n            pass\n"
                                   "        return 1\n\n\nif True:\n    async def h():\n        x = 1\n"
                                   "        return x\n")
    assert _function_lengths(tmp_path) == {"m.py::C.f": 4, "m.py::C.f.g": 2, "m.py::h": 3}


def test_no_function_over_100_lines_outside_the_numeric_kernels() -> None:
    lengths = _function_lengths(SRC)
    long = {name: n for name, n in lengths.items() if n > MAX_FUNCTION_LINES}
    assert set(long) <= LONG_KERNELS, {n: long[n] for n in sorted(set(long) - LONG_KERNELS)}
    stale = sorted(LONG_KERNELS - set(long))  # gone, or within the limit now: drop it from the list
    assert not stale, {n: lengths.get(n, "no such function") for n in stale}


def test_the_cascade_step_reads_as_the_block_diagram() -> None:
    """``Cascade._step`` (the body of ``Cascade.step``) is at most 40 lines and reads no config
    switch: the mechanisms it runs are the blocks composed at construction (issue 34)."""
    tree = ast.parse((SRC / "control" / "cascade.py").read_text(encoding="utf-8"))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Cascade")
    step = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "_step")
    assert step.end_lineno is not None and step.end_lineno - step.lineno + 1 <= 40
    switches = [ast.unparse(n) for n in ast.walk(step)
                if isinstance(n, ast.Attribute) and n.attr in ("cfg", "any_course", "settings")]
    assert not switches, switches
