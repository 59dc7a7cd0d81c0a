"""Types that users' tools accept (issue 37 item 4): mypy (with the pydantic plugin) and pyright
report no error on src/ nor on the Python examples of README.md and docs/*.md, checked as a
user's own files (tests/_snippets.py). Configuration: pyproject's [tool.mypy] and [tool.pyright].

The two checkers run at once, as subprocesses (one each of the machine's two cores); on a busy
machine pyright alone takes minutes, hence the generous timeout.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from _snippets import extract

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "tsmpc"
TIMEOUT_S = 1800
_MYPY_ERROR = re.compile(r"^(?P<file>[^:\n]+):\d+: error: ", re.M)


def _require(module: str) -> None:
    if importlib.util.find_spec(module) is None:
        pytest.fail(f"{module} is not installed: pip install -e '.[test]'")


def _start(cmd: list[str]) -> subprocess.Popen[str]:
    env = {**os.environ, "PYRIGHT_PYTHON_IGNORE_WARNINGS": "1", "NO_COLOR": "1"}
    env.pop("MYPYPATH", None)
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def _finish(proc: subprocess.Popen[str], what: str) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(f"{what} did not finish in {TIMEOUT_S} s")
    return proc.returncode, out, err


def _split(files: list[str], snippets: Path) -> tuple[list[str], list[str]]:
    """(errors in src/, errors in the snippets) from the files the errors name."""
    snip = [f for f in files if Path(f).resolve().is_relative_to(snippets.resolve())]
    return [f for f in files if f not in snip], snip


def run_checkers(snippets: Path) -> dict[str, tuple[list[str], list[str], str]]:
    """{checker: (its errors in src, its errors in the snippets, its report)}, both run at once."""
    mypy = _start([sys.executable, "-m", "mypy", "--no-color-output", "--no-error-summary",
                   "--show-error-codes", str(SRC), str(snippets)])
    pyright = _start([sys.executable, "-m", "pyright", "--outputjson",
                      "--pythonpath", sys.executable, str(SRC), str(snippets)])
    m_rc, m_out, m_err = _finish(mypy, "mypy")
    p_rc, p_out, p_err = _finish(pyright, "pyright")
    # mypy: 0 clean, 1 errors found, 2 a crash or bad usage (no file to blame: fail loudly)
    assert m_rc in (0, 1), f"mypy failed (exit {m_rc}): {m_out[-3000:]}{m_err[-3000:]}"
    m_lines = [line for line in m_out.splitlines() if ": error: " in line]
    m_files = [m.group("file") for m in _MYPY_ERROR.finditer(m_out)]
    try:
        report = json.loads(p_out)
    except json.JSONDecodeError:
        pytest.fail(f"pyright failed (exit {p_rc}): {p_out[-3000:]}{p_err[-3000:]}")
    diags = [d for d in report["generalDiagnostics"] if d["severity"] == "error"]
    assert report["summary"]["errorCount"] == len(diags)
    p_lines = [f"{d['file']}:{d['range']['start']['line'] + 1}: {d['message']} ({d.get('rule', '')})"
               for d in diags]
    return {"mypy": (*_split(m_files, snippets), "\n".join(m_lines)),
            "pyright": (*_split([d["file"] for d in diags], snippets), "\n".join(p_lines))}


@pytest.mark.slow
def test_mypy_and_pyright_accept_src_and_the_docs_examples(tmp_path: Path) -> None:
    _require("mypy")
    _require("pyright")
    snippets = tmp_path / "snippets"
    written = extract(snippets)
    assert len(written) >= 5, f"the docs' Python examples were not found: {sorted(written)}"
    results = run_checkers(snippets)
    for name, (src_errors, snip_errors, _) in results.items():
        print(f"{name}: {len(src_errors)} errors in src/, {len(snip_errors)} in the "
              f"{len(written)} examples")
    failed = {name: _name_pages(report, written) for name, (a, b, report) in results.items() if a or b}
    assert not failed, "\n\n".join(f"{name}:\n{report[-6000:]}" for name, report in failed.items())


def _name_pages(report: str, written: dict[Path, tuple[Path, int]]) -> str:
    """The report with each snippet's file named by its page and block (what a reader edits)."""
    for f, (page, i) in written.items():
        where = f"{page.relative_to(ROOT)} (python block {i})"
        report = report.replace(str(f.resolve()), where).replace(str(f), where)
    return report
