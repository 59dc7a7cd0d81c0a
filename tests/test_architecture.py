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


def _imports(path: Path, top_level_only: bool) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    out: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.startswith("tsmpc")}


def _module(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph(top_level_only: bool) -> dict[str, set[str]]:
    mods = {_module(p): p for p in SRC.rglob("*.py")}
    g = {}
    for name, p in mods.items():
        deps = set()
        for d in _imports(p, top_level_only):
            while d not in mods and "." in d:  # `from tsmpc.x import y` where y is a name
                d = d.rsplit(".", 1)[0]
            if d in mods and d != name and not d.startswith("tsmpc.cli") and d != "tsmpc":
                deps.add(d)
        g[name] = deps
    return g


def test_no_import_circle_at_module_level() -> None:
    g = _graph(top_level_only=True)
    state: dict[str, int] = {}

    def visit(n: str, path: list[str]) -> None:
        state[n] = 1
        for d in g.get(n, ()):
            if state.get(d) == 1:
                pytest.fail("import circle: " + " -> ".join([*path[path.index(d):], d]))
            if d not in state:
                visit(d, [*path, d])
        state[n] = 2

    for n in g:
        if n not in state:
            visit(n, [n])


def test_layering_sweep_plots_synthesis() -> None:
    full = _graph(top_level_only=False)
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
