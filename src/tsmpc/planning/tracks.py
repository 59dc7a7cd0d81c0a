"""Real race tracks in the TUMFTM racetrack-database format (the paper's scenario).

A file is a closed centre line with the widths to the right and left track borders::

    # x_m,y_m,w_tr_right_m,w_tr_left_m
    0.693929,-2.314857,6.405,6.679
    ...

The track is kept (with its widths) for plots and off-track checks; :func:`plan_track` turns its
centre line into a closed-lap :class:`~tsmpc.planning.reference.Reference`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tsmpc.config import PlannerSettings
from tsmpc.errors import DataFormatError
from tsmpc.planning.reference import Reference

#: Largest width from the centre line to a border [m] (the widest circuits are ~20 m wide in all).
MAX_WIDTH_M = 100.0

__all__ = ["MAX_WIDTH_M", "TUMFTM_HEADER", "Track", "is_tumftm", "lateral_offset", "load_tumftm",
           "off_track", "plan_track"]

TUMFTM_HEADER = "# x_m,y_m,w_tr_right_m,w_tr_left_m"


@dataclass(frozen=True)
class Track:
    """A closed race track (the paper's scenario).

    Attributes:
        name: track name (the file stem).
        x: (n,) centre line X [m], in driving order; the loop closes from the last point to the first.
        y: (n,) centre line Y [m].
        w_right: (n,) distance from the centre line to the right border [m].
        w_left: (n,) distance from the centre line to the left border [m].
    """

    name: str
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    w_right: NDArray[np.float64]
    w_left: NDArray[np.float64]

    def __post_init__(self) -> None:
        n = None
        for field in ("x", "y", "w_right", "w_left"):
            a = np.ascontiguousarray(getattr(self, field), dtype=float).reshape(-1)
            if n is None:
                n = a.size
            if a.size != n:
                raise DataFormatError(f"track {self.name}: {field} has {a.size} points, x has {n}")
            if not np.all(np.isfinite(a)):
                raise DataFormatError(f"track {self.name}: {field} contains NaN or inf")
            a.setflags(write=False)
            object.__setattr__(self, field, a)
        if n is None or n < 4:
            raise DataFormatError(f"track {self.name}: needs at least 4 centre-line points")
        if np.any(self.w_right <= 0) or np.any(self.w_left <= 0):
            raise DataFormatError(f"track {self.name}: track widths must be positive")
        wide = np.flatnonzero(np.maximum(self.w_right, self.w_left) > MAX_WIDTH_M)
        if wide.size:
            k = int(wide[0])
            raise DataFormatError(f"track {self.name}: point {k + 1}: a width of "
                                  f"{max(self.w_right[k], self.w_left[k]):.4g} m; widths must be "
                                  f"<= {MAX_WIDTH_M:g} m")
        from tsmpc.planning.reference import check_coordinates

        check_coordinates(self.x, self.y, f"track {self.name}")

    @property
    def centre(self) -> NDArray[np.float64]:
        """(n, 2) centre line [m]."""
        return np.stack([self.x, self.y], axis=1)

    @property
    def length(self) -> float:
        """Length of the closed centre-line polygon [m]."""
        c = np.vstack([self.centre, self.centre[:1]])
        return float(np.sum(np.hypot(*np.diff(c, axis=0).T)))

    def borders(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(right, left) border polylines, each (n, 2) [m] (for plots)."""
        c = np.vstack([self.centre[-1:], self.centre, self.centre[:1]])
        tang = c[2:] - c[:-2]
        tang /= np.maximum(np.hypot(tang[:, 0], tang[:, 1]), 1e-12)[:, None]
        normal = np.stack([-tang[:, 1], tang[:, 0]], axis=1)  # to the left
        return self.centre - normal * self.w_right[:, None], self.centre + normal * self.w_left[:, None]


def is_tumftm(path: str | Path) -> bool:
    """True if the file starts with the TUMFTM header (spaces ignored)."""
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import first_line

    try:  # never opens a FIFO or a device: the loader then names what the path is
        first = first_line(path, "track")
    except TsmpcError:
        return False
    return first.replace(" ", "").strip() == TUMFTM_HEADER.replace(" ", "")


def load_tumftm(path: str | Path) -> Track:
    """Load a TUMFTM track CSV; malformed files raise :class:`DataFormatError` naming the problem."""
    from tsmpc.textfile import number, read_text

    p = Path(path)
    lines = read_text(p, "track (TUMFTM CSV)").splitlines()
    if not lines or lines[0].replace(" ", "").strip() != TUMFTM_HEADER.replace(" ", ""):
        raise DataFormatError(f"{p}: not a TUMFTM track: the first line must be '{TUMFTM_HEADER}'")
    rows = []
    for no, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(",")
        if len(parts) != 4:
            raise DataFormatError(f"{p}:{no}: expected 4 values x,y,w_right,w_left, got {len(parts)}")
        try:
            rows.append([number(v) for v in parts])
        except ValueError:
            raise DataFormatError(f"{p}:{no}: non-numeric value in {line.strip()!r}") from None
    if len(rows) < 4:
        raise DataFormatError(f"{p}: a track needs at least 4 centre-line points, found {len(rows)}")
    a = np.array(rows)
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(a), axis=1))[0])
        raise DataFormatError(f"{p}: NaN or inf on data row {bad + 1}")
    if np.allclose(a[0, :2], a[-1, :2]):
        a = a[:-1]  # a repeated first point: the loop closes implicitly
    try:
        track = Track(p.stem, a[:, 0], a[:, 1], a[:, 2], a[:, 3])
        from tsmpc.planning.planner import check_waypoints

        check_waypoints(track.centre, closed=True)
    except DataFormatError as err:
        raise DataFormatError(f"{p}: {err}") from None
    return track


def plan_track(track: Track, settings: PlannerSettings, dt: float = 0.1, laps: int = 1,
               tail_s: float = 0.0) -> Reference:
    """A closed-lap reference along the centre line of ``track`` (the paper's scenario).

    The lap time is a whole number of samples; ``tail_s`` > 0 continues along the next lap (and
    returns an open reference) for an MPC's look-ahead.
    """
    from tsmpc.planning.planner import plan_path

    return plan_path(track.centre, settings, closed=True, dt=dt, laps=laps, tail_s=tail_s)


def lateral_offset(track: Track, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """Signed distance [m] of points (x, y) from the centre line (positive to the left of the
    driving direction), measured to the nearest centre-line segment."""
    off, _, _ = _project(track, x, y)
    return off


def off_track(track: Track, x: ArrayLike, y: ArrayLike, margin: float = 0.0) -> NDArray[np.bool_]:
    """True where (x, y) lies beyond a border (less than ``margin`` [m] inside it counts too)."""
    off, wr, wl = _project(track, x, y)
    return (off > wl - margin) | (off < -(wr - margin))


def _project(track: Track, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # (not in scipy's stubs)

    q = np.stack([np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)], axis=1)
    c = track.centre
    n = c.shape[0]
    # Nearest vertex, then the best of the segments around it (and a few more for tight spots).
    _, iv = cKDTree(c).query(q)
    best = np.full(q.shape[0], np.inf)
    off = np.zeros(q.shape[0])
    wr = np.zeros(q.shape[0])
    wl = np.zeros(q.shape[0])
    for shift in (-2, -1, 0, 1):
        i0 = np.mod(iv + shift, n)
        i1 = np.mod(i0 + 1, n)
        p0, p1 = c[i0], c[i1]
        d = p1 - p0
        seg2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
        u = np.clip(np.sum((q - p0) * d, axis=1) / seg2, 0.0, 1.0)
        foot = p0 + u[:, None] * d
        dist = np.hypot(*(q - foot).T)
        side = np.sign(d[:, 0] * (q[:, 1] - p0[:, 1]) - d[:, 1] * (q[:, 0] - p0[:, 0]))
        better = dist < best
        best = np.where(better, dist, best)
        off = np.where(better, side * dist, off)
        wr = np.where(better, (1 - u) * track.w_right[i0] + u * track.w_right[i1], wr)
        wl = np.where(better, (1 - u) * track.w_left[i0] + u * track.w_left[i1], wl)
    return off, wr, wl
