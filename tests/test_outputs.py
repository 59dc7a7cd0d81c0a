"""Output safety (issue 12): file modes from the umask, --overwrite replaces only tsmpc's own
files, and SIGINT / SIGTERM stop a run cleanly with exit 130 / 143 and a marked partial folder
(including a signal that a solver swallowed)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.cli._common import PARTIAL_MARKER, Interrupted, check_interrupted, handle_interrupts
from tsmpc.sim.log import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o077])
def test_atomic_writes_get_the_mode_the_umask_says(tmp_path: Path, mask: int) -> None:
    old = os.umask(mask)
    try:
        atomic_write_text(tmp_path / "f.json", "{}")
    finally:
        os.umask(old)
    assert (tmp_path / "f.json").stat().st_mode & 0o777 == 0o666 & ~mask


def test_a_signal_swallowed_by_a_solver_is_still_seen_after_the_step() -> None:
    """CasADi/IPOPT catch SIGINT inside a solve and return a failed status; the flag set by our
    handler makes the next per-step check raise anyway."""
    with handle_interrupts():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.1)  # the handler runs here and raises ...
        except Interrupted:
            pass  # ... and the "solver" swallows it
        with pytest.raises(Interrupted) as err:
            check_interrupted()
    assert err.value.code == 130
    check_interrupted()  # after the context nothing is pending any more


def test_overwrite_replaces_only_tsmpc_outputs(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")
    (out / "circuit.png").write_bytes(b"stale figure of an earlier run")
    (out / "metrics.json").write_text("{}")
    runner = CliRunner()
    res = runner.invoke(app, ["run", "--duration", "0.5", "--no-plots", "--out", str(out)])
    assert res.exit_code == 2 and "--overwrite" in res.output
    assert (out / "metrics.json").read_text() == "{}"  # refused: nothing touched
    res = runner.invoke(app, ["run", "--duration", "0.5", "--no-plots", "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    assert (out / "notes.txt").read_text() == "mine\n"
    assert not (out / "circuit.png").exists()  # stale figure removed (this run made none)
    assert not (out / PARTIAL_MARKER).exists()
    assert json.loads((out / "metrics.json").read_text())["scenario"]["tracked_steps"] == 5


def test_show_reference_out_folder_writes_into_it(tmp_path: Path) -> None:
    from tsmpc.planning.circuit import builtin_circuit

    builtin_circuit(dt=0.1).to_csv(tmp_path / "ref.csv")
    (tmp_path / "figs").mkdir()
    res = CliRunner().invoke(app, ["show-reference", str(tmp_path / "ref.csv"), "--out",
                                   str(tmp_path / "figs")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "figs" / "ref.png").stat().st_size > 1000
    assert not (tmp_path / "figs.png").exists()


def test_planner_output_keeps_full_precision(tmp_path: Path) -> None:
    """A path far from the origin (9e6 m offsets, near the 1e7 m coordinate limit) reads back bit
    for bit."""
    import numpy as np

    from tsmpc.config import PlannerSettings
    from tsmpc.planning.paper_format import load_reference
    from tsmpc.planning.planner import plan_path

    wp = np.array([[0.0, 0.0], [60.0, 0.0], [120.0, 10.0], [170.0, 40.0]]) + 9e6
    ref = plan_path(wp, PlannerSettings(), closed=False)
    ref.to_csv(tmp_path / "far.csv")
    back = load_reference(tmp_path / "far.csv", window=None)
    np.testing.assert_array_equal(back.x, ref.x)
    np.testing.assert_array_equal(back.theta, ref.theta)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


@pytest.mark.parametrize(("method", "sig", "code"), [
    ("nl", signal.SIGINT, 130),  # CasADi/IPOPT own the SIGINT handler during a solve
    ("nl", signal.SIGTERM, 143),
    ("ref", signal.SIGINT, 130),
    ("ref", signal.SIGTERM, 143),
])
def test_interrupted_run_exits_non_zero_and_marks_the_folder(
    tmp_path: Path, method: str, sig: int, code: int
) -> None:
    out = tmp_path / "out"
    # With the compiled kernels a 120 s TS-MPC run takes well under the 1.5 s wait below (and
    # NL only a few seconds), so it could finish before the signal: the numpy blocks keep it
    # running long enough (the interrupt handling under test is the same).
    env = {**_env(), "TSMPC_NO_JIT": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "tsmpc", "run", "--method", method, "--duration", "120", "--no-plots",
         "--out", str(out)], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 240  # a cold design cache solves the LMIs first
        while not (out / PARTIAL_MARKER).exists():
            assert proc.poll() is None, proc.communicate()[0]
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.05)
        time.sleep(1.5)  # designs loaded (or being solved), simulation under way
        proc.send_signal(sig)
        text, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, text
    assert "Traceback" not in text
    assert "interrupted" in text
    marker = json.loads((out / PARTIAL_MARKER).read_text())
    assert marker["status"] == "interrupted" and marker["signal"] == signal.Signals(sig).name
    # Either complete outputs or a marked partial run: here the run stopped early, so marked.
    assert not (out / "metrics.json").exists()


def test_interrupted_sweep_keeps_its_records_and_resumes(tmp_path: Path) -> None:
    """SIGINT mid-sweep: exit 130, the records written so far stay, PARTIAL marks the folder,
    and --resume runs only what is missing."""
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 2.0\n[grid]\nmethod = ["ref", "fzn"]\n'
                     'seed = [1, 2, 3, 4, 5, 6, 7, 8]\n')
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "tsmpc", "sweep", str(sweep), "--dry-run", "--no-plots",
           "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while len(list((out / "runs").glob("*.json"))) < 2:
            assert proc.poll() is None, proc.communicate()[0]
            assert time.monotonic() < deadline, "no record appeared"
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        text, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "--resume" in text
    assert json.loads((out / PARTIAL_MARKER).read_text())["status"] == "interrupted"
    kept = {p.name: p.read_text() for p in (out / "runs").glob("*.json")}
    assert 2 <= len(kept) < 16
    done = subprocess.run([*cmd, "--resume"], env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert not (out / PARTIAL_MARKER).exists()
    after = {p.name: p.read_text() for p in (out / "runs").glob("*.json")}
    assert len(after) == 16 and all(after[k] == v for k, v in kept.items())
