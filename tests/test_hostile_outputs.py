"""Output failures end cleanly (issue 24): a full disk, a quota, a read-only file system, a closed
or full stdout, a broken pipe, an interrupt while figures are written — each ends with one line on
stderr, a non-zero exit and PARTIAL saying ``failed`` (or ``interrupted``) with the reason, and no
temporary file is left behind (``tsmpc.cli._common.guarded_run``, ``tsmpc.io``). A terminal that
cannot encode a character and markup characters in user strings are not failures: the run
completes and the strings are printed literally.

The write failures are injected in-process (``os.replace`` of the atomic writer raises, exactly
where a real ENOSPC surfaces after the temporary file was written); stdout failures need a real
process (``/dev/full``, a pipe closed by its reader, ``>&-``).
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.cli._common import PARTIAL_MARKER

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
RUN = ["run", "--duration", "1", "--no-plots"]


def _leftovers(out: Path) -> list[str]:
    """Temporary files of the atomic writers and the probes (must never stay)."""
    return [p.name for p in out.iterdir() if ".tmp" in p.name or p.name.startswith(".tsmpc-probe")]


def _marker(out: Path) -> dict:
    return json.loads((out / PARTIAL_MARKER).read_text())


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("target", "code", "words", "plots"), [
    ("metrics.json", errno.ENOSPC, "the disk is full", False),
    ("timeseries.npz", errno.ENOSPC, "the disk is full", False),
    ("timeseries.mat", errno.EDQUOT, "quota", False),
    ("rmse.tex", errno.EROFS, "read-only", False),
    ("report.html", errno.ENOSPC, "the disk is full", False),
    ("errors.pdf", errno.ENOSPC, "the disk is full", True),
    ("circuit.png", errno.EIO, "Input/output error", True),
    ("*", errno.ENOSPC, "the disk is full", False),  # every write, PARTIAL's own too
])
def test_a_failed_write_ends_with_one_line_partial_failed_and_no_temporary_file(
    tmp_path: Path, monkeypatch, target: str, code: int, words: str, plots: bool
) -> None:
    from tsmpc import io as tio

    real = os.replace
    started = []

    def failing_replace(src, dst, *a, **k):
        name = Path(dst).name
        if name == PARTIAL_MARKER and not started:
            started.append(1)  # the first marker ("running") is written
            return real(src, dst, *a, **k)
        if target == "*" or name == target:
            raise OSError(code, os.strerror(code), str(dst))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(tio.os, "replace", failing_replace)
    out = tmp_path / "out"
    argv = ["run", "--duration", "1", "--out", str(out)] + ([] if plots else ["--no-plots"])
    argv += ["--mat"] if target == "timeseries.mat" else []  # .mat only on request
    res = runner.invoke(app, argv)
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and words in errors[0] and "PARTIAL" in errors[0], res.output
    marker = _marker(out)
    assert marker["status"] == "failed" and words in marker["reason"]
    assert not _leftovers(out), _leftovers(out)


@pytest.mark.timeout(120)
def test_an_interrupt_while_figures_are_written_leaves_no_temporary_file(tmp_path: Path,
                                                                        monkeypatch) -> None:
    from matplotlib.figure import Figure

    from tsmpc.cli._common import Interrupted

    real = Figure.savefig
    calls = []

    def interrupted_savefig(self, *a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise Interrupted(signal.SIGINT)
        return real(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", interrupted_savefig)
    out = tmp_path / "out"
    res = runner.invoke(app, ["run", "--duration", "1", "--out", str(out)])
    assert res.exit_code == 130, res.output
    assert _marker(out)["status"] == "interrupted"
    assert not _leftovers(out), _leftovers(out)
    assert not [p for p in out.iterdir() if p.suffix == ".pdf" and p.stat().st_size == 0]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("text", ["o[/]mk", "[bold red]x[/]", "[link=https:x]y", ":smile:z"])
def test_markup_in_an_output_path_is_printed_literally(tmp_path: Path, text: str) -> None:
    out = tmp_path / text
    res = runner.invoke(app, [*RUN, "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert text in res.output.replace("\n", "")  # the path as given, not interpreted
    assert not (out / PARTIAL_MARKER).exists()


@pytest.mark.timeout(120)
def test_markup_in_a_reference_name_is_printed_literally(tmp_path: Path) -> None:
    from tsmpc.planning.circuit import builtin_circuit

    ref = tmp_path / "[bold]r[-].csv"
    builtin_circuit(dt=0.1).slice(0, 200).to_csv(ref)
    res = runner.invoke(app, [*RUN, "--reference", str(ref), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert "[bold]r[-]" in res.output


@pytest.mark.timeout(180)
def test_markup_in_a_sweep_name_is_printed_literally(tmp_path: Path) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "[/bold] oops [/]"\nduration_s = 2.0\n[grid]\nseed = [1, 2]\n')
    res = runner.invoke(app, ["sweep", str(sweep), "--dry-run", "--no-plots", "--workers", "1",
                              "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert "[/bold] oops [/]" in res.output


# -- real processes: stdout full, closed, a broken pipe, an ASCII terminal -------------------
def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("OMP_NUM_THREADS", "1")
    env.update(extra)
    return env


def _cmd(out: Path) -> list[str]:
    return [sys.executable, "-m", "tsmpc", *RUN, "--out", str(out)]


@pytest.mark.timeout(180)
def test_stdout_to_dev_full_fails_in_one_line(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with open("/dev/full", "w") as full:
        res = subprocess.run(_cmd(out), stdout=full, stderr=subprocess.PIPE, text=True, env=_env(),
                             timeout=150)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr
    assert len([ln for ln in res.stderr.splitlines() if ln.startswith("error:")]) == 1, res.stderr
    assert _marker(out)["status"] == "failed"
    assert not _leftovers(out)


@pytest.mark.timeout(180)
def test_a_pipe_closed_by_its_reader_fails_in_one_line(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = subprocess.Popen(_cmd(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env())
    try:
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.read(5)
        proc.stdout.close()  # like `tsmpc run ... | head -c 5`
        err = proc.stderr.read().decode()
        code = proc.wait(timeout=150)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 1, err
    assert "Traceback" not in err and "Exception ignored" not in err
    assert len([ln for ln in err.splitlines() if ln.startswith("error:")]) == 1, err
    assert _marker(out)["status"] == "failed"


@pytest.mark.timeout(180)
def test_a_closed_stdout_is_refused_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = subprocess.run(["/bin/sh", "-c", 'exec "$@" >&-', "sh", *_cmd(out)], stderr=subprocess.PIPE,
                         text=True, env=_env(), timeout=150)
    assert res.returncode == 2, res.stderr
    assert "stdout is closed" in res.stderr and "Traceback" not in res.stderr
    assert not out.exists()


@pytest.mark.timeout(180)
@pytest.mark.parametrize("encoding", ["ascii", "latin-1"])
def test_a_terminal_without_utf8_gets_replacement_characters(tmp_path: Path, encoding: str) -> None:
    out = tmp_path / "out"
    res = subprocess.run(_cmd(out), capture_output=True, env=_env(PYTHONIOENCODING=encoding),
                         timeout=150)
    err = res.stderr.decode(encoding, "replace")
    assert res.returncode == 0, err
    assert "Traceback" not in err and "UnicodeEncodeError" not in err
    assert (out / "metrics.json").is_file() and not (out / PARTIAL_MARKER).exists()
    assert b"RMSE" in res.stdout


@pytest.mark.timeout(180)
@pytest.mark.parametrize("argv", [["design", "--json"], ["plan", "examples/waypoints.csv", "--out", "{T}"],
                                  ["--version"], ["warmup"]])
def test_any_command_with_stdout_on_a_full_disk_fails_in_one_line(tmp_path: Path, argv: list[str]) -> None:
    """Commands without an output folder: the entry point's last net turns the failed write into
    one line and exit 1 (never a traceback, never exit 0)."""
    args = [a.replace("{T}", str(tmp_path / "r.csv")) for a in argv]
    with open("/dev/full", "w") as full:
        res = subprocess.run([sys.executable, "-m", "tsmpc", *args], stdout=full, stderr=subprocess.PIPE,
                             text=True, env=_env(), timeout=150, cwd=ROOT)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr
    assert len([ln for ln in res.stderr.splitlines() if ln.startswith("error:")]) == 1, res.stderr
