"""Small file-output helpers shared by every layer (designs, references, runs, sweeps): writes are
atomic (a temporary file in the same folder, fsync, then rename), so a reader never sees a
half-written file and an interrupted run leaves the previous file intact."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_savefig", "atomic_write_bytes", "atomic_write_text", "open_lock_file",
           "overwrite_in_place"]


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        # mkstemp creates 0600; a data file gets the mode open() would give it (0666 & ~umask).
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
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
