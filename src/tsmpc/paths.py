"""Where tsmpc keeps its caches (LMI designs, compiled kernels), and whether a folder is usable.

``$TSMPC_CACHE_DIR`` when set (honoured as given: the CLI refuses it with one line when it is not
a writable folder), else ``$HOME/.cache/tsmpc``. When ``HOME`` is empty or relative (a service
account, ``HOME=""``) — which used to put the cache at ``/.cache/tsmpc`` — or that folder cannot
be written, the explicit fallback is a private per-user folder in the temporary directory
(``/tmp/tsmpc-cache-<uid>``, mode 0700, refused if another user owns it), announced once on
stderr (issue 24).
"""

from __future__ import annotations

import os
import stat
import sys
import tempfile
from pathlib import Path

from tsmpc.io import new_private_file

__all__ = ["cache_root", "folder_problem", "private_fallback"]

_NOTED: set[str] = set()


def folder_problem(path: Path, *, create: bool = True) -> str | None:
    """None when ``path`` is (or can be made) a folder this process can write; else why not."""
    try:
        if create and not os.path.lexists(path):
            path.mkdir(parents=True, exist_ok=True)
        st = os.stat(path)
    except OSError as err:
        return f"cannot create it ({err.strerror or err})"
    except ValueError as err:
        return f"invalid path ({err})"
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a folder"
    tmp: list[Path] = []
    try:
        try:  # (the probe's name is known before it exists: an interrupt cannot leave it behind)
            os.close(new_private_file(path, ".tsmpc-probe-", "", tmp))
        finally:
            if tmp:
                tmp[0].unlink(missing_ok=True)
    except OSError as err:
        return f"cannot write there ({err.strerror or err})"
    return None


def private_fallback() -> Path:
    """``<tmp>/tsmpc-cache-<uid>``: created 0700; raises ``OSError`` when it exists but is not a
    private folder of this user (someone else's folder must never hold our compiled code)."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    path = Path(tempfile.gettempdir()) / f"tsmpc-cache-{uid}"
    try:
        path.mkdir(mode=0o700)
    except FileExistsError:
        pass
    st = os.lstat(path)
    if not stat.S_ISDIR(st.st_mode) or (hasattr(os, "getuid") and st.st_uid != uid) \
            or st.st_mode & 0o022:
        raise OSError(f"{path} is not a private folder of this user")
    return path


def _note(why: str, path: Path) -> None:
    if why not in _NOTED:
        _NOTED.add(why)
        print(f"tsmpc: {why}: caching in {path} (set TSMPC_CACHE_DIR to choose)", file=sys.stderr)


def cache_root() -> Path:
    """The cache folder (see the module docstring)."""
    env = os.environ.get("TSMPC_CACHE_DIR")
    if env:
        return Path(env)
    home = os.environ.get("HOME")
    why = None
    if home is not None and not (home and os.path.isabs(home)):
        why = f"HOME={home!r} is not a usable home folder"
    else:
        try:
            default = Path.home() / ".cache" / "tsmpc"
        except (KeyError, RuntimeError):
            why, default = "no home folder", None
        if default is not None:
            problem = folder_problem(default)
            if problem is None:
                return default
            why = f"{default}: {problem}"
    try:
        path = private_fallback()
    except OSError as err:  # nowhere safe: the caller's writes fail and are reported there
        _note(f"{why}; and the fallback is unusable ({err})", Path(tempfile.gettempdir()))
        return Path(tempfile.gettempdir()) / f"tsmpc-cache-{os.getpid()}-unusable"
    _note(why or "no cache folder", path)
    return path
