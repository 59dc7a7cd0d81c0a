"""The axes of a sweep: their names, shared by :mod:`tsmpc.sweep` (which validates and expands
them) and :mod:`tsmpc.report.sweep_plots` (which plots against them), so neither imports the
other."""

from __future__ import annotations

__all__ = ["AXES"]

_FLOAT_AXES = ("noise_scale", "mass_scale", "inertia_scale", "cornering_scale", "speed_scale")
_CHOICE_AXES = ("method", "friction", "scenario", "track", "seed", "case", "controller")
#: Every axis, in the order of tables and plots.
AXES = ("method", "friction", "scenario", *_FLOAT_AXES, "track", "seed", "case", "controller")
