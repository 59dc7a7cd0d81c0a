"""Bounded resources (issue 38 item 2): signals end a command within a bounded time even when it
is busy where the handlers only record them, the memory a run needs is estimated and checked
before any work (exit 2 naming the limit and the estimate), and a ``ulimit -v`` run ends with one
line instead of spinning inside OpenBLAS."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tsmpc.cli import _memory

TSMPC = str(Path(sys.executable).with_name("tsmpc"))

# -- signals: the watchdog and the second-signal rule --------------------------------------------
# A driver that enters the CLI's guarded run, inside a deferred region (where the handlers only
# record a signal, as in the simulation loops), and then stays busy without checking the flag.
DRIVER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import numpy as np
    from tsmpc.cli import _common, _watchdog

    busy, out = sys.argv[1], Path(sys.argv[2])
    _common.install_signal_handlers()
    if sys.argv[3] == "armed":
        _watchdog.enable()  # what the tsmpc entry point does
    out.mkdir()
    with _common.guarded_run(out):
        _common.mark_partial(out, "running")
        with _common.deferred_interrupts():
            print("ready", flush=True)
            if busy == "sleep":  # a C call that the signal interrupts and that resumes
                time.sleep(60)
            elif busy == "python":  # Python that never checks the flag
                t = time.monotonic()
                while time.monotonic() - t < 60:
                    pass
            elif busy == "blas":  # long BLAS calls (the GIL released inside)
                a = np.random.default_rng(0).standard_normal((1500, 1500))
                t = time.monotonic()
                while time.monotonic() - t < 60:
                    a = np.tanh(a @ a)
""")

GRACE = 2.0  # TSMPC_SIGNAL_GRACE_S in these tests (the default is 10 s)


def _start(tmp_path: Path, busy: str, armed: bool = True) -> subprocess.Popen[str]:
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    env = {**os.environ, "TSMPC_SIGNAL_GRACE_S": str(GRACE), "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, str(script), busy, str(tmp_path / "out"),
                             "armed" if armed else "off"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.3)
    return proc


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("busy", "signals", "bound_s", "code"), [
    # one signal: the watchdog ends the process GRACE s later (+ a start-up margin)
    ("sleep", [signal.SIGTERM], GRACE + 4.0, 143),
    ("python", [signal.SIGTERM], GRACE + 4.0, 143),
    ("blas", [signal.SIGTERM], GRACE + 6.0, 143),
    ("sleep", [signal.SIGINT], GRACE + 4.0, 130),
    # a second signal: at once, with the first signal's code
    ("python", [signal.SIGTERM, signal.SIGINT], 1.5, 143),
    ("sleep", [signal.SIGINT, signal.SIGINT], 1.5, 130),
])
def test_a_signal_ends_a_busy_command_within_the_bound(tmp_path: Path, busy: str, signals: list[int],
                                                        bound_s: float, code: int) -> None:
    proc = _start(tmp_path, busy)
    t0 = time.monotonic()
    for k, sig in enumerate(signals):
        if k:
            time.sleep(0.3)
            t0 = time.monotonic()  # the second signal's bound counts from it
        proc.send_signal(sig)
    try:
        rc = proc.wait(timeout=bound_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"{busy}: still running {bound_s} s after {signals}")
    elapsed = time.monotonic() - t0
    err = proc.stderr.read() if proc.stderr else ""
    assert rc == code, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: interrupted"), err
    assert ("second signal" in lines[0]) == (len(signals) > 1)
    if len(signals) == 1:
        assert elapsed >= GRACE - 0.5  # the command had its grace period
    # the folder says it was interrupted, as after a clean interrupt: nothing in it looks complete
    marker = json.loads((tmp_path / "out" / "PARTIAL").read_text())
    assert marker["status"] == "interrupted" and marker["signal"] == signal.Signals(signals[0]).name
    assert not [p.name for p in (tmp_path / "out").iterdir() if p.name != "PARTIAL"]


@pytest.mark.timeout(30)
def test_without_the_entry_point_a_signal_is_only_recorded(tmp_path: Path) -> None:
    """The rules are armed by the tsmpc entry point only (a library user's or a test's process is
    never ended): without enable(), the busy driver is still running after the grace period."""
    proc = _start(tmp_path, "sleep", armed=False)
    proc.send_signal(signal.SIGTERM)
    time.sleep(GRACE + 2.0)
    alive = proc.poll() is None
    proc.kill()
    proc.wait()
    assert alive


# -- memory: the estimate and the limit ----------------------------------------------------------
def _est(steps: int, methods: tuple[str, ...] = ("ref",), samples: int = 2000, file_bytes: int = 0
         ) -> _memory.MemoryEstimate:
    return _memory.estimate_run(outer_steps=steps, inner_per_outer=10, horizon=10, methods=methods,
                                reference_samples=samples, file_bytes=file_bytes)


def test_the_estimate_counts_the_log_columns() -> None:
    """Per MPC step (Tc/Td = 10 inner steps, N = 10): the engine's buffers (15 + 4 + 33 outer,
    10 x (19 + 10 noise) inner, 10 x 2 flag bytes) and the RunLog (24 + 33 outer, 16-char status;
    10 x 20 inner, a flag, a 16-char status), doubled for temporaries."""
    engine = 8 * (15 + 4 + 33) + 10 * (8 * 19 + 2 + 80)
    runlog = 8 * (21 + 3 + 33) + 64 + 10 * (8 * 20 + 1 + 64)
    per_step = 2 * (engine + runlog)
    a, b = _est(1000), _est(101000)
    assert (b.resident_mb - a.resident_mb) * 2**20 == pytest.approx(100000 * per_step, rel=1e-9)
    two = _est(101000, ("ref", "fzn"))
    assert (two.resident_mb - b.resident_mb) * 2**20 == pytest.approx(2 * 101000 * runlog, rel=1e-9)
    nl = _est(1000, ("ref", "nl"))
    assert nl.virtual_mb - _est(1000, ("ref", "fzn")).virtual_mb == pytest.approx(_memory.VIRTUAL_NL_MB)
    # the file being parsed costs READ_BYTES_FACTOR x its size
    f = _est(1000, file_bytes=100 * 2**20)
    assert f.resident_mb - a.resident_mb == pytest.approx(100 * _memory.READ_BYTES_FACTOR)


@pytest.mark.parametrize(("env", "steps", "refused", "names"), [
    ("1000", 3000, False, None),  # a 5-minute run fits in 1 GB
    ("1000", 2_000_000, True, "TSMPC_MEMORY_LIMIT_MB"),  # 55 h of driving does not
    ("100", 30, True, "TSMPC_MEMORY_LIMIT_MB"),  # below the baseline of any run
    ("-5", 30, True, "must be a positive number"),
    ("lots", 30, True, "must be a positive number"),
    (None, 30, False, None),  # the default: 80 % of this machine's memory
    (None, 10**9, True, "80% of the memory"),
])
def test_the_limit_refuses_what_does_not_fit(monkeypatch: pytest.MonkeyPatch, env: str | None,
                                             steps: int, refused: bool, names: str | None) -> None:
    if env is None:
        monkeypatch.delenv(_memory.ENV_LIMIT, raising=False)
    else:
        monkeypatch.setenv(_memory.ENV_LIMIT, env)
    problem = _memory.memory_problem(_est(steps))
    assert (problem is not None) == refused, problem
    if names:
        assert problem is not None and names in problem


def _cli(args: list[str], *, ulimit_kb: int | None = None, env: dict[str, str] | None = None,
         timeout: float = 60) -> tuple[int, str, float]:
    cmd = [TSMPC, *args]
    if ulimit_kb is not None:
        cmd = ["bash", "-c", f'ulimit -v {ulimit_kb}; exec "$@"', "bash", *cmd]
    t0 = time.monotonic()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                         env={**os.environ, **(env or {})})
    return res.returncode, res.stderr, time.monotonic() - t0


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("LMI design")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kb", [250000, 400000, 500000])
@pytest.mark.parametrize("args", [
    ["run", "--duration", "3", "--no-plots"],
    ["compare", "--methods", "ref,nl", "--duration", "3", "--no-plots"],
])
def test_a_low_ulimit_v_ends_with_one_line(tmp_path: Path, kb: int, args: list[str]) -> None:
    """The reported hang: under ``ulimit -v 400000`` the run spun in OpenBLAS's allocation retries
    for ever. Now: exit 2 at once, one line naming the limit; nothing written."""
    out = tmp_path / "out"
    rc, err, seconds = _cli([*args, "--out", str(out)], ulimit_kb=kb)
    line = _one_line(err)
    assert rc == 2 and seconds < 30, (rc, seconds, err)
    assert "ulimit -v" in line and f"{kb / 1024:.0f} MB" in line, line
    assert not out.exists()


@pytest.mark.timeout(120)
def test_a_ulimit_v_between_the_two_baselines_refuses_only_the_nl_compare(tmp_path: Path) -> None:
    """Above the floor of any run but below what CasADi adds: the compare with NL is refused
    after the inputs are read (naming its estimate), before any design or write."""
    kb = int((_memory.address_space_floor_mb() + 0.5 * _memory.VIRTUAL_NL_MB) * 1024)
    out = tmp_path / "out"
    rc, err, _ = _cli(["compare", "--methods", "ref,nl", "--duration", "3", "--no-plots", "--out",
                       str(out)], ulimit_kb=kb)
    line = _one_line(err)
    assert rc == 2, err
    assert "2 methods need about" in line and "address space" in line, line
    assert not out.exists() or not any(out.iterdir())


def _planned_csv(path: Path, rows: int) -> Path:
    with path.open("w") as fh:
        fh.write("t,x,y,theta,v,omega,kappa\n")
        fh.write("".join(f"{i / 10:.1f},{i / 2:.1f},0,0,5,0,0\n" for i in range(rows)))
    return path


@pytest.mark.parametrize(("window", "duration", "laps", "refused"), [
    (None, None, 1, True),  # 200 000 MPC steps (5.5 h of driving): about 2 GB
    ((1, 50), None, 1, False),  # a window of it
    (None, 5.0, 1, False),  # its first 5 s
    ((1, 150_000), None, 1, True),
    ((1, 50_000), None, 3, True),  # laps multiply the steps
    ((1, 50_000), None, 1, False),
])
def test_the_reference_estimate_before_parsing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               window: tuple[int, int] | None, duration: float | None,
                                               laps: int, refused: bool) -> None:
    monkeypatch.setenv(_memory.ENV_LIMIT, "1000")
    ref = _planned_csv(tmp_path / "ref.csv", 200_000)
    problem = _memory.reference_problem(ref, methods=["ref"], duration=duration, window=window,
                                        laps=laps, Tc=0.1, Td=0.01, horizon=10)
    assert (problem is not None) == refused, problem
    if refused:
        assert problem is not None and problem.startswith(f"--reference {ref}: not enough memory")


def test_the_sample_count_reads_both_file_layouts(tmp_path: Path) -> None:
    planned = _planned_csv(tmp_path / "p.csv", 1000)
    assert _memory.reference_samples_upper(planned) == (1002, False)  # header + rows + 1
    paper = tmp_path / "paper.csv"
    paper.write_text("\n".join(",".join(["1.0"] * 5000) for _ in range(6)) + "\n")
    samples, is_paper = _memory.reference_samples_upper(paper)
    assert is_paper and 5000 - 1 <= samples <= 5000


@pytest.mark.timeout(120)
def test_a_huge_reference_is_refused_quickly(tmp_path: Path) -> None:
    """The reported case, scaled: a 1.5-million-row reference (40 MB) without --duration would run
    150 000 s; it was parsed for minutes and ran out of memory. Refused in seconds, naming the
    limit and the file."""
    ref = _planned_csv(tmp_path / "big.csv", 1_500_000)
    out = tmp_path / "out"
    rc, err, seconds = _cli(["run", "--reference", str(ref), "--no-plots", "--out", str(out)],
                            env={_memory.ENV_LIMIT: "8000"})
    line = _one_line(err)
    assert rc == 2 and seconds < 15, (rc, seconds, err)
    assert line.startswith(f"error: --reference {ref}: not enough memory") and "8000 MB" in line, line
    assert not out.exists()


@pytest.mark.timeout(60)
def test_timeout_ends_a_run_in_its_grace_period(tmp_path: Path) -> None:
    """``timeout``'s SIGTERM in the middle of a real run: exit 143 within the grace period. The run
    is long whatever the machine: NL-MPC (about 20-40x real time) on a 600 s straight reference
    (the built-in circuit's 134 s in the compiled engine take 0.15 s: the signal came after the
    run had finished)."""
    out = tmp_path / "out"
    ref = _planned_csv(tmp_path / "straight.csv", 6001)
    proc = subprocess.Popen([TSMPC, "run", "--method", "nl", "--reference", str(ref), "--no-plots",
                             "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "TSMPC_SIGNAL_GRACE_S": str(GRACE)})
    deadline = time.monotonic() + 30
    while not (out / "PARTIAL").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)  # in the designs, the kernels' loading or the loop
    assert proc.poll() is None, "a 600 s run ended by itself"
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        rc = proc.wait(timeout=GRACE + 6)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail("the run did not end after SIGTERM")
    assert rc == 143
    assert time.monotonic() - t0 < GRACE + 6
    assert "Traceback" not in (proc.stderr.read() if proc.stderr else "")
