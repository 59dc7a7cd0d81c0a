"""An install that fits the use (issue 37 item 2): the core (no extra) imports and steps
:class:`~tsmpc.control.cascade.Cascade`; every optional dependency is imported only by the feature
that needs it; every install hint names an extra that pyproject.toml defines, in a form that
works from a checkout (tsmpc is not on PyPI)."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

import tsmpc
from tsmpc.extras import EXTRAS, MissingExtraError, from_import_error, install_hint, require

ROOT = Path(__file__).resolve().parents[1]
SRC = Path(tsmpc.__file__).parent  # the package under test (a copy on PYTHONPATH too)
#: What a deployment must not need (the extras' heavy packages).
OPTIONAL = ("dask", "distributed", "pandas", "pyarrow", "casadi", "matplotlib", "typer", "rich",
            "PIL", "imageio_ffmpeg")


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def _blocked(code: str, blocked: tuple[str, ...] = OPTIONAL, timeout: float = 600,
             args: tuple[str, ...] = ()) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter where importing any of ``blocked`` raises ImportError,
    as on a core install without them."""
    prelude = textwrap.dedent(f"""
        import importlib.abc, sys
        BLOCKED = {set(blocked)!r}
        class _NotInstalled(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in BLOCKED:
                    raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
                return None
        sys.meta_path.insert(0, _NotInstalled())
    """)
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code), *args],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_cascade_imports_and_steps_without_any_optional_dependency() -> None:
    res = _blocked("""
        import numpy as np
        from tsmpc.config import Config
        from tsmpc.control.cascade import Cascade, Measurement
        from tsmpc.planning.circuit import builtin_circuit
        from tsmpc.vehicle.plant import VehiclePlant

        cfg = Config()
        ref = builtin_circuit(dt=cfg.rates.Tc)
        cascade = Cascade(cfg, "ref", ref)
        car = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
        car.reset([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, 0.0])
        worst = 0.0
        for i in range(200):  # 2 s at T_d = 10 ms
            X, Y, theta, v, _, omega = car.state
            cmd = cascade.step(i * cfg.rates.Td, Measurement((X, Y, theta), v, omega))
            car.step([cmd.F_xR, cmd.delta], cfg.rates.Td, mu_road=0.9)
            d = np.hypot(ref.x - car.state[0], ref.y - car.state[1]).min()
            worst = max(worst, d)
        loaded = sorted({m.split(".")[0] for m in sys.modules} & BLOCKED)
        print("LOADED", loaded)
        moved = float(np.hypot(car.state[0] - ref.x[0], car.state[1] - ref.y[0]))
        print("STATUS", cascade.last_plan.status, "WORST", worst, "MOVED", moved)
    """)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "LOADED []" in res.stdout, res.stdout
    status = res.stdout.split("STATUS ", 1)[1].split()
    # The car tracked the circuit for 2 s: the plan is optimal, the car stays within 0.5 m of the
    # nearest reference sample (measured 0.20 m: the samples are v·T_c apart, not the car's
    # error) and it drove off (measured 4.7 m from rest): a cascade that returns nothing useful
    # leaves the car standing or drifting off.
    assert "optimal" in status[0].lower(), res.stdout
    assert float(status[2]) < 0.5 and float(status[4]) > 3.0, res.stdout


def test_the_cli_modules_import_no_optional_dependency_but_typer() -> None:
    """Registering the commands (``tsmpc --help``) loads only typer and rich's CLI helpers: every
    heavy dependency stays inside the command that needs it."""
    res = _blocked("""
        import tsmpc.cli
        print("LOADED", sorted({m.split(".")[0] for m in sys.modules} & BLOCKED))
    """, blocked=tuple(m for m in OPTIONAL if m not in ("typer", "rich")))
    assert res.returncode == 0, res.stderr[-3000:]
    assert "LOADED []" in res.stdout, res.stdout


def test_the_tsmpc_command_without_the_cli_extra_says_what_to_install() -> None:
    res = _blocked("from tsmpc._entry import main; main()", args=())
    assert res.returncode == 2, (res.returncode, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert 'pip install -e ".[cli]"' in lines[0] and "[cli] extra" in lines[0], lines[0]


@pytest.mark.parametrize(("blocked", "argv", "extra"), [
    ("casadi", ["--methods", "ref,nl", "--no-plots"], "nl"),
    ("matplotlib", ["--methods", "ref"], "report"),
])
def test_compare_without_an_extra_it_needs_exits_2_naming_it(tmp_path: Path, blocked: str,
                                                             argv: list[str], extra: str) -> None:
    out = tmp_path / "out"
    res = _blocked("import sys; from tsmpc.cli import main; sys.argv = ['tsmpc', *sys.argv[1:]]; main()",
                   blocked=(blocked,), timeout=300,
                   args=("compare", "--duration", "1", "--out", str(out), *argv))
    assert res.returncode == 2, (res.returncode, res.stdout[-2000:], res.stderr[-2000:])
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and f'pip install -e ".[{extra}]"' in errors[0], res.stderr
    assert not out.exists() or not any(out.iterdir())  # refused before any work


def test_a_missing_optional_module_deep_in_a_command_becomes_the_install_line() -> None:
    """The entry point's last net and guarded_run turn an ImportError of an optional dependency
    (a command that imports dask, pandas, … only when it runs) into the extra's install line."""
    hint = from_import_error(ModuleNotFoundError("No module named 'dask'", name="dask.distributed"))
    assert hint is not None and 'pip install -e ".[sweep]"' in hint
    assert from_import_error(ModuleNotFoundError("x", name="numpy")) is None  # core: a real bug
    with pytest.raises(MissingExtraError, match=r'pip install -e "\.\[nl\]"'):
        require("casadi.no_such_module", "the NL-MPC")


def test_every_extra_named_by_a_hint_is_defined_and_brings_its_package() -> None:
    extras = _pyproject()["project"]["optional-dependencies"]
    core = " ".join(_pyproject()["project"]["dependencies"]).lower()
    for module, (package, extra) in EXTRAS.items():
        assert extra in extras, (module, extra)
        assert any(req.lower().startswith(package.lower()) for req in extras[extra]), (module, extra)
        assert package.split("[")[0].lower() not in core, f"{package} is optional, not core"
    # [all]: everything a user runs
    everything = " ".join(extras["all"])
    for extra in ("cli", "nl", "sweep", "report", "video", "data"):
        assert extra in everything, extra


def test_every_install_line_in_the_source_works_from_a_checkout() -> None:
    """`pip install "tsmpc[video]"` fails (tsmpc is not on PyPI): every hint says
    `pip install -e ".[EXTRA]"` with an EXTRA pyproject.toml defines."""
    extras = set(_pyproject()["project"]["optional-dependencies"])
    assert install_hint("video").startswith('pip install -e ".[video]"')
    found = 0
    for path in SRC.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "tsmpc[" not in text, f"{path}: an install by name fails"
        for m in re.finditer(r"pip install(?: -e)? [\"']?\.\[([a-z_,]+)\]", text):
            found += 1
            assert set(m.group(1).split(",")) <= extras, (path, m.group(0))
    assert found >= 1


def test_every_install_line_in_the_docs_and_examples_names_a_defined_extra() -> None:
    extras = set(_pyproject()["project"]["optional-dependencies"])
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "examples").glob("*.py"))]
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert 'install "tsmpc[' not in text and "install 'tsmpc[" not in text, page
        for m in re.finditer(r"pip install[^\n`]*?\.\[([a-z_,]+)\]", text):
            assert set(m.group(1).split(",")) <= extras, (page.name, m.group(0))


@pytest.mark.parametrize("blocked", ["distributed", "pyarrow"])
def test_sweep_without_the_sweep_extra_exits_2_before_any_work(tmp_path: Path, blocked: str) -> None:
    """`tsmpc sweep` needs Dask, pandas and pyarrow: without them it says so at once (it said so
    only after compiling the batch kernel, minutes later)."""
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "s"\nduration_s = 1.0\n[grid]\nseed = [1]\n')
    out = tmp_path / "out"
    res = _blocked("import sys; from tsmpc.cli import main; sys.argv = ['tsmpc', *sys.argv[1:]]; main()",
                   blocked=(blocked,), timeout=120, args=("sweep", str(sweep), "--out", str(out)))
    assert res.returncode == 2, (res.returncode, res.stdout[-2000:], res.stderr[-2000:])
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and 'pip install -e ".[sweep]"' in errors[0], res.stderr
    assert "compiling" not in res.stderr and not out.exists()
