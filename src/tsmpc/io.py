"""Small file-output helpers shared by every layer (designs, references, runs, sweeps): writes are
atomic (a temporary file in the same folder, fsync, then rename), so a reader never sees a
half-written file and an interrupted run leaves the previous file intact."""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_savefig", "atomic_write_bytes", "atomic_write_text", "new_private_file", "open_lock_file",
           "overwrite_in_place"]


def new_private_file(folder: Path, prefix: str, suffix: str, tmp: list[Path]) -> int:
    """Create a new file ``folder/prefix<random>suffix`` (``O_EXCL``, mode 0666 & ~umask, as
    ``open()`` gives a data file) and return its descriptor. Its path goes into ``tmp`` *before*
    it is created, so a caller's clean-up (``try``/``except BaseException``) knows the file
    whatever moment an interrupt arrives (``tempfile.mkstemp`` returns the name only after
    creating the file: a SIGINT inside it left the file behind)."""
    for _ in range(100):
        tmp[:] = [folder / f"{prefix}{secrets.token_hex(6)}{suffix}"]
        try:
            return os.open(tmp[0], os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:  # someone else's file: not ours to remove
            tmp.clear()
            continue
    raise FileExistsError(f"{folder}: no free temporary name after 100 tries")


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder + rename); an
    interrupt at any moment leaves the previous file and no temporary file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp: list[Path] = []
    try:
        fd = new_private_file(path.parent, f".{path.name}.", ".tmp", tmp)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp[0], path)
    except BaseException:
        if tmp:
            tmp[0].unlink(missing_ok=True)
        raise


def _umask() -> int:
    # os.umask can only be read by setting it; set it back at once.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_savefig(fig: object, path: str | Path, **kwargs: object) -> None:
    """Save a matplotlib figure atomically: rendered in memory (format from the suffix), then
    written by :func:`atomic_write_bytes` — an interrupt or a full disk leaves no partial or
    temporary file."""
    import io

    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".").lower() or "png", **kwargs)  # type: ignore[attr-defined]
    atomic_write_bytes(path, buf.getvalue())


def overwrite_in_place(path: str | Path, data: bytes) -> None:
    """Rewrite the existing regular file ``path`` in place (no new file: works on a full disk for
    a small file that already owns its blocks, where :func:`atomic_write_bytes` cannot). For
    small status files only (a reader may see a half-written file while it runs)."""
    import stat

    fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(f"{path}: not a regular file")
        os.write(fd, data)
        os.ftruncate(fd, len(data))
    finally:
        os.close(fd)


def open_lock_file(path: Path) -> int:
    """A descriptor of the lock file ``path`` for ``fcntl.flock`` (created empty when missing,
    never written): a regular file only, not followed through a symbolic link, and a FIFO at the
    path never blocks the open. Raises OSError (the caller then works without the lock)."""
    import errno
    import stat

    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    fd = os.open(path, flags, 0o644)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    return fd


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[bool]:
    """Hold an exclusive ``flock`` on the lock file ``path`` (its folder created) for the block;
    yields whether it holds one. A process that dies releases it. Without ``fcntl`` (Windows), or
    where the lock file cannot be opened (a read-only folder, a FIFO at the path), there is no
    lock (False): the caller's work must be correct without one, the lock only saves doing it
    twice at once."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        fcntl = None  # type: ignore[assignment]
    fd = -1
    if fcntl is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = open_lock_file(path)
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            if fd >= 0:
                os.close(fd)
            fd = -1
    try:
        yield fd >= 0
    finally:
        if fd >= 0:
            os.close(fd)  # (closing releases the flock)
