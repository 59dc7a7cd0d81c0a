"""Reading the package's text inputs (configs, references, tracks, waypoints, sweep files).

One place turns every way a file can be unreadable — missing, a folder, no permission, binary,
not UTF-8 — into one :class:`~tsmpc.errors.TsmpcError` line naming the file and what was expected,
so no input file ever ends in a ``UnicodeDecodeError`` traceback.
"""

from __future__ import annotations

from pathlib import Path

from tsmpc.errors import DataFormatError, TsmpcError

__all__ = ["MAX_TEXT_BYTES", "first_line", "read_text"]

#: Largest text input read [bytes]: the biggest real input (a race track) is < 1 MB.
MAX_TEXT_BYTES = 256 * 1024 * 1024


def read_text(
    path: str | Path, what: str, error: type[TsmpcError] = DataFormatError
) -> str:
    """The UTF-8 text of ``path``; any problem raises ``error`` naming the file and ``what`` it
    should have been (e.g. ``"reference"``)."""
    p = Path(path)
    try:
        if p.is_file() and p.stat().st_size > MAX_TEXT_BYTES:
            raise error(f"{p}: {p.stat().st_size} bytes is too large for a {what} "
                        f"(limit {MAX_TEXT_BYTES} bytes)")
        data = p.read_bytes()
    except OSError as err:
        raise error(f"{p}: cannot read {what}: {err.strerror or err}") from None
    if b"\x00" in data:
        raise error(f"{p}: binary file, not a {what} (expected UTF-8 text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{p}: not UTF-8 text (invalid byte at offset {err.start}); "
                    f"expected a {what}") from None


def first_line(path: str | Path, what: str, error: type[TsmpcError] = DataFormatError) -> str:
    """The first line of a text file (same errors as :func:`read_text`)."""
    text = read_text(path, what, error)
    return text.split("\n", 1)[0].strip()
