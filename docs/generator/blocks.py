"""Generated blocks of the documentation: one marker scheme for README.md and docs/*.md, and the
drift check that compares a published block with a fresh run's.

Every number the documentation publishes from a run sits between two HTML comments::

    <!-- PRODUCER:NAME:begin -->
    | approach | x | ... |
    <!-- PRODUCER:NAME:end -->

PRODUCER names the section of the generator (``python docs/generate.py``) that runs the real runs
and renders the block; NAME the block. A block written on its own line is a Markdown block (a
table, a list); a block written inside a line (``… measured <!-- p:n:begin -->4.7 s<!-- p:n:end -->
on …``) stays inside its paragraph. The same block may appear in several files (README.md and a
docs page): the generator rewrites every copy.

:func:`drift` compares the text of a published block with the freshly generated one: the words
must agree exactly, every number within a relative tolerance beyond its printed rounding, and
table columns named as timings are skipped (timings depend on the machine)."""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

__all__ = [
    "BlockId",
    "blocks_in",
    "check_files",
    "drift",
    "numbers",
    "read_block",
    "update_block",
]

_MARK = "<!-- {producer}:{name}:{end} -->"
_ANY = re.compile(r"<!-- ([a-z0-9][a-z0-9_-]*):([a-z0-9][a-z0-9_.-]*):begin -->")
#: A number as printed in the docs: optional sign (ASCII or Unicode minus), digits with optional
#: thousands separators and decimals, optional exponent.
_NUM = re.compile(r"(?<![\w.])([-−+]?)(\d{1,3}(?:,\d{3})+|\d+)(\.\d+)?(e[-+]?\d+)?(?![\w])")


@dataclass(frozen=True)
class BlockId:
    """A generated block: the generator section that produces it and its name."""

    producer: str
    name: str

    def __str__(self) -> str:
        return f"{self.producer}:{self.name}"

    def markers(self) -> tuple[str, str]:
        return (_MARK.format(producer=self.producer, name=self.name, end="begin"),
                _MARK.format(producer=self.producer, name=self.name, end="end"))


def _pattern(block: BlockId) -> re.Pattern[str]:
    """Groups: the indentation of a block on its own lines, the newline after the begin marker
    (absent: an inline block), the body."""
    begin, end = block.markers()
    return re.compile(r"(?m)(^[ \t]*)?" + re.escape(begin) + r"(\n?)(.*?)\n?[ \t]*" + re.escape(end),
                      re.S)


def blocks_in(text: str) -> list[BlockId]:
    """Every generated block of ``text``, in order of appearance."""
    return [BlockId(m.group(1), m.group(2)) for m in _ANY.finditer(text)]


def read_block(text: str, block: BlockId) -> str:
    """The body of ``block`` in ``text`` (ValueError when its markers are missing)."""
    m = _pattern(block).search(text)
    if m is None:
        raise ValueError(f"markers of block {block} not found")
    return textwrap.dedent(m.group(3))


def update_block(text: str, block: BlockId, body: str) -> str:
    """``text`` with the body of every copy of ``block`` replaced by ``body``. A block on its own
    lines stays on its own lines; an inline block stays inline (``body`` must then be one line).
    Raises ValueError when the markers are missing (a generator never appends blindly)."""
    begin, end = block.markers()
    pat = _pattern(block)
    if not pat.search(text):
        raise ValueError(f"markers of block {block} not found")

    def sub(m: re.Match[str]) -> str:
        indent = m.group(1) or ""
        if m.group(2):  # a Markdown block (indented inside a list item: every line indented)
            lines = "\n".join((indent + ln) if ln.strip() else "" for ln in body.strip().splitlines())
            return f"{indent}{begin}\n{lines}\n{indent}{end}" if lines else f"{indent}{begin}\n{indent}{end}"
        if "\n" in body.strip():
            raise ValueError(f"block {block} is inline: its body must be one line")
        return f"{indent}{begin}{body.strip()}{end}"

    return pat.sub(sub, text)


def numbers(text: str) -> list[tuple[float, int]]:
    """The numbers printed in ``text`` as (value, decimals), in order."""
    out = []
    for m in _NUM.finditer(text):
        sign, whole, frac, exp = m.groups()
        v = float(whole.replace(",", "") + (frac or "") + (exp or ""))
        out.append((-v if sign in ("-", "−") else v, len(frac) - 1 if frac else 0))
    return out


def _close(a: tuple[float, int], b: tuple[float, int], rel: float) -> bool:
    """Published ``a`` against fresh ``b``: within ``rel`` of the larger magnitude plus the
    rounding of both printed values (half a unit of each one's last printed digit)."""
    (va, da), (vb, db) = a, b
    if math.isclose(va, vb, rel_tol=0.0, abs_tol=0.0):
        return True
    slack = 0.5 * 10.0 ** -da + 0.5 * 10.0 ** -db
    return abs(va - vb) <= rel * max(abs(va), abs(vb)) + slack


def _words(text: str) -> str:
    return " ".join(_NUM.sub("#", text).split())


def _table_rows(text: str) -> tuple[list[str], dict[str, list[str]]] | None:
    """A Markdown table: its header cells and each row's cells keyed by the first cell."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip().startswith("|")]
    if len(lines) < 2 or not re.fullmatch(r"\|(\s*:?-+:?\s*\|)+", lines[1]):
        return None
    def split(ln):
        return ([c.strip() for c in re.split(r"(?<!\\)\|", ln.strip())[1:-1]])
    rows: dict[str, list[str]] = {}
    for ln in lines[2:]:
        cells = split(ln)
        rows[cells[0]] = cells
    return split(lines[0]), rows


def _compare_text(where: str, published: str, fresh: str, rel: float) -> list[str]:
    if _words(published) != _words(fresh):
        return [f"{where}: the text differs:\n    published: {_words(published)[:300]}\n"
                f"    fresh:     {_words(fresh)[:300]}"]
    out = []
    for (pa, fa) in zip(numbers(published), numbers(fresh), strict=True):
        if not _close(pa, fa, rel):
            out.append(f"{where}: published {pa[0]:g}, fresh run {fa[0]:g} (more than "
                       f"{rel:.0%} apart)")
    return out


def _prose(text: str, skip_lines: Sequence[str]) -> str:
    """The lines of ``text`` that are not table rows nor hold one of ``skip_lines``."""
    return "\n".join(ln for ln in text.splitlines() if not ln.strip().startswith("|")
                     and not any(s in ln for s in skip_lines))


def drift(published: str, fresh: str, *, rel: float = 0.02, skip_columns: Iterable[str] = (),
          skip_lines: Sequence[str] = (), rows_only: bool = False, where: str = "block") -> list[str]:
    """What differs between a published block and the freshly generated one (empty: nothing).

    Both texts must read the same once numbers are blanked; every number must agree within
    ``rel`` (relative) beyond the rounding of the printed values. In a Markdown table, the
    columns whose header contains one of ``skip_columns`` (timings) are not compared, and with
    ``rows_only`` the fresh table may hold a subset of the published rows (a shortened check that
    re-runs only some rows: each fresh row is compared with the published row of the same label).
    Text lines holding one of ``skip_lines`` (e.g. "load average") are not compared.
    """
    skip = tuple(skip_columns)
    pt, ft = _table_rows(published), _table_rows(fresh)
    if pt is None or ft is None:
        return _compare_text(where, _prose(published, skip_lines), _prose(fresh, skip_lines), rel)
    out = [] if rows_only else _compare_text(where, _prose(published, skip_lines),
                                              _prose(fresh, skip_lines), rel)
    (ph, prow), (fh, frow) = pt, ft
    if ph != fh:
        return [*out, f"{where}: the table header differs: {ph} vs {fh}"]
    if not rows_only and list(prow) != list(frow):
        return [*out, f"{where}: the rows differ: {list(prow)} vs {list(frow)}"]
    keep = [i for i, h in enumerate(ph) if not any(s in h for s in skip)]
    for label, cells in frow.items():
        if label not in prow:
            out.append(f"{where}: row {label!r} is not published")
            continue
        pc = prow[label]
        if len(pc) != len(cells):
            out.append(f"{where}: row {label!r} has {len(pc)} cells published, {len(cells)} fresh")
            continue
        for i in keep:
            out += _compare_text(f"{where}, row {label!r}, column {ph[i]!r}", pc[i], cells[i], rel)
    return out


def check_files(texts: dict[str, str], fresh: dict[BlockId, str], *, rel: float = 0.02,
                skip_columns: Sequence[str] = (), skip_lines: Sequence[str] = (),
                rows_only: Iterable[BlockId] = ()) -> list[str]:
    """:func:`drift` of every fresh block against every published copy in ``texts`` (file name →
    text). A fresh block no file publishes is reported too."""
    partial = set(rows_only)
    out = []
    for block, body in fresh.items():
        copies = [(f, t) for f, t in texts.items() if block in blocks_in(t)]
        if not copies:
            out.append(f"{block}: published nowhere")
        for fname, text in copies:
            out += drift(read_block(text, block), body, rel=rel, skip_columns=skip_columns,
                         skip_lines=skip_lines, rows_only=block in partial, where=f"{fname} {block}")
    return out
