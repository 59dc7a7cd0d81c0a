"""Inputs are regular files of bounded size (issue 24): a FIFO, a device, a folder or a socket is
refused *before it is opened for reading* (``tsmpc.textfile.read_bytes``: ``os.stat`` + S_ISREG,
a non-blocking open, the check repeated on the descriptor), for every kind of input file of every
command; every read has a size cap. A FIFO used to block until killed and ``/dev/zero`` was read
until the process held 24 GB.

Each case has a timeout: a hang fails the test instead of the suite.
"""

from __future__ import annotations

import os
import socket
import stat
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app

runner = CliRunner()

#: The kinds of non-regular files and the words the message uses for them (the files' names
#: must not contain those words: the needle would match the path).
KINDS = {"fifo": "FIFO", "dev0": "device", "dir0": "folder", "sock0": "socket", "lnk0": "device"}


@pytest.fixture(scope="module")
def d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("nonreg")
    os.mkfifo(d / "fifo")
    (d / "dir0").mkdir()
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(d / "sock0"))  # the socket file stays after the fixture's socket is gone
    s.close()
    (d / "lnk0").symlink_to("/dev/zero")
    (d / "dev0").symlink_to("/dev/zero")  # /dev/zero itself, by a name in this folder
    # a sparse 300 MB reference: above the 256 MB cap (never read)
    with open(d / "huge.csv", "wb") as fh:
        fh.write(b"t,x,y,theta,v,omega,kappa\n")
        fh.truncate(300 * 1024 * 1024)
    for kind in KINDS:
        (d / f"sweep-base-{kind}.toml").write_text(f'name = "t"\nbase_config = "{kind}"\n')
        (d / f"sweep-track-{kind}.toml").write_text(f'name = "t"\n[grid]\ntrack = ["{kind}"]\n')
        (d / f"sweep-choice-{kind}.toml").write_text(
            f'name = "t"\n[random]\nn = 2\nchoices = {{ track = ["{kind}"] }}\n')
        run = d / f"run-{kind}"
        run.mkdir()
        (run / "metrics.json").write_text("{}")
        target = d / kind
        (run / "timeseries.npz").symlink_to(target)
        mrun = d / f"run-metrics-{kind}"
        mrun.mkdir()
        (mrun / "metrics.json").symlink_to(target)
    (d / "wp.csv").write_text("x,y\n0,0\n60,0\n120,10\n170,40\n")
    return d


def _cases() -> list[tuple[str, list[str], str]]:
    out: list[tuple[str, list[str], str]] = []
    for kind, word in KINDS.items():
        f = f"{{D}}/{kind}"
        out += [
            (f"run-config-{kind}", ["run", "--no-plots", "--out", "{O}", "--config", f], word),
            (f"run-reference-{kind}", ["run", "--no-plots", "--out", "{O}", "--reference", f], word),
            (f"compare-config-{kind}", ["compare", "--out", "{O}", "--config", f], word),
            (f"design-config-{kind}", ["design", "--config", f], word),
            (f"demo-config-{kind}", ["plant-demo", "--config", f], word),
            (f"plan-source-{kind}", ["plan", f, "--out", "{O}.csv"], word),
            (f"show-reference-{kind}", ["show-reference", f, "--out", "{O}.png"], word),
            (f"sweep-file-{kind}", ["sweep", f, "--out", "{O}"], word),
            (f"sweep-base-config-{kind}", ["sweep", f"{{D}}/sweep-base-{kind}.toml", "--out", "{O}"], word),
            (f"sweep-grid-track-{kind}", ["sweep", f"{{D}}/sweep-track-{kind}.toml", "--out", "{O}"],
             "track"),
            (f"sweep-choice-track-{kind}", ["sweep", f"{{D}}/sweep-choice-{kind}.toml", "--out", "{O}"],
             "track"),
            (f"animate-npz-{kind}", ["animate", f"{{D}}/run-{kind}", "--out", "{O}.gif"], word),
            (f"animate-metrics-{kind}", ["animate", f"{{D}}/run-metrics-{kind}", "--out", "{O}.gif"], word),
        ]
    out += [
        ("run-reference-too-large", ["run", "--no-plots", "--out", "{O}", "--reference", "{D}/huge.csv"],
         "too large"),
        ("plan-source-too-large", ["plan", "{D}/huge.csv", "--out", "{O}.csv"], "too large"),
        ("run-reference-dev-null", ["run", "--no-plots", "--out", "{O}", "--reference", "/dev/null"],
         "device"),
        ("run-config-proc-self-mem", ["run", "--no-plots", "--out", "{O}", "--config", "/proc/self/mem"],
         "cannot read"),
        ("plan-track-animate-track-fifo", ["animate", "{D}/run-dir0", "--out", "{O}.gif", "--track",
                                           "{D}/fifo"], "cannot read"),
    ]
    return out


CASES = _cases()


@pytest.mark.timeout(30)
@pytest.mark.parametrize(("argv", "needle"), [pytest.param(a, n, id=i) for i, a, n in CASES])
def test_non_regular_or_huge_input_is_refused_without_reading(d: Path, tmp_path: Path,
                                                               argv: list[str], needle: str) -> None:
    out = tmp_path / "out"
    args = [a.replace("{D}", str(d)).replace("{O}", str(out)) for a in argv]
    res = runner.invoke(app, args)
    text = res.output
    assert "Traceback" not in text
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, text
    shown = text
    for a in sorted(args, key=len, reverse=True):  # the needle must not match a path we passed
        if "/" in a:
            shown = shown.replace(a, "<ARG>")
    assert needle in shown, text
    assert len([ln for ln in text.splitlines() if ln.lower().startswith("error:")]) == 1, text
    assert not out.exists() or not any(out.iterdir())
    assert not Path(f"{out}.csv").exists() and not Path(f"{out}.png").exists()


@pytest.mark.timeout(30)
@pytest.mark.parametrize("kind", list(KINDS))
def test_the_reader_never_opens_a_non_regular_file(d: Path, kind: str) -> None:
    from tsmpc.errors import DataFormatError
    from tsmpc.textfile import first_line, read_bytes, read_head, read_text

    for fn in (read_text, read_bytes, read_head, first_line):
        with pytest.raises(DataFormatError, match=KINDS[kind]):
            fn(d / kind, "thing")


@pytest.mark.timeout(30)
def test_a_file_growing_past_its_cap_is_not_read_past_it(tmp_path: Path, monkeypatch) -> None:
    """The size is checked twice: by stat before the read, and by counting while reading (a
    file that grows in between is refused, never read to its end)."""
    from tsmpc import textfile
    from tsmpc.errors import DataFormatError

    p = tmp_path / "grows.txt"
    p.write_text("x" * 100)
    real = os.stat

    def small_stat(path, *a, **k):  # the file looks small to stat, then turns out large
        st = real(path, *a, **k)
        if Path(path) == p:
            return os.stat_result((st.st_mode, *st[1:6], 10, *st[7:]))
        return st

    monkeypatch.setattr(textfile.os, "stat", small_stat)
    with pytest.raises(DataFormatError, match="too large"):
        textfile.read_text(p, "thing", limit=50)
    assert textfile.read_head(p, "thing", size=50) == "x" * 50


@pytest.mark.timeout(30)
@pytest.mark.parametrize("kind", ["fifo", "dir0", "dev0"])
def test_a_design_cache_entry_that_is_not_a_file_is_resolved_and_named(tmp_path: Path, monkeypatch,
                                                                       capsys, kind: str) -> None:
    """A FIFO, folder or device in place of a cached design: never blocks, never crashes; the
    design is solved again and cached in its place (the atomic rename replaces a FIFO or a
    link), or one line says it could not be cached there (a folder)."""
    from tsmpc.config import Config
    from tsmpc.synthesis import cache

    src = cache.cache_dir()
    cfg = Config()
    key = cache.kinematic_key(cfg)[:32]
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path))
    entry = tmp_path / f"kinematic-{key}.json"
    if kind == "fifo":
        os.mkfifo(entry)
    elif kind == "dir0":
        entry.mkdir()
    else:
        entry.symlink_to("/dev/null")
    assert not stat.S_ISREG(os.stat(entry).st_mode)
    design = cache.load_or_design_kinematic(cfg)
    assert design.S.shape == (3, 3)
    err = capsys.readouterr().err
    if kind == "dir0":
        assert "cannot cache the kinematic design" in err and str(entry) in err
    else:  # healed: the entry is a regular file holding the design, read back next time
        assert stat.S_ISREG(os.lstat(entry).st_mode)
        again = cache.load_or_design_kinematic(cfg)
        assert (again.S == design.S).all()
    del src


def test_every_file_read_of_the_package_goes_through_the_safe_reader() -> None:
    """The mechanism, not the cases: outside tsmpc.textfile (reads) and tsmpc.io (writes), no
    module opens or reads a file itself — so no new input can bypass the regular-file check and
    the size cap."""
    import re

    root = Path(__file__).resolve().parents[1] / "src" / "tsmpc"
    pattern = re.compile(r"\.read_text\(|\.read_bytes\(|(?<![\w.])open\(|\.open\(|np\.load\(\s*[^i]"
                         r"|json\.load\(|tomllib\.load\(|pickle\.load")
    allowed = {"textfile.py", "io.py"}
    offenders = []
    for path in root.rglob("*.py"):
        if path.name in allowed:
            continue
        for no, line in enumerate(path.read_text().splitlines(), start=1):
            code = line.split("#", 1)[0]
            if pattern.search(code) and "os.open(os.devnull" not in code:
                offenders.append(f"{path.relative_to(root)}:{no}: {line.strip()}")
    assert not offenders, "\n".join(offenders)
