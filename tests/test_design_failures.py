"""Design failure is a result, not a crash (issue 24): whatever the LMI design step raises — the
solver's own exceptions (``cvxpy.error.SolverError``, ``ValueError: Problem data contains NaN or
Inf``), tsmpc's ``SolverError``/``CertificateError``, or anything else — a command exits 2 with one
line naming the design and the config field most likely responsible (``tsmpc.diagnose``), and a
run's PARTIAL marker says ``failed`` with that reason. No solver exception escapes.

The exceptions are injected where the designs are loaded or solved (fast); a few real infeasible
designs (valid, in-range configs no certified design exists for) check the whole path.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.cli._common import PARTIAL_MARKER
from tsmpc.config import Config, replace
from tsmpc.diagnose import explain_design_failure, suspect_fields

runner = CliRunner()


def _errors() -> dict[str, Exception]:
    import cvxpy

    from tsmpc.errors import CertificateError, SolverError

    return {
        "cvxpy-solver-error": cvxpy.error.SolverError("Solver 'CLARABEL' failed."),
        "nan-or-inf": ValueError("Problem data contains NaN or Inf."),
        "linalg": np.linalg.LinAlgError("Singular matrix"),
        "zero-division": ZeroDivisionError("float division by zero"),
        "overflow": OverflowError("math range error"),
        "tsmpc-solver": SolverError("kinematic LQR-LMI: infeasible"),
        "certificate": CertificateError("certificate(s) violated"),
        "runtime": RuntimeError("something inside the solver"),
    }


#: (design that fails, config TOML, field the message must name)
SUSPECTS = [
    ("kinematic", "[kinematic_lmi]\nR = [1e6, 3.0]\n", "kinematic_lmi.R"),
    ("kinematic", "[kinematic_box]\nv_d = [1.0, 60.0]\n", "kinematic_box.v_d"),
    ("kinematic", "[rates]\nTc = 0.5\n", "rates.Tc"),
    ("dynamic", "[vehicle]\nmass = 5.0\ninertia = 4.0\n", "vehicle.mass"),
    ("dynamic", "[dynamic_box]\nv = [0.5, 20.0]\n", "dynamic_box.v"),
    ("dynamic", "[dynamic_lmi]\nfilter_bandwidth = 900.0\n", "dynamic_lmi.filter_bandwidth"),
    ("dynamic", "[rates]\nTd = 0.05\nTc = 0.1\n", "rates.Td"),
    ("dynamic", "", "the design's inputs"),  # the defaults: no field to blame, the inputs named
]


def _inject(monkeypatch, kind: str, exc: Exception) -> None:
    from tsmpc.synthesis import cache

    name = f"load_or_design_{kind}"
    monkeypatch.setattr(cache, name, lambda *a, **k: (_ for _ in ()).throw(exc))


@pytest.mark.timeout(60)
@pytest.mark.parametrize("error", list(_errors()))
@pytest.mark.parametrize(("kind", "toml", "field"), SUSPECTS)
def test_run_with_a_failing_design_exits_2_naming_the_field(tmp_path: Path, monkeypatch, error: str,
                                                            kind: str, toml: str, field: str) -> None:
    exc = _errors()[error]
    _inject(monkeypatch, kind, exc)
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    out = tmp_path / "out"
    res = runner.invoke(app, ["run", "--duration", "1", "--no-plots", "--config", str(cfg),
                              "--out", str(out)])
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    line = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(line) == 1, res.output
    assert f"no certified {kind} LMI design" in line[0] and field in line[0], line[0]
    assert str(exc).split(".")[0][:20] in line[0]  # the solver's words are kept
    marker = json.loads((out / PARTIAL_MARKER).read_text())
    assert marker["status"] == "failed" and field in marker["reason"]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("command", ["design", "compare", "sweep"])
@pytest.mark.parametrize("kind", ["kinematic", "dynamic"])
def test_every_command_that_designs_maps_a_solver_exception_to_exit_2(tmp_path: Path, monkeypatch,
                                                                      command: str, kind: str) -> None:
    import cvxpy

    _inject(monkeypatch, kind, cvxpy.error.SolverError("Solver 'CLARABEL' failed."))
    cfg = tmp_path / "c.toml"
    cfg.write_text("[vehicle]\ng = 12.0\n[kinematic_lmi]\nQ = [2.0, 1.5, 3.0]\n")
    out = tmp_path / "out"
    if command == "design":
        argv = ["design", "--no-cache", "--config", str(cfg)]
    elif command == "compare":
        argv = ["compare", "--methods", "ref", "--duration", "1", "--no-plots", "--config", str(cfg),
                "--out", str(out)]
    else:
        sweep = tmp_path / "s.toml"
        sweep.write_text(f'name = "t"\nduration_s = 1.0\nbase_config = "{cfg}"\n')
        argv = ["sweep", str(sweep), "--out", str(out)]
    res = runner.invoke(app, argv)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "CLARABEL" in res.output
    assert ("vehicle.g" if kind == "dynamic" else "kinematic_lmi.Q") in res.output
    if command == "sweep":
        assert not out.exists()  # nothing written before the designs


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize(("toml", "field"), [
    ("[kinematic_lmi]\nR = [1e8, 1e8]\n", "kinematic_lmi.R"),
    ("[kinematic_box]\nomega = [-20.0, 20.0]\nv_d = [0.001, 200.0]\n", "kinematic_box.v_d"),
    ("[vehicle]\ng = 30.0\nmass = 100000.0\ninertia = 1e7\ncornering_stiffness = 1.0\n",
     "vehicle.cornering_stiffness"),
])
def test_a_real_infeasible_design_exits_2_naming_the_field(tmp_path: Path, monkeypatch, toml: str,
                                                          field: str) -> None:
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "cache"))
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    res = runner.invoke(app, ["design", "--config", str(cfg)])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and field in res.output


def test_the_suspects_are_the_changed_inputs_furthest_from_their_defaults() -> None:
    cfg = Config()
    assert suspect_fields("kinematic", cfg) == []
    c = replace(cfg, vehicle=replace(cfg.vehicle, mass=700.0, g=25.0),
                kinematic_lmi=replace(cfg.kinematic_lmi, R=(1e6, 3.0)))
    dyn = suspect_fields("dynamic", c)
    assert [k for k, _, _ in dyn] == ["vehicle.g", "vehicle.mass"]  # 25/9.81 is further than 700/683
    kin = suspect_fields("kinematic", c)
    assert [k for k, _, _ in kin] == ["kinematic_lmi.R"]  # vehicle is no input of the kinematic design
    msg = explain_design_failure("dynamic", c, ValueError("Problem data contains NaN or Inf."))
    assert "vehicle.g = 25.0 (default 9.81)" in msg and "also changed: vehicle.mass" in msg
    assert "\n" not in msg and len(msg) < 1000
