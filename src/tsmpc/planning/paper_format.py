"""The paper planner's reference format (SPEC §10): 6 comma-separated rows x_d, y_d, θ_d (wrapped),
v_d, α_d (unused), ω_d; one column per 0.1 s. The paper's run uses columns 5…1316 (1-based)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tsmpc.errors import DataFormatError
from tsmpc.planning.reference import CSV_HEADER, Reference, check_consistency, check_window
from tsmpc.textfile import read_text

__all__ = ["PAPER_RUN_WINDOW", "load_paper_reference", "load_reference", "save_paper_format"]

#: 1-based inclusive columns of the paper's 127.2 s run (+ the N = 40 look-ahead).
PAPER_RUN_WINDOW = (5, 1316)
_ROWS = ("x_d", "y_d", "theta_d", "v_d", "alpha_d", "omega_d")


def load_paper_reference(
    path: str | Path, window: tuple[int, int] | None = PAPER_RUN_WINDOW, dt: float = 0.1
) -> Reference:
    """Load a paper-format file; ``window`` = 1-based inclusive columns (None: all).

    θ is unwrapped; κ = ω / v where v > 0.1 m/s (0 otherwise). Raises :class:`DataFormatError`
    naming the problem (unreadable, wrong row count, text, NaN, bad window).
    """
    p = Path(path)
    return _parse_paper(read_text(p, "reference"), p, window, dt)


def _parse_paper(text: str, p: Path, window: tuple[int, int] | None, dt: float) -> Reference:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if len(lines) != 6:
        raise DataFormatError(
            f"{p}: paper format needs 6 rows ({', '.join(_ROWS)}), found {len(lines)}")
    rows = []
    for i, ln in enumerate(lines):
        try:
            rows.append([float(v) for v in ln.split(",")])
        except ValueError:
            raise DataFormatError(f"{p}: row {i + 1} ({_ROWS[i]}) has a non-numeric value") from None
    if len({len(r) for r in rows}) != 1:
        raise DataFormatError(f"{p}: rows have different lengths {[len(r) for r in rows]}")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        bad = [_ROWS[i] for i in range(6) if not np.all(np.isfinite(data[i]))]
        raise DataFormatError(f"{p}: NaN or inf values in row(s) {', '.join(bad)}")
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
    from tsmpc.sim.log import atomic_write_text

    th = (ref.theta + np.pi) % (2 * np.pi) - np.pi
    rows = [ref.x, ref.y, th, ref.v, np.zeros(len(ref)), ref.omega]
    # repr: the shortest text that reads back to the same double (full precision, any magnitude).
    atomic_write_text(path, "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")


def load_reference(
    path: str | Path, window: tuple[int, int] | None = PAPER_RUN_WINDOW, dt: float = 0.1
) -> Reference:
    """Load a paper-format file or a planned CSV (header ``t,x,y,...``); ``window`` = 1-based
    inclusive columns of a paper file or data rows of a planned CSV (None: all).

    A race track or a waypoint list is refused with a hint to plan it first."""
    p = Path(path)
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
        [float(v) for v in line.split(",")]
    except ValueError:
        return False
    return True
