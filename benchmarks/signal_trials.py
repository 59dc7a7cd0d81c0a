"""SIGINT/SIGTERM at random moments of `tsmpc run` (issue 24): how many trials end as promised —
exit 130/143, PARTIAL "interrupted" with the signal's name, no traceback, no temporary file.

Each trial starts ``python -m tsmpc run`` (figures on, so the moment can fall in the design load,
the kernel load, the simulation loop, the figure or the report writing), waits until its PARTIAL
marker appears, sleeps a random delay and sends the signal. A trial whose run finished before the
signal arrived is not counted (it is re-drawn with a shorter delay): the process had exited, or
had already decided its exit code — exit 0 with a complete folder (no PARTIAL, metrics.json and
report.html written); from that decision on the entry point blocks the signals, so a signal can
no longer kill the process mid-shutdown.

    python benchmarks/signal_trials.py --trials 100 --jobs 2

tests/test_signals.py runs 20 trials of the same function in CI.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Trial:
    """One interrupted run: what it was sent, when, and how it ended."""

    signal: int
    delay_s: float
    returncode: int | None
    marker: dict | None
    output: str
    leftovers: tuple[str, ...]
    landed: bool  #: the signal arrived while the run was still going

    @property
    def ok(self) -> bool:
        """Ended as promised: 128 + signal, PARTIAL interrupted naming the signal, one line."""
        name = signal.Signals(self.signal).name
        return (self.returncode == 128 + self.signal and self.marker is not None
                and self.marker.get("status") == "interrupted" and self.marker.get("signal") == name
                and "Traceback" not in self.output and "SystemError" not in self.output
                and "Exception ignored" not in self.output
                and not self.leftovers)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def trial(sig: int, delay_s: float, folder: Path, duration_s: float = 20.0,
          plots: bool = True) -> Trial:
    """Start a run into ``folder``/out, send ``sig`` ``delay_s`` after its PARTIAL appears."""
    out = folder / "out"
    cmd = [sys.executable, "-m", "tsmpc", "run", "--duration", str(duration_s), "--out", str(out)]
    if not plots:
        cmd.append("--no-plots")
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    landed = False
    try:
        deadline = time.monotonic() + 300
        while not (out / "PARTIAL").exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(delay_s)
        if proc.poll() is None:
            proc.send_signal(sig)
            landed = True
        text, _ = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    marker = None
    try:
        marker = json.loads((out / "PARTIAL").read_text())
    except (OSError, ValueError):
        pass
    left = tuple(p.name for p in out.iterdir() if ".tmp" in p.name) if out.is_dir() else ()
    complete = marker is None and (out / "metrics.json").is_file() and (out / "report.html").is_file()
    if proc.returncode == 0 and complete:
        landed = False  # sent after the run had decided to exit 0 with all its files
    return Trial(sig, delay_s, proc.returncode, marker, text, left, landed)


def run_trials(n: int, *, jobs: int = 2, seed: int = 0, max_delay_s: float = 4.0,
               duration_s: float = 20.0) -> list[Trial]:
    """``n`` landed trials, half SIGINT and half SIGTERM, at seeded random delays."""
    rng = random.Random(seed)
    plan = [(signal.SIGINT if i % 2 else signal.SIGTERM, rng.uniform(0.0, max_delay_s), i % 4 != 3)
            for i in range(n)]

    def one(item: tuple[int, float, bool]) -> Trial:
        sig, delay, plots = item
        for _ in range(6):
            with tempfile.TemporaryDirectory(prefix="tsmpc-sig-") as tmp:
                t = trial(sig, delay, Path(tmp), duration_s=duration_s, plots=plots)
            if t.landed:
                return t
            delay *= 0.5  # the run was faster than the delay: try an earlier moment
        return t

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(one, plan))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    t0 = time.perf_counter()
    trials = run_trials(args.trials, jobs=args.jobs, seed=args.seed)
    landed = [t for t in trials if t.landed]
    ok = [t for t in landed if t.ok]
    for t in landed:
        if not t.ok:
            print(f"FAILED: {signal.Signals(t.signal).name} after {t.delay_s:.2f} s: exit "
                  f"{t.returncode}, marker {t.marker}, leftovers {t.leftovers}\n{t.output[-800:]}")
    by = {s: sum(1 for t in ok if t.signal == s) for s in (signal.SIGINT, signal.SIGTERM)}
    print(f"{len(ok)}/{len(landed)} landed trials ended as promised (SIGINT {by[signal.SIGINT]}, "
          f"SIGTERM {by[signal.SIGTERM]}); {len(trials) - len(landed)} runs finished before the "
          f"signal; {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
