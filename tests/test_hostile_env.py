"""Caches and environment variables heal or are named (issue 24).

* a kernel cache numba cannot load (corrupt, truncated) is deleted and the kernels compiled
  again, once; if that fails too, one line names the folder (``tsmpc.kernels``);
* ``NUMBA_CACHE_DIR`` / ``TSMPC_CACHE_DIR`` that are not writable folders are refused with one
  line naming them (numba used to bypass the first silently into the package's ``__pycache__``);
* ``TSMPC_BLAS_THREADS`` above the core count is capped with a warning, unreadable values are
  refused by the CLI (``tsmpc.blas``);
* an empty or relative ``HOME`` gets an explicit private fallback folder, announced once, instead
  of ``/.cache/tsmpc`` (``tsmpc.paths``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.fixture()
def afile(tmp_path: Path) -> Path:
    p = tmp_path / "afile"
    p.write_text("not a folder\n")
    return p


ENV_CASES = [
    ("numba-cache-is-a-file", "NUMBA_CACHE_DIR", "{F}", "NUMBA_CACHE_DIR"),
    ("numba-cache-under-a-file", "NUMBA_CACHE_DIR", "{F}/sub", "NUMBA_CACHE_DIR"),
    ("numba-cache-in-proc", "NUMBA_CACHE_DIR", "/proc/tsmpc-numba", "NUMBA_CACHE_DIR"),
    ("tsmpc-cache-is-a-file", "TSMPC_CACHE_DIR", "{F}", "TSMPC_CACHE_DIR"),
    ("tsmpc-cache-in-proc", "TSMPC_CACHE_DIR", "/proc/tsmpc-cache", "TSMPC_CACHE_DIR"),
    ("blas-threads-text", "TSMPC_BLAS_THREADS", "many", "TSMPC_BLAS_THREADS"),
    ("blas-threads-zero", "TSMPC_BLAS_THREADS", "0", "TSMPC_BLAS_THREADS"),
    ("blas-threads-negative", "TSMPC_BLAS_THREADS", "-3", "TSMPC_BLAS_THREADS"),
    ("blas-threads-fraction", "TSMPC_BLAS_THREADS", "2.5", "TSMPC_BLAS_THREADS"),
    ("blas-threads-huge-number", "TSMPC_BLAS_THREADS", "9" * 40, "TSMPC_BLAS_THREADS"),
]


COMMANDS = {"run": ["run", "--no-plots", "--duration", "1"], "warmup": ["warmup"], "design": ["design"],
            "sweep": ["sweep"]}


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("command", "var", "value", "needle"), [
    pytest.param(argv, v, x, n, id=f"{i}-{name}")
    for i, v, x, n in ENV_CASES for name, argv in COMMANDS.items()
    if not (name == "design" and v == "NUMBA_CACHE_DIR")])  # design compiles no kernels: not its variable
def test_an_unusable_environment_variable_is_refused_naming_it(tmp_path: Path, afile: Path, monkeypatch,
                                                               command: list[str], var: str, value: str,
                                                               needle: str) -> None:
    monkeypatch.setenv(var, value.replace("{F}", str(afile)))
    out = tmp_path / "out"
    argv = list(command)
    if command == ["sweep"]:
        sweep = tmp_path / "s.toml"
        sweep.write_text('name = "t"\nduration_s = 1.0\n')
        argv += [str(sweep), "--out", str(out)]
    elif command[0] == "run":
        argv += ["--out", str(out)]
    res = runner.invoke(app, argv)
    assert res.exit_code == 2, res.output
    assert needle in res.output and "Traceback" not in res.output
    assert len([ln for ln in res.output.splitlines() if ln.startswith("error:")]) == 1
    assert not out.exists()


def test_blas_threads_above_the_core_count_are_capped_with_one_warning(monkeypatch, capsys) -> None:
    from tsmpc import blas

    monkeypatch.setattr(blas, "_WARNED", set())
    monkeypatch.setattr(blas, "cores", lambda: 2)
    for text, want in (("3", 2), ("100000", 2), ("2", 2), ("1", 1), ("default", None)):
        monkeypatch.setenv("TSMPC_BLAS_THREADS", text)
        assert blas.blas_threads_setting() == want
    err = capsys.readouterr().err
    assert err.count("warning") == 2 and "using 2" in err  # once per value, none when in range
    monkeypatch.setenv("TSMPC_BLAS_THREADS", "lots")  # inside a simulation: never raises
    assert blas.blas_threads_setting() == 1


@pytest.mark.parametrize("home", ["", "relative/home"])
def test_an_empty_or_relative_home_gets_a_private_fallback(tmp_path: Path, monkeypatch, capsys,
                                                           home: str) -> None:
    import tempfile

    from tsmpc import paths
    from tsmpc.synthesis.cache import cache_dir

    monkeypatch.delenv("TSMPC_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", home)
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(paths, "_NOTED", set())
    got = cache_dir()
    assert got == tmp_path / f"tsmpc-cache-{os.getuid()}" and got.is_dir()
    assert got.stat().st_mode & 0o777 == 0o700
    assert cache_dir() == got
    err = capsys.readouterr().err
    assert err.count("caching in") == 1 and "TSMPC_CACHE_DIR" in err  # announced once


def test_a_fallback_folder_owned_by_someone_else_is_never_used(tmp_path: Path, monkeypatch) -> None:
    import tempfile

    from tsmpc import paths

    monkeypatch.delenv("TSMPC_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", "")
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(paths, "_NOTED", set())
    trap = tmp_path / f"tsmpc-cache-{os.getuid()}"
    trap.mkdir(mode=0o777)
    trap.chmod(0o777)  # world-writable: someone else could plant compiled code in it
    assert paths.cache_root() != trap
    with pytest.raises(OSError, match="private"):
        paths.private_fallback()


def test_a_cache_that_cannot_be_cleaned_or_rebuilt_is_named_in_one_line(monkeypatch, tmp_path: Path,
                                                                        capsys) -> None:
    from tsmpc import kernels

    # _import_all forgets a broken kernel module (sys.modules) to re-import it: restore this
    # process's afterwards, or the run engine of later tests sees "replaced" kernels and steps aside
    for m in kernels._MODULES:
        if f"tsmpc.kernels.{m}" in sys.modules:
            monkeypatch.setitem(sys.modules, f"tsmpc.kernels.{m}", sys.modules[f"tsmpc.kernels.{m}"])
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernels._tree_folder(tmp_path)
    folder.mkdir(parents=True)
    (folder / "mpc.fast_step-1.py311.nbi").write_text("garbage")

    def corrupt(modules: tuple[str, ...] = ()) -> dict:
        raise ValueError("invalid literal for int() with base 10: 'arbage'")

    monkeypatch.setattr(kernels, "_compile_all", corrupt)
    with pytest.raises(kernels.KernelCacheError, match="unusable even after a rebuild") as err:
        kernels._import_all()
    assert str(folder) in str(err.value)
    assert not list(folder.glob("*.nbi"))  # the entry was deleted before the second try
    (folder / "mpc.fast_step-1.py311.nbi").write_text("garbage")

    def no_delete(_folder: Path, _modules: tuple[str, ...] = ()) -> int:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(kernels, "_purge", no_delete)
    with pytest.raises(kernels.KernelCacheError, match="nor cleaned"):
        kernels._import_all()
    # the library falls back to numpy with one line naming the reason; the CLI's warmup exits 1
    monkeypatch.setattr(kernels, "_LOADED", None)
    monkeypatch.setattr(kernels, "_FAILED", False)
    assert kernels.load("mpc") is None
    assert "nor cleaned" in capsys.readouterr().err and "nor cleaned" in (kernels.failure() or "")
    res = runner.invoke(app, ["warmup"])
    assert res.exit_code == 1 and "nor cleaned" in res.output


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_corrupt_kernel_cache_is_rebuilt_once_and_then_loads(tmp_path: Path) -> None:
    """Garbage and truncated entries in a copy of the real cache: the first process rebuilds it
    (one line says so) and its kernels work; the next one loads them without a word."""
    from tsmpc import kernels

    src = kernels.numba_cache_dir()
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", NUMBA_CACHE_DIR=str(tmp_path / "c"))
    env.pop("TSMPC_NO_JIT", None)
    cmd = [sys.executable, "-m", "tsmpc", "warmup"]
    if any(kernels._tree_folder(src).glob("*.nbi")):
        shutil.copytree(src, tmp_path / "c")
    else:  # no cache yet on this machine: make one
        subprocess.run(cmd, env=env, capture_output=True, timeout=500, check=True)
    folder = kernels._tree_folder(tmp_path / "c")
    # The plant kernel's entries (index truncated, machine code garbage): the process rebuilds
    # that module only (seconds; each kernel module is loaded and repaired on its own). The run
    # engine's and the batch kernel's repair (sim.engine._compiled, minutes of compiling) has its
    # own test below, on a stand-in kernel.
    entries = sorted(folder.glob("plant.*.nb[ic]"))
    assert entries
    for p in entries:
        p.write_bytes(b"" if p.suffix == ".nbi" else b"\x80garbage" * 10)
    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=500)
    assert first.returncode == 0, first.stdout + first.stderr
    assert "could not be loaded" in first.stderr and "kernels and run engine ready" in first.stdout
    assert "compiling the plant kernels again" in first.stderr
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=500)
    assert second.returncode == 0 and "could not be loaded" not in second.stderr
    assert "compiling" not in second.stderr


class _StandInKernel:
    """A kernel whose cached machine code cannot be loaded ``failures`` times."""

    def __init__(self, failures: int) -> None:
        self.failures, self.calls = failures, 0

    def run_borrowed(self, *args: object) -> None:  # (the engine's entry, kernels.engine)
        self.calls += 1
        if self.calls <= self.failures:
            raise EOFError("Ran out of input")  # what numba raises on a truncated entry


@pytest.mark.parametrize("failures", [1, 2])
def test_the_engine_rebuilds_an_unloadable_cache_once(failures: int, tmp_path: Path, monkeypatch,
                                                      capsys) -> None:
    """sim.engine._compiled (the engine's and the batch kernel's first call): an entry that
    cannot be loaded is deleted with the engine's other entries and compiled again, once; a
    second failure leaves the Python loop running (False), never an exception."""
    from tsmpc import kernels
    from tsmpc.sim import engine

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernels._tree_folder(tmp_path)
    folder.mkdir(parents=True)
    for name in ("engine.run-1.py311.nbi", "engine.run-1.py311.1.nbc", "mpc.riccati-1.py311.nbi"):
        (folder / name).write_bytes(b"\x80garbage")
    ke = _StandInKernel(failures)
    saved = dict(engine._KERNEL)
    try:
        ok = engine._compiled(ke, ())
    finally:
        engine._KERNEL.clear()
        engine._KERNEL.update(saved)
    err = capsys.readouterr().err
    assert ok is (failures == 1) and ke.calls == 2
    assert "could not be loaded (EOFError); compiling it again" in err
    # the engine's entries only (its compile lock, engine.lock, stays)
    assert sorted(p.name for p in folder.iterdir() if p.suffix != ".lock") == ["mpc.riccati-1.py311.nbi"]
