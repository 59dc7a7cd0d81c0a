"""Figures, tables and reports of runs and sweeps (the ``[report]`` and ``[video]`` extras: matplotlib
and ffmpeg load on first use).

What users import is re-exported here, by name (``from tsmpc.report import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.report.animation import AnimationResult, animate_run
    from tsmpc.report.figures import save_all
    from tsmpc.report.html import render_report, write_report
    from tsmpc.report.mismatch import acceptance, verdict_table
    from tsmpc.report.reference_plot import reference_figure, save_reference_figure
    from tsmpc.report.sweep_plots import save_sweep_plots
    from tsmpc.report.tables import comfort_rows, rmse_markdown, rmse_rows, timing_rows

#: public name → the submodule that defines it
_EXPORTS = {
    "AnimationResult": "animation",
    "acceptance": "mismatch",
    "animate_run": "animation",
    "comfort_rows": "tables",
    "reference_figure": "reference_plot",
    "render_report": "html",
    "rmse_markdown": "tables",
    "rmse_rows": "tables",
    "save_all": "figures",
    "save_reference_figure": "reference_plot",
    "save_sweep_plots": "sweep_plots",
    "timing_rows": "tables",
    "verdict_table": "mismatch",
    "write_report": "html",
}

__all__ = [
    "AnimationResult", "acceptance", "animate_run", "comfort_rows", "reference_figure", "render_report",
    "rmse_markdown", "rmse_rows", "save_all", "save_reference_figure", "save_sweep_plots", "timing_rows",
    "verdict_table", "write_report",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
