"""Waypoint lists for the planner (SPEC §10): a CSV of ``x,y`` rows [m], optionally with a header
naming its columns (``x``, ``y`` and the optional speed cap ``v`` [m/s] to the next waypoint).

The columns are strict (issue 24): a header may name only those columns, each once; a file
without a header has exactly two columns; every row has as many values as the first; every value
is a plain decimal number (:func:`tsmpc.textfile.number`), finite. Anything else is refused with
the line number — never an ignored column or a converted ``6_0``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tsmpc.errors import DataFormatError
from tsmpc.textfile import number, read_text

__all__ = ["WAYPOINT_COLUMNS", "read_waypoints"]

#: The columns a waypoint CSV may have.
WAYPOINT_COLUMNS = ("x", "y", "v")
#: Largest waypoint file read [bytes].
MAX_WAYPOINT_BYTES = 64 * 1024 * 1024


def _numeric(text: str) -> bool:
    try:
        number(text)
    except ValueError:
        return False
    return True


def read_waypoints(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """(waypoints (n, 2) [m], speed caps (n,) [m/s] or None) from a waypoint CSV."""
    p = Path(path)
    text = read_text(p, "waypoints CSV (x,y rows)", limit=MAX_WAYPOINT_BYTES)
    lines = [(no, ln.strip()) for no, ln in enumerate(text.splitlines(), start=1)]
    lines = [(no, ln) for no, ln in lines if ln and not ln.startswith("#")]
    header: list[str] | None = None
    if lines and not _numeric(lines[0][1].split(",")[0]):
        no, ln = lines.pop(0)
        header = [h.strip().lower() for h in ln.split(",")]
        unknown = [h for h in header if h not in WAYPOINT_COLUMNS]
        if unknown:
            raise DataFormatError(f"{p}:{no}: unknown column {unknown[0][:40]!r} in the header; a "
                                  f"waypoint CSV has the columns {', '.join(WAYPOINT_COLUMNS)} "
                                  "(v optional)")
        if len(set(header)) != len(header) or not {"x", "y"} <= set(header):
            raise DataFormatError(f"{p}:{no}: the header must name x and y once each (and "
                                  "optionally v)")
    width = len(header) if header is not None else 2
    rows = []
    for no, ln in lines:
        parts = ln.split(",")
        if len(parts) != width:
            what = "the header's" if header is not None else "x,y:"
            raise DataFormatError(f"{p}:{no}: {len(parts)} values, expected {width} ({what} "
                                  f"{','.join(header or ['x', 'y'])})")
        try:
            rows.append([number(v) for v in parts])
        except ValueError as err:
            raise DataFormatError(f"{p}:{no}: waypoints must be numeric 'x,y' rows ({err})") from None
    if len(rows) < 2:
        raise DataFormatError(f"{p}: expected at least 2 rows of 'x,y' waypoints")
    data = np.array(rows, dtype=float)
    if not np.all(np.isfinite(data)):
        raise DataFormatError(f"{p}: data row {int(np.argwhere(~np.isfinite(data))[0, 0]) + 1}: "
                              "NaN or inf (waypoints must be finite)")
    ix, iy = (header.index("x"), header.index("y")) if header else (0, 1)
    cap = data[:, header.index("v")] if header and "v" in header else None
    return data[:, [ix, iy]], cap
