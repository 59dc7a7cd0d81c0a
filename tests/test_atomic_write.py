"""Atomic writes under interrupts (tsmpc.io): whatever moment a KeyboardInterrupt (SIGINT) arrives
— here raised the instant the temporary file was created, where ``tempfile.mkstemp`` had not yet
told the caller its name — the previous file stays and no temporary file is left (the random-moment
signal trials once left a ``.PARTIAL.*.tmp`` behind)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tsmpc import io, paths


def _interrupt_after_create(monkeypatch: pytest.MonkeyPatch) -> None:
    real = os.open

    def open_then_interrupt(file: object, flags: int, *args: object, **kwargs: object) -> int:
        fd = real(file, flags, *args, **kwargs)  # type: ignore[arg-type]
        if flags & os.O_EXCL:  # the temporary file, just created
            os.close(fd)
            raise KeyboardInterrupt
        return fd

    monkeypatch.setattr(os, "open", open_then_interrupt)


def test_an_interrupt_as_the_temporary_file_is_created_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "marker.json"
    target.write_text("previous\n")
    _interrupt_after_create(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        io.atomic_write_text(target, "new\n")
    assert target.read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["marker.json"]


def test_an_interrupt_during_a_writability_probe_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _interrupt_after_create(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        paths.folder_problem(tmp_path)
    assert list(tmp_path.iterdir()) == []
