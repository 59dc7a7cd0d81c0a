"""``tsmpc data fetch`` and the data resolver (issue 37, item 1).

The fetch runs over real HTTP against a local server (``http.server`` on 127.0.0.1, in a thread)
serving a folder laid out like the upstream (``<owner>/<repo>/<commit>/<path>``), with copies of
the data files the tests use (synthetic bytes where they are missing) and a registry whose hashes
are computed from what is served (the real registry is checked against the real files apart).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import http.server
import os
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from _paths import REQUIRE_DATA_ENV, data_roots, need_data
from tsmpc import datasets
from tsmpc.cli import app

runner = CliRunner()


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class _Server:
    """A threaded HTTP server over ``root`` counting the requests it answered."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.requests: list[str] = []
        outer = self

        class Handler(http.server.SimpleHTTPRequestHandler):
            def log_message(self, *args: object) -> None:  # quiet test output
                pass

            def do_GET(self) -> None:
                outer.requests.append(self.path)
                super().do_GET()

        self.httpd = http.server.ThreadingHTTPServer(
            ("127.0.0.1", 0), functools.partial(Handler, directory=str(root)))
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


def _local_copy(f: datasets.RemoteFile) -> Path | None:
    """The file the tests read for registry entry ``f`` (the real registry's), if any."""
    stem = Path(f.path).stem
    if f.path == datasets.PAPER_FILE:
        return datasets.find("paper", data_roots())
    if f.path.endswith(".csv"):
        return datasets.find(stem, data_roots())
    folder = datasets.find("tracks", data_roots())
    return folder / Path(f.path).name if folder is not None and (folder / Path(f.path).name).is_file() \
        else None


@pytest.fixture
def upstream(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[_Server, dict[str, bytes]]]:
    """The local upstream and the bytes served per data path; the registry is overridden with
    their hashes; the cache, data-dir and mirror variables point nowhere real."""
    site = tmp_path / "site"
    served: dict[str, bytes] = {}
    registry = {}
    for name, ds in datasets.DATASETS.items():
        files = []
        for f in ds.files:
            local = _local_copy(f)
            data = local.read_bytes() if local is not None else f"synthetic {f.path}\n".encode()
            target = site / f.source
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
            served[f.path] = data
            files.append(dataclasses.replace(f, sha256=_sha(data)))
        registry[name] = dataclasses.replace(ds, files=tuple(files))
    monkeypatch.setattr(datasets, "DATASETS", registry)
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(datasets.DATA_DIR_ENV, raising=False)
    monkeypatch.delenv(datasets.MIRROR_ENV, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("no_proxy", "127.0.0.1,localhost")
    server = _Server(site)
    try:
        yield server, served
    finally:
        server.close()


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


def test_fetch_all_over_http(upstream: tuple[_Server, dict[str, bytes]], tmp_path: Path) -> None:
    server, served = upstream
    res = runner.invoke(app, ["data", "fetch", "all", "--mirror", server.url])
    assert res.exit_code == 0, res.output
    data = tmp_path / "cache" / "data"
    mask = os.umask(0o022)
    os.umask(mask)
    for rel, content in served.items():
        assert (data / rel).read_bytes() == content, rel
        assert (data / rel).stat().st_mode & 0o777 == 0o666 & ~mask, rel  # as a plain write, not 0600
    assert len(server.requests) == len(served)
    # the licence is recorded next to each dataset; the paper's says it must not be redistributed
    paper_note = (data / "paper" / "README.txt").read_text(encoding="utf-8")
    assert "NO LICENCE" in paper_note and "do not redistribute" in paper_note
    assert "LGPL-3.0" in (data / "tracks" / "README.txt").read_text(encoding="utf-8")
    assert (data / "tracks" / "LICENSE-LGPL-3.0.txt").is_file()
    # the resolver now finds the fetched files (no TSMPC_DATA_DIR; the cache comes before ../shared)
    assert datasets.resolve("paper") == data / "paper" / "planner_references_100ms.csv"
    assert datasets.resolve("Monza") == data / "tracks" / "Monza.csv"
    # a second fetch keeps the files whose hash is right: nothing is downloaded again
    res = runner.invoke(app, ["data", "fetch", "all", "--mirror", server.url])
    assert res.exit_code == 0, res.output
    assert len(server.requests) == len(served)


def test_wrong_hash_refused_no_file_left(upstream: tuple[_Server, dict[str, bytes]],
                                          tmp_path: Path) -> None:
    server, _served = upstream
    f = datasets.DATASETS["paper"].files[0]
    served_file = server.root / f.source
    served_file.write_bytes(served_file.read_bytes() + b"0\n")  # one byte more than pinned
    res = runner.invoke(app, ["data", "fetch", "paper", "--mirror", server.url])
    assert res.exit_code == 2, res.output
    errors = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "SHA-256 mismatch" in errors[0] and f.sha256 in errors[0]
    assert _leftovers(tmp_path / "cache" / "data") == []  # neither the file nor a temporary one


def test_mirror_environment_variable(upstream: tuple[_Server, dict[str, bytes]], tmp_path: Path,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    server, served = upstream
    monkeypatch.setenv(datasets.MIRROR_ENV, server.url)
    res = runner.invoke(app, ["data", "fetch", "tracks"])
    assert res.exit_code == 0, res.output
    n_tracks = len(datasets.DATASETS["tracks"].files)
    assert len(server.requests) == n_tracks and all(r.startswith("/TUMFTM/") for r in server.requests)
    assert (tmp_path / "cache" / "data" / "tracks" / "Spa.csv").read_bytes() == served["tracks/Spa.csv"]
    # --mirror wins over the variable
    monkeypatch.setenv(datasets.MIRROR_ENV, "http://127.0.0.1:9")
    res = runner.invoke(app, ["data", "fetch", "paper", "--mirror", server.url])
    assert res.exit_code == 0, res.output


def test_network_failures_exit_1(upstream: tuple[_Server, dict[str, bytes]], tmp_path: Path) -> None:
    server, _served = upstream
    (server.root / datasets.DATASETS["paper"].files[0].source).unlink()  # the mirror lacks it: 404
    res = runner.invoke(app, ["data", "fetch", "paper", "--mirror", server.url])
    assert res.exit_code == 1, res.output
    assert "HTTP 404" in res.output and len(res.output.strip().splitlines()) == 2  # progress + error
    res = runner.invoke(app, ["data", "fetch", "paper", "--mirror", "http://127.0.0.1:9"])
    assert res.exit_code == 1, res.output
    assert _leftovers(tmp_path / "cache" / "data") == []
    (tmp_path / "a-file").write_text("", encoding="utf-8")
    for bad in (["data", "fetch", "nope"], ["data", "fetch", "paper", "--mirror", "no-such-folder"],
                ["data", "fetch", "paper", "--mirror", server.url, "--dir", str(tmp_path / "a-file")]):
        res = runner.invoke(app, bad)
        assert res.exit_code == 2 and res.output.count("error:") == 1, res.output


def test_local_folder_mirror(upstream: tuple[_Server, dict[str, bytes]], tmp_path: Path) -> None:
    server, served = upstream
    res = runner.invoke(app, ["data", "fetch", "paper", "--mirror", str(server.root),
                              "--dir", str(tmp_path / "site-data")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "site-data" / datasets.PAPER_FILE).read_bytes() == served[datasets.PAPER_FILE]
    assert server.requests == []


def _layout(root: Path, tag: str) -> None:
    (root / "paper").mkdir(parents=True)
    (root / datasets.PAPER_FILE).write_text(tag, encoding="utf-8")
    (root / "tracks").mkdir()
    for f in datasets.DATASETS["tracks"].data_files:
        (root / f.path).write_text(tag, encoding="utf-8")


def test_resolver_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    env, cache, shared = tmp_path / "env", tmp_path / "cache", tmp_path / "shared"
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(cache))
    monkeypatch.setenv(datasets.DATA_DIR_ENV, str(env))
    monkeypatch.setattr(datasets, "checkout_data_dir", lambda: shared)
    with pytest.raises(datasets.DataNotFoundError) as err:
        datasets.resolve("monza")
    assert "`tsmpc data fetch tracks`" in str(err.value) and str(env) in str(err.value)
    _layout(shared, "shared")
    assert datasets.resolve("paper").read_text(encoding="utf-8") == "shared"
    _layout(cache / "data", "cache")
    assert datasets.resolve("paper").read_text(encoding="utf-8") == "cache"
    assert datasets.resolve("tracks") == cache / "data" / "tracks"
    _layout(env, "env")
    assert datasets.resolve("paper").read_text(encoding="utf-8") == "env"
    assert datasets.resolve("SPA").read_text(encoding="utf-8") == "env"
    # a folder that lacks one track is not where "tracks" is found (it must be whole)
    (env / "tracks" / "Spa.csv").unlink()
    assert datasets.resolve("tracks") == cache / "data" / "tracks"
    assert datasets.resolve("monza").read_text(encoding="utf-8") == "env"
    with pytest.raises(datasets.DataNotFoundError, match="unknown dataset"):
        datasets.resolve("nowhere")


def test_cli_takes_dataset_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monza = need_data("monza")
    data = tmp_path / "data"
    (data / "tracks").mkdir(parents=True)
    (data / "tracks" / "Monza.csv").write_bytes(monza.read_bytes())
    monkeypatch.setenv(datasets.DATA_DIR_ENV, str(data))
    out = tmp_path / "monza_ref.csv"
    res = runner.invoke(app, ["plan", "monza", "--out", str(out), "--v-max", "20"])
    assert res.exit_code == 0, res.output
    assert out.is_file()
    # a dataset found nowhere: one line, exit 2, the fetch command
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "empty-cache"))
    monkeypatch.setattr(datasets, "checkout_data_dir", lambda: None)
    res = runner.invoke(app, ["plan", "spa", "--out", str(tmp_path / "spa.csv")])
    assert res.exit_code == 2 and "`tsmpc data fetch tracks`" in res.output, res.output
    res = runner.invoke(app, ["run", "--reference", "paper", "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "`tsmpc data fetch paper`" in res.output, res.output
    assert not (tmp_path / "run").exists()
    # a file of that name in the working folder is a path, not a dataset name
    monkeypatch.chdir(tmp_path)
    Path("spa").write_text("x,y\n0,0\n50,0\n100,20\n", encoding="utf-8")
    res = runner.invoke(app, ["plan", "spa", "--out", str(tmp_path / "wp.csv"), "--open"])
    assert res.exit_code == 0, res.output


def test_pinned_hashes_are_the_data_tests_use() -> None:
    """The real registry names the very bytes the project tests and measures with."""
    for ds in datasets.DATASETS.values():
        for f in ds.data_files:
            path = need_data("paper" if ds.name == "paper" else Path(f.path).stem)
            assert _sha(path.read_bytes()) == f.sha256, f.path
            assert f.source.count("/") >= 3 and len(f.source.split("/")[2]) == 40  # a pinned commit


def test_missing_data_skips_or_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import _paths

    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(datasets.DATA_DIR_ENV, raising=False)
    monkeypatch.setattr(datasets, "checkout_data_dir", lambda: None)
    monkeypatch.setattr(_paths, "CHECKOUT_DATA", tmp_path / "no-shared")
    # (caught as BaseException: a skip where a failure is due must fail this test, not skip it)
    monkeypatch.delenv(REQUIRE_DATA_ENV, raising=False)
    with pytest.raises(BaseException) as outcome:
        need_data("paper")
    assert outcome.type is pytest.skip.Exception and "`tsmpc data fetch paper`" in str(outcome.value)
    monkeypatch.setenv(REQUIRE_DATA_ENV, "1")
    with pytest.raises(BaseException) as outcome:
        need_data("tracks")
    assert outcome.type is pytest.fail.Exception and "`tsmpc data fetch tracks`" in str(outcome.value)


def test_without_pooch_the_install_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """pooch is the [data] extra: without it the fetch says how to install it (exit 2)."""
    import sys

    monkeypatch.setitem(sys.modules, "pooch", None)  # import pooch -> ImportError
    res = runner.invoke(app, ["data", "fetch", "paper", "--dir", str(tmp_path / "d")])
    assert res.exit_code == 2 and '".[data]"' in res.output and res.output.count("error:") == 1, res.output


def test_where_names_the_folder_or_the_command(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TSMPC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv(datasets.DATA_DIR_ENV, str(tmp_path / "env"))
    monkeypatch.setattr(datasets, "checkout_data_dir", lambda: None)
    res = runner.invoke(app, ["data", "where"])
    assert res.exit_code == 1, res.output
    assert "paper: missing: run `tsmpc data fetch paper`" in res.output
    assert "tracks: missing: run `tsmpc data fetch tracks`" in res.output
    _layout(tmp_path / "env", "env")
    res = runner.invoke(app, ["data", "where"])
    assert res.exit_code == 0, res.output
    assert f"paper: {tmp_path / 'env' / datasets.PAPER_FILE}" in res.output
