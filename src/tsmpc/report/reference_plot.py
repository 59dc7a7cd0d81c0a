"""Figure of a planned reference: path (with track borders), v_d(t) and ω_d(t) (SPEC §10).

Plotting only; matplotlib (Agg) is imported inside the functions so the library never needs it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from tsmpc.planning.reference import Reference
    from tsmpc.planning.tracks import Track

__all__ = ["reference_figure", "save_reference_figure"]


def reference_figure(ref: Reference, track: Track | None = None, title: str | None = None) -> Figure:
    """Three panels: the path x_d–y_d (track borders if given, start marked), v_d(t), ω_d(t)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 4.6), layout="constrained")
    ax_p, ax_v, ax_w = fig.subplots(1, 3, width_ratios=[1.3, 1, 1])
    if track is not None:
        right, left = track.borders()
        for b in (right, left):
            ax_p.plot(*_closed(b).T, color="0.55", lw=0.8)
    ax_p.plot(ref.x, ref.y, color="C0", lw=1.3, label="reference")
    ax_p.plot(ref.x[0], ref.y[0], "o", color="C2", label="start")
    ax_p.annotate("", xy=(ref.x[min(5, len(ref) - 1)], ref.y[min(5, len(ref) - 1)]),
                  xytext=(ref.x[0], ref.y[0]), arrowprops={"arrowstyle": "->", "color": "C2"})
    ax_p.plot(ref.x[-1], ref.y[-1], "s", color="C3", label="end")
    ax_p.set_aspect("equal", adjustable="datalim")
    ax_p.set(xlabel="x [m]", ylabel="y [m]", title=title or "path")
    ax_p.legend(loc="best", fontsize=8)
    ax_v.plot(ref.t, ref.v, color="C0")
    ax_v.set(xlabel="t [s]", ylabel="v_d [m/s]", title="speed")
    ax_w.plot(ref.t, ref.omega, color="C1")
    ax_w.set(xlabel="t [s]", ylabel="ω_d [rad/s]", title="yaw rate")
    for ax in (ax_p, ax_v, ax_w):
        ax.grid(True, alpha=0.3)
    return fig


def save_reference_figure(ref: Reference, path: str | Path, track: Track | None = None,
                          title: str | None = None) -> Path:
    """Write :func:`reference_figure` as a PNG (parent directories created)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    from tsmpc.io import atomic_savefig

    atomic_savefig(reference_figure(ref, track, title), out, dpi=110)
    return out


def _closed(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.vstack([a, a[:1]])
