"""The paper planner's reference format: 6 comma-separated rows x_d, y_d, θ_d (wrapped),
v_d, α_d (unused), ω_d; one column per 0.1 s. The paper's run uses columns 5…1316 (1-based).

The format has no time column, so the column period is *measured* (beyond the paper): with the planner's
integration convention x(k) = x(k−1) + v(k) cos θ(k) T, the travelled distance per column over v
gives T, and so does Δθ over ω. A file sampled at another period is read at its own period (or
refused when the two measures disagree, or disagree with an explicit ``dt``)."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import numpy as np

from tsmpc.errors import DataFormatError
from tsmpc.planning.reference import CSV_HEADER, Reference, check_consistency, check_window
from tsmpc.textfile import number, read_text

__all__ = [
    "PAPER_COLUMNS",
    "PAPER_DT",
    "PAPER_RUN_WINDOW",
    "column_period",
    "is_paper_run",
    "load_paper_reference",
    "load_reference",
    "paper_window",
    "save_paper_format",
]

#: 1-based inclusive columns of the paper's 127.2 s run (+ the N = 40 look-ahead).
PAPER_RUN_WINDOW = (5, 1316)
#: Column period of the paper's file [s].
PAPER_DT = 0.1
#: Columns of the paper's file.
PAPER_COLUMNS = 2525
#: Relative disagreement between period estimates (or with a given dt) that is refused.
PERIOD_TOL = 0.02


def column_period(data: np.ndarray) -> tuple[float | None, float | None]:
    """(T from positions vs the v row, T from Δθ vs the ω row) [s] of 6-row paper data; None
    where the data cannot say (never moving, never turning). Least squares over the columns that
    move (v > 1 m/s) or turn (|ω| > 1e-3 rad/s)."""
    x, y, th, v, _, w = data
    ds, v1 = np.hypot(np.diff(x), np.diff(y)), v[1:]
    m = v1 > 1.0
    t_pos = float(ds[m] @ v1[m] / (v1[m] @ v1[m])) if np.count_nonzero(m) >= 3 else None
    dth = (np.diff(th) + np.pi) % (2 * np.pi) - np.pi
    w1 = w[1:]
    m = np.abs(w1) > 1e-3
    t_ang = float(dth[m] @ w1[m] / (w1[m] @ w1[m])) if np.count_nonzero(m) >= 3 else None
    return t_pos, t_ang


def _checked_period(p: Path, data: np.ndarray, dt: float | None) -> float:
    """The column period to use: ``dt`` when given and not contradicted by the data, else the
    measured one; raises :class:`DataFormatError` naming the estimates and ``--dt``."""
    t_pos, t_ang = column_period(data)
    est = [t for t in (t_pos, t_ang) if t is not None and t > 0]
    say = ", ".join(f"{name} imply {t:.4g} s" for name, t in
                    (("positions vs v", t_pos), ("Δθ vs ω", t_ang)) if t is not None)
    if len(est) == 2 and abs(est[0] - est[1]) > PERIOD_TOL * max(est):
        if dt is None:
            raise DataFormatError(f"{p}: cannot tell the column period ({say}); "
                                  "pass --dt SECONDS")
        return dt
    if dt is not None:
        if est and abs(est[0] - dt) > PERIOD_TOL * dt:
            raise DataFormatError(f"{p}: --dt {dt:g} s disagrees with the data ({say}); "
                                  f"pass --dt {est[0]:.3g} or omit --dt")
        return dt
    if not est:
        return PAPER_DT  # nothing to measure (a standstill file): the format's nominal period
    return float(f"{est[0]:.3g}")
_ROWS = ("x_d", "y_d", "theta_d", "v_d", "alpha_d", "omega_d")


def load_paper_reference(
    path: str | Path, window: tuple[int, int] | None = PAPER_RUN_WINDOW, dt: float | None = None
) -> Reference:
    """Load a paper-format file; ``window`` = 1-based inclusive columns (None: all).

    ``dt`` None: the column period measured from the data (:func:`column_period`); a given
    ``dt`` the data contradict is refused. θ is unwrapped; κ = ω / v where v > 0.1 m/s (0
    otherwise). Raises :class:`DataFormatError` naming the problem (unreadable, wrong row count,
    text, NaN, bad window, unclear period).
    """
    p = Path(path)
    return _parse_paper(read_text(p, "reference"), p, window, dt)


def _parse_paper(text: str, p: Path, window: tuple[int, int] | None, dt: float | None) -> Reference:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if len(lines) != 6:
        raise DataFormatError(
            f"{p}: paper format needs 6 rows ({', '.join(_ROWS)}), found {len(lines)}")
    rows = []
    for i, ln in enumerate(lines):
        try:
            rows.append([number(v) for v in ln.split(",")])
        except ValueError:
            raise DataFormatError(f"{p}: row {i + 1} ({_ROWS[i]}) has a non-numeric value") from None
    if len({len(r) for r in rows}) != 1:
        raise DataFormatError(f"{p}: rows have different lengths {[len(r) for r in rows]}")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        bad = [_ROWS[i] for i in range(6) if not np.all(np.isfinite(data[i]))]
        raise DataFormatError(f"{p}: NaN or inf values in row(s) {', '.join(bad)}")
    dt = _checked_period(p, data, dt)
    if window is not None:
        a, b = check_window(window, data.shape[1], str(p))
        data = data[:, a - 1 : b]
    x, y, th, v, _, w = data
    n = x.size
    kappa = np.where(np.abs(v) > 0.1, w / np.where(np.abs(v) > 0.1, v, 1.0), 0.0)
    first = (window[0] - 1) if window is not None else 0
    t = (first + np.arange(n)) * dt
    ref = Reference(t, x, y, np.unwrap(th), v, w, kappa)
    check_consistency(ref, str(p), first_sample=first + 1, what="column")
    return ref


def save_paper_format(ref: Reference, path: str | Path) -> None:
    """Write the 6-row paper format (θ wrapped to ±π; α_d = 0), atomically."""
    from tsmpc.io import atomic_write_text

    th = (ref.theta + np.pi) % (2 * np.pi) - np.pi
    rows = [ref.x, ref.y, th, ref.v, np.zeros(len(ref)), ref.omega]
    # repr: the shortest text that reads back to the same double (full precision, any magnitude).
    atomic_write_text(path, "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")


def paper_window(dt: float) -> tuple[int, int]:
    """The paper run's time span (columns 5…1316 at 0.1 s) in the columns of a file sampled at
    ``dt``."""
    a, b = PAPER_RUN_WINDOW
    return round((a - 1) * PAPER_DT / dt) + 1, round((b - 1) * PAPER_DT / dt) + 1


#: References already parsed in this process, by file identity (a sweep worker loads the same
#: file for every run: parsing it cost 15 ms of a 130 ms run). At most _MEMO_SIZE entries.
_MEMO: dict[tuple[Any, ...], Reference] = {}
_MEMO_SIZE = 8


def load_reference(
    path: str | Path, window: tuple[int, int] | None = PAPER_RUN_WINDOW, dt: float | None = None
) -> Reference:
    """Load a paper-format file or a planned CSV (header ``t,x,y,...``); ``window`` = 1-based
    inclusive columns of a paper file or data rows of a planned CSV (None: all).

    A race track or a waypoint list is refused with a hint to plan it first. A file loaded before
    in this process, unchanged since (same inode, size and modification time), is not parsed
    again: the same :class:`Reference` is returned (treat it as read-only)."""
    p = Path(path)
    try:
        st = os.stat(p)
        key: tuple[Any, ...] | None = (str(p.resolve()), st.st_ino, st.st_size, st.st_mtime_ns,
                                       window, dt)
        regular = stat.S_ISREG(st.st_mode)
    except OSError:
        key, regular = None, False  # read_text names the problem
    if key is not None and key in _MEMO:
        return _MEMO[key]
    ref = _load_reference(p, window, dt)
    if key is not None and regular:
        for a in vars(ref).values():  # shared from now on: nobody may write into it
            if isinstance(a, np.ndarray):
                a.flags.writeable = False
        if len(_MEMO) >= _MEMO_SIZE:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[key] = ref
    return ref


def _load_reference(p: Path, window: tuple[int, int] | None, dt: float | None) -> Reference:
    text = read_text(p, "reference")
    first = text.split("\n", 1)[0].strip().replace(" ", "")
    if first == CSV_HEADER:
        ref = Reference.from_csv(p, text=text)
        if window is not None:
            a, b = check_window(window, len(ref), str(p), unit="row")
            ref = ref.slice(a - 1, b)
        return ref
    if first.startswith("#") or not _numeric_row(first):
        kind = "a race track" if first.replace(" ", "") == "#x_m,y_m,w_tr_right_m,w_tr_left_m" \
            else "not a reference"
        raise DataFormatError(
            f"{p}: {kind} (first line {first[:40]!r}); a reference is a planned CSV with the "
            f"header '{CSV_HEADER}' or the 6-row paper format — plan it first with "
            f"`tsmpc plan {p.name} --out ref.csv`")
    return _parse_paper(text, p, window, dt)


def _numeric_row(line: str) -> bool:
    try:
        [number(v) for v in line.split(",")]
    except ValueError:
        return False
    return True


def is_paper_run(full: Reference, window: tuple[int, int] | None, Tc: float) -> bool:
    """True only for the paper's own run: its file (2525 columns at 0.1 s), its window, T_c = 0.1 s —
    the only case in which the paper's Table 5 may be printed beside ours."""
    return (len(full) == PAPER_COLUMNS and abs(full.dt - PAPER_DT) < 1e-9
            and tuple(window or ()) == PAPER_RUN_WINDOW and abs(Tc - PAPER_DT) < 1e-12)
