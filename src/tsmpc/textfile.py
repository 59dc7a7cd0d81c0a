"""Reading the package's inputs (configs, references, tracks, waypoints, sweep files, caches,
run folders): the one place that opens a file for reading.

Every way a file can be unreadable becomes one :class:`~tsmpc.errors.TsmpcError` line naming the
file and what was expected, before anything is read (issues 12 and 24):

* only a *regular file* is read: a folder, a FIFO, a device (``/dev/zero``) or a socket is refused
  after an ``os.stat``, and the file is opened non-blocking and checked again on the open
  descriptor (a path swapped for a FIFO in between cannot block the process);
* every read has a size cap (``limit``; :data:`MAX_TEXT_BYTES` by default): a larger file is
  refused, and a file that grows while it is read is never read past the cap;
* text must be UTF-8 without NUL bytes (binary files and images are named as such);
* numbers in text data are parsed by :func:`number`: plain decimal literals only (Python's
  ``float`` also takes ``"6_0"`` = 60 and non-ASCII digits).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from tsmpc.errors import DataFormatError, TsmpcError

__all__ = ["MAX_TEXT_BYTES", "first_line", "number", "read_bytes", "read_head", "read_text"]

#: Largest text input read [bytes] by default: the largest planned reference the planner makes
#: (``MAX_SAMPLES`` rows of 7 numbers) is below it.
MAX_TEXT_BYTES = 256 * 1024 * 1024


def _describe(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "is a folder"
    if stat.S_ISFIFO(mode):
        return "is a FIFO (named pipe), not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device, not a regular file"
    if stat.S_ISSOCK(mode):
        return "is a socket, not a regular file"
    return "is not a regular file"


def read_bytes(path: str | Path, what: str, error: type[TsmpcError] = DataFormatError, *,
               limit: int = MAX_TEXT_BYTES, head: bool = False) -> bytes:
    """The bytes of the regular file ``path`` (at most ``limit``; ``head``: the first ``limit``
    bytes of a longer file instead of refusing it). Anything else raises ``error`` naming the
    file and ``what`` it should have been."""
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError as err:
        raise error(f"{p}: cannot read {what}: {err.strerror or err}") from None
    except ValueError as err:  # a NUL byte in the path
        raise error(f"{p!r}: cannot read {what}: invalid path ({err})") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{p}: cannot read {what}: {_describe(st.st_mode)}")
    if st.st_size > limit and not head:
        raise error(f"{p}: {st.st_size} bytes is too large for a {what} (limit {limit} bytes)")
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as err:
        raise error(f"{p}: cannot read {what}: {err.strerror or err}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):  # swapped between stat and open
            raise error(f"{p}: cannot read {what}: {_describe(st.st_mode)}")
        chunks, size = [], 0
        while size <= limit:
            try:
                chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            except InterruptedError:
                continue
            except OSError as err:
                if err.errno == errno.EAGAIN:
                    raise error(f"{p}: cannot read {what}: not ready (not a regular file)") from None
                raise error(f"{p}: cannot read {what}: {err.strerror or err}") from None
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > limit:
        if head:
            return data[:limit]
        raise error(f"{p}: more than {limit} bytes is too large for a {what} (limit {limit} bytes)")
    return data


def read_text(
    path: str | Path, what: str, error: type[TsmpcError] = DataFormatError, *,
    limit: int = MAX_TEXT_BYTES,
) -> str:
    """The UTF-8 text of ``path`` (a regular file of at most ``limit`` bytes); any problem raises
    ``error`` naming the file and ``what`` it should have been (e.g. ``"reference"``)."""
    p = Path(path)
    return _decode(read_bytes(p, what, error, limit=limit), p, what, error)


def _decode(data: bytes, p: Path, what: str, error: type[TsmpcError], partial: bool = False) -> str:
    if b"\x00" in data:
        raise error(f"{p}: binary file, not a {what} (expected UTF-8 text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        if partial and err.start >= len(data) - 3:  # a character cut by the head's end
            return data[:err.start].decode("utf-8")
        raise error(f"{p}: not UTF-8 text (invalid byte at offset {err.start}); "
                    f"expected a {what}") from None


def read_head(path: str | Path, what: str, error: type[TsmpcError] = DataFormatError,
              size: int = 4096) -> str:
    """The first ``size`` bytes of a text file, decoded (same checks as :func:`read_text`): for
    recognising a file's format by its first lines."""
    p = Path(path)
    return _decode(read_bytes(p, what, error, limit=size, head=True), p, what, error, partial=True)


def first_line(path: str | Path, what: str, error: type[TsmpcError] = DataFormatError) -> str:
    """The first line of a text file (same errors as :func:`read_text`, for that line only)."""
    p = Path(path)
    head = read_bytes(p, what, error, limit=4096, head=True)
    line = head.split(b"\n", 1)[0]
    if b"\x00" not in line:
        try:
            return line.decode("utf-8").strip()
        except UnicodeDecodeError:
            pass
    return _decode(head, p, what, error, partial=True).split("\n", 1)[0].strip()  # raises


def number(text: str) -> float:
    """A number of a text data file: a plain decimal literal (``-1.5``, ``2e3``, ``nan``, ``inf``;
    surrounding blanks allowed). Raises ``ValueError`` for anything else — including what
    Python's ``float`` would silently convert: digit separators (``"6_0"`` → 60) and non-ASCII
    digits."""
    if not text.isascii() or "_" in text:
        raise ValueError(f"not a plain decimal number: {text.strip()[:40]!r}")
    return float(text)
