"""The data tsmpc reads but does not ship: the paper's planner reference and the TUMFTM race
tracks — where to download them (pinned commits, pinned SHA-256) and where to find them.

Two datasets:

* ``paper`` — the reference trajectory of the paper's planner (6 rows x_d, y_d, θ_d, v_d, α_d,
  ω_d; one column per 0.1 s), published by the paper's first author with his code in
  the public repository ``euge2838/Autonomous_Guidance_MPC_and_LQR-LMI`` **without a licence**:
  tsmpc downloads it for the user and never redistributes it (no copy in the package, the
  repository or a wheel). The upstream file ``Planner_References_100ms.txt`` is already the
  comma-separated 6-row format tsmpc reads (byte-equal to the copy the project tests with), so
  it is stored unchanged under tsmpc's name ``paper/planner_references_100ms.csv``.
* ``tracks`` — five race tracks of the TUMFTM racetrack-database (centre line and widths,
  ``# x_m,y_m,w_tr_right_m,w_tr_left_m``), LGPL-3.0; the licence text is downloaded with them.

A data folder is laid out as ``paper/planner_references_100ms.csv`` and ``tracks/<Name>.csv``.
:func:`resolve` looks for a dataset, in order, in

1. ``$TSMPC_DATA_DIR`` (a folder laid out as above, e.g. a site's read-only copy);
2. the fetched cache ``<cache>/data`` (:func:`tsmpc.paths.cache_root`: ``$TSMPC_CACHE_DIR`` or
   ``~/.cache/tsmpc``), where :func:`fetch` (``tsmpc data fetch``) writes;
3. ``../shared/data`` beside the repository checkout (only when tsmpc runs from a checkout).

Downloads use pooch: each file goes to a temporary name in the target folder and is moved into
place only when its SHA-256 equals the pinned one (a wrong hash leaves no file). A mirror base
URL (``--mirror`` or ``$TSMPC_DATA_MIRROR``) replaces ``https://raw.githubusercontent.com``: a
mirror serves the same relative paths ``<owner>/<repo>/<commit>/<path>`` (a local folder or
``file://`` URL laid out that way works too, for sites without network).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, unquote, urlsplit

from tsmpc.errors import ConfigError, TsmpcError
from tsmpc.textfile import read_bytes

__all__ = [
    "DATASETS",
    "DATA_DIR_ENV",
    "MIRROR_ENV",
    "UPSTREAM",
    "DataFetchError",
    "DataHashError",
    "DataNotFoundError",
    "Dataset",
    "RemoteFile",
    "cache_data_dir",
    "checkout_data_dir",
    "data_roots",
    "dataset_of",
    "fetch",
    "fetch_command",
    "find",
    "is_dataset_name",
    "label",
    "names",
    "path_or_dataset",
    "resolve",
]

#: Environment variable naming a data folder searched first.
DATA_DIR_ENV = "TSMPC_DATA_DIR"
#: Environment variable naming a mirror base URL (replaces :data:`UPSTREAM`).
MIRROR_ENV = "TSMPC_DATA_MIRROR"
#: Where the files come from: GitHub's raw file server (``<owner>/<repo>/<commit>/<path>``).
UPSTREAM = "https://raw.githubusercontent.com"
#: Seconds without an answer before a download is given up.
TIMEOUT_S = 60.0
#: Largest file a mirror folder may serve [bytes] (the datasets' files are below 1 MB).
MAX_FILE_BYTES = 64 * 1024 * 1024


class DataNotFoundError(TsmpcError, LookupError):
    """A dataset is in none of the data folders; the message names the fetch command."""


class DataFetchError(TsmpcError):
    """A download failed (network, HTTP error, a mirror without the file)."""


class DataHashError(DataFetchError):
    """A downloaded file's SHA-256 is not the pinned one (nothing was written)."""


@dataclass(frozen=True)
class RemoteFile:
    """One file of a dataset: ``path`` (relative to the data folder, where tsmpc reads it) and
    where it comes from: ``source`` = ``<owner>/<repo>/<commit>/<path>`` below the base URL."""

    path: str
    source: str
    sha256: str


@dataclass(frozen=True)
class Dataset:
    """A named set of files with their origin and licence (written next to them as README.txt)."""

    name: str
    folder: str
    files: tuple[RemoteFile, ...]
    origin: str
    licence: str

    @property
    def data_files(self) -> tuple[RemoteFile, ...]:
        """The files commands read (not the licence text)."""
        return tuple(f for f in self.files if f.path.endswith(".csv"))


_PAPER_REPO = "euge2838/Autonomous_Guidance_MPC_and_LQR-LMI"
_PAPER_COMMIT = "33be5e39f4f1a1ed8e11e67506f471094f52f309"
_TUM_REPO = "TUMFTM/racetrack-database"
_TUM_COMMIT = "e59595d1f3573b30d1ded6a08984935b957688e0"

#: The paper's file (tsmpc's name for it) and the race tracks tsmpc's docs and tests use.
PAPER_FILE = "paper/planner_references_100ms.csv"
_TRACKS = {
    "Hockenheim": "5eb6b7d8ff7b9fc905b38caed9a65d8e76e4bd7af5af9ba82aecdf4a6e0eacc5",
    "Monza": "4b5993986e67950df1b89efa03a4df02127f07b7213985917f0bad27ad3d48b6",
    "Silverstone": "27c51454e81780a75c353d3e6c9f73dbbcd1e82139782e95bd722ade19736e39",
    "Spa": "952673dfa772427be8a9013b8c1cb5ff5935f85c0c21d2a223adb04c6d640c8a",
    "Zandvoort": "f3f2a82c9f41bcee8d7161a6ad6c0b8e6d4b902dd772459918c9fe7f7451bc59",
}

#: The registry: dataset name -> :class:`Dataset` (tests substitute their own).
DATASETS: dict[str, Dataset] = {
    "paper": Dataset(
        name="paper", folder="paper",
        files=(RemoteFile(PAPER_FILE,
                          f"{_PAPER_REPO}/{_PAPER_COMMIT}/Trajectory references/Planner_References_100ms.txt",
                          "ab6ba5a3c255bfbe130ad7436752f543387b551f081dde3b4bb48a265690a980"),),
        origin=f"https://github.com/{_PAPER_REPO} (commit {_PAPER_COMMIT}), file "
               "'Trajectory references/Planner_References_100ms.txt': the code repository of the "
               "paper's first author, whose README cites 'TS-MPC for Autonomous Vehicles including a "
               "dynamic TS-MHE-UIO' (Alcalá, Puig, Quevedo)",
        licence="NO LICENCE: the authors published this file with their code without a licence. "
                "Use it to reproduce and test; do not redistribute it (tsmpc downloads it for you "
                "and never ships a copy)."),
    "tracks": Dataset(
        name="tracks", folder="tracks",
        files=(*(RemoteFile(f"tracks/{n}.csv", f"{_TUM_REPO}/{_TUM_COMMIT}/tracks/{n}.csv", h)
                 for n, h in _TRACKS.items()),
               RemoteFile("tracks/LICENSE-LGPL-3.0.txt", f"{_TUM_REPO}/{_TUM_COMMIT}/LICENSE",
                          "e3a994d82e644b03a792a930f574002658412f62407f5fee083f2555c5f23118")),
        origin=f"https://github.com/{_TUM_REPO} (commit {_TUM_COMMIT}), folder 'tracks' "
               "(TUM Institute of Automotive Technology)",
        licence="GNU Lesser General Public License v3.0 (LGPL-3.0): see LICENSE-LGPL-3.0.txt in "
                "this folder."),
}


# -- names -----------------------------------------------------------------------------------
def names() -> list[str]:
    """Every name :func:`resolve` takes: the datasets and each track (lower case)."""
    out = list(DATASETS)
    for ds in DATASETS.values():
        if len(ds.data_files) > 1:
            out += [Path(f.path).stem.lower() for f in ds.data_files]
    return out


def _lookup(name: str) -> tuple[Dataset, str | None]:
    """(dataset, relative path of the one file named, or None for the whole dataset)."""
    key = name.strip().lower()
    if key in DATASETS:
        ds = DATASETS[key]
        return ds, (ds.data_files[0].path if len(ds.data_files) == 1 else None)
    for ds in DATASETS.values():
        for f in ds.data_files:
            if Path(f.path).stem.lower() == key:
                return ds, f.path
    raise KeyError(name)


def is_dataset_name(text: str | os.PathLike[str]) -> bool:
    """True when ``text`` is a bare dataset or track name (``paper``, ``tracks``, ``monza``)."""
    s = os.fspath(text)
    if not s or "/" in s or os.sep in s or "." in s:
        return False
    try:
        _lookup(s)
    except KeyError:
        return False
    return True


def label(track: str | os.PathLike[str]) -> str:
    """A reference's name for tables and figures: ``paper`` (the dataset name or a path to its
    file) -> ``paper reference``, ``monza`` -> ``Monza`` (the file's stem), any other path -> its
    stem. Needs no data on disk."""
    s = os.fspath(track)
    rel = None
    if is_dataset_name(s):
        rel = _lookup(s)[1]
    stem = Path(rel if rel is not None else s).stem
    return "paper reference" if stem == Path(PAPER_FILE).stem else stem


def dataset_of(name: str) -> str:
    """The dataset a name belongs to (``monza`` -> ``tracks``); ``KeyError`` for an unknown name."""
    return _lookup(name)[0].name


def fetch_command(name: str) -> str:
    """The command that downloads what ``name`` needs."""
    try:
        return f"tsmpc data fetch {dataset_of(name)}"
    except KeyError:
        return "tsmpc data fetch all"


# -- where data is ---------------------------------------------------------------------------
def cache_data_dir() -> Path:
    """``<cache>/data``: where :func:`fetch` writes by default."""
    from tsmpc.paths import cache_root

    return cache_root() / "data"


def checkout_data_dir() -> Path | None:
    """``../shared/data`` beside the repository when tsmpc runs from a checkout (``src/tsmpc``
    under a folder holding ``pyproject.toml``), else None (an installed wheel has no checkout)."""
    pkg = Path(__file__).resolve().parent
    if pkg.parent.name != "src" or not (pkg.parents[1] / "pyproject.toml").is_file():
        return None
    return pkg.parents[2] / "shared" / "data"


def data_roots() -> list[tuple[str, Path]]:
    """The folders searched, in order, each with a label for messages."""
    roots: list[tuple[str, Path]] = []
    env = os.environ.get(DATA_DIR_ENV)
    if env:
        roots.append((f"${DATA_DIR_ENV}", Path(env)))
    roots.append(("the cache", cache_data_dir()))
    shared = checkout_data_dir()
    if shared is not None:
        roots.append(("the checkout's ../shared", shared))
    return roots


def _complete(root: Path, files: Iterable[RemoteFile]) -> bool:
    return all((root / f.path).is_file() for f in files)


def find(name: str, roots: Iterable[tuple[str, Path]] | None = None) -> Path | None:
    """The path of dataset or track ``name`` in the first data folder that has it whole (a file
    for ``paper`` or a track, the folder for ``tracks``), else None. ``roots``: (label, folder)
    pairs searched instead of :func:`data_roots`. ``KeyError``: unknown name."""
    ds, rel = _lookup(name)
    wanted = [f for f in ds.data_files if f.path == rel] if rel else list(ds.data_files)
    for _label, root in (data_roots() if roots is None else roots):
        if _complete(root, wanted):
            return root / (rel or ds.folder)
    return None


def resolve(name: str) -> Path:
    """Like :func:`find`, but a missing dataset raises :class:`DataNotFoundError` naming the
    folders searched and the fetch command; an unknown name raises it listing the known ones."""
    try:
        path = find(name)
    except KeyError:
        raise DataNotFoundError(f"unknown dataset {name!r}: one of {', '.join(names())}") from None
    if path is None:
        where = "; ".join(f"{label} {root}" for label, root in data_roots())
        raise DataNotFoundError(f"dataset {name!r} not found (searched {where}); download it with "
                                f"`{fetch_command(name)}`")
    return path


def path_or_dataset(text: str | os.PathLike[str]) -> Path:
    """``text`` as a path when something exists there or it is no dataset name; else the dataset
    it names, resolved (:class:`DataNotFoundError` when not downloaded)."""
    if os.path.lexists(text) or not is_dataset_name(text):
        return Path(text)
    return resolve(os.fspath(text))


# -- download --------------------------------------------------------------------------------
def _base_url(mirror: str | None) -> str:
    base = mirror if mirror is not None else os.environ.get(MIRROR_ENV) or UPSTREAM
    base = base.strip()
    scheme = urlsplit(base).scheme.lower()
    if scheme in ("http", "https", "ftp", "file"):
        return base.rstrip("/")
    if not scheme and base and Path(base).is_dir():  # a local folder laid out like the mirror
        return Path(base).resolve().as_uri()
    what = "--mirror" if mirror is not None else f"${MIRROR_ENV}"
    raise ConfigError(f"{what} {base!r}: not an http(s)://, ftp:// or file:// URL nor an existing "
                     "folder")


def _copy_local(url: str, output_file: object, _pooch: object = None,
                check_only: bool = False) -> bool | None:
    """pooch downloader for ``file://`` mirrors: copy the file (pooch checks the hash)."""
    src = Path(unquote(urlsplit(url).path))
    if check_only:
        return src.is_file()
    data = read_bytes(src, "dataset file", DataFetchError, limit=MAX_FILE_BYTES)  # the safe reader
    try:
        if isinstance(output_file, (str, os.PathLike)):
            Path(output_file).write_bytes(data)
        else:
            output_file.write(data)  # type: ignore[attr-defined]
    except OSError as err:
        raise DataFetchError(f"{url}: cannot copy it ({err.strerror or err})") from None
    return None


def _licence_note(ds: Dataset) -> str:
    files = "\n".join(f"  {Path(f.path).name}  sha256 {f.sha256}" for f in ds.files)
    return (f"tsmpc dataset '{ds.name}', downloaded by `tsmpc data fetch {ds.name}`.\n\n"
            f"Source: {ds.origin}.\n\nLicence: {ds.licence}\n\nFiles:\n{files}\n")


def fetch(which: str = "all", *, mirror: str | None = None, root: Path | None = None,
          progress: Callable[[str], None] | None = None) -> list[Path]:
    """Download dataset ``which`` (``paper``, ``tracks`` or ``all``) into ``root`` (default
    :func:`cache_data_dir`), each file checked against its pinned SHA-256, and write README.txt
    (origin and licence) into each dataset's folder. Files already there with the right hash are
    kept. Returns the paths of the dataset files.

    Raises :class:`DataHashError` for a wrong hash (the file is not written), :class:`DataFetchError`
    for a failed download, :class:`~tsmpc.errors.ConfigError` for a bad ``which`` or mirror and
    :class:`~tsmpc.extras.MissingExtraError` without pooch (the ``[data]`` extra)."""
    from tsmpc.extras import require
    from tsmpc.io import _umask, atomic_write_text

    pooch = require("pooch", "tsmpc data fetch")  # the [data] extra (it brings requests)
    import requests

    key = which.strip().lower()
    if key == "all":
        chosen = list(DATASETS.values())
    elif key in DATASETS:
        chosen = [DATASETS[key]]
    else:
        raise ConfigError(f"unknown dataset {which!r}: one of {', '.join([*DATASETS, 'all'])}")
    base = _base_url(mirror)
    dest = cache_data_dir() if root is None else Path(root)
    pooch.get_logger().setLevel("WARNING")  # tsmpc reports progress itself
    http = pooch.HTTPDownloader(timeout=TIMEOUT_S, progressbar=False)
    out: list[Path] = []
    for ds in chosen:
        for f in ds.files:
            url = f"{base}/{quote(f.source)}"
            target = dest / f.path
            if progress is not None:
                progress(f"{ds.name}: {target.name} <- {url}")
            downloader = _copy_local if url.startswith("file:") else http
            try:
                pooch.retrieve(url, known_hash=f"sha256:{f.sha256}", fname=target.name,
                               path=target.parent, downloader=downloader, progressbar=False)
            except ValueError as err:
                if "hash" in str(err).lower():
                    raise DataHashError(
                        f"{url}: SHA-256 mismatch: the file served is not the pinned {f.path} "
                        f"(expected {f.sha256}); nothing was written") from None
                raise DataFetchError(f"{url}: {err}") from None
            except requests.exceptions.RequestException as err:
                raise DataFetchError(f"{url}: download failed ({_reason(err)})") from None
            except OSError as err:
                raise DataFetchError(f"{target}: cannot write ({err.strerror or err})") from None
            try:  # pooch's temporary file was 0600: give it the mode a plain write would (umask)
                os.chmod(target, 0o666 & ~_umask())
            except OSError as err:
                raise DataFetchError(f"{target}: cannot set its mode ({err.strerror or err})") from None
            if f in ds.data_files:
                out.append(target)
        note = dest / ds.folder / "README.txt"
        try:
            atomic_write_text(note, _licence_note(ds))
        except OSError as err:
            raise DataFetchError(f"{note}: cannot write ({err.strerror or err})") from None
    return out


def _reason(err: Exception) -> str:
    """A short reason for a requests error (the status line of an HTTP error, else its class)."""
    resp = getattr(err, "response", None)
    if resp is not None and getattr(resp, "status_code", None):
        return f"HTTP {resp.status_code} {resp.reason or ''}".strip()
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text[:200]}" if text else type(err).__name__
