"""References: the planner from waypoints to a timed reference, the built-in circuit,
the paper's reference format, TUMFTM race tracks, and the plan's feasibility check and re-timing.

What users import is re-exported here, by name (``from tsmpc.planning import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.planning.feasibility import PlanCheck, check_plan, feasible_plan
    from tsmpc.planning.paper_format import load_paper_reference, load_reference, save_paper_format
    from tsmpc.planning.planner import plan_path
    from tsmpc.planning.reference import Reference
    from tsmpc.planning.retime import retime_for_force_budget
    from tsmpc.planning.tracks import Track, load_tumftm, plan_track
    from tsmpc.planning.waypoints import read_waypoints

#: public name → the submodule that defines it
_EXPORTS = {
    "PlanCheck": "feasibility",
    "Reference": "reference",
    "Track": "tracks",
    "builtin_circuit": "circuit",
    "check_plan": "feasibility",
    "feasible_plan": "feasibility",
    "load_paper_reference": "paper_format",
    "load_reference": "paper_format",
    "load_tumftm": "tracks",
    "plan_path": "planner",
    "plan_track": "tracks",
    "read_waypoints": "waypoints",
    "retime_for_force_budget": "retime",
    "save_paper_format": "paper_format",
}

__all__ = [
    "PlanCheck", "Reference", "Track", "builtin_circuit", "check_plan", "feasible_plan",
    "load_paper_reference", "load_reference", "load_tumftm", "plan_path", "plan_track", "read_waypoints",
    "retime_for_force_budget", "save_paper_format",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
