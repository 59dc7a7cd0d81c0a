"""LMI designs (the paper's LMI designs): the kinematic TS-MPC's terminal ingredients and the
dynamic TS-LQR's gains, each returned with certificates recomputed outside the solver, and the
design cache that solves a design once per parameter set.

What users import is re-exported here, by name (``from tsmpc.synthesis import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.synthesis.cache import (
        load_or_design_dynamic,
        load_or_design_feasibility,
        load_or_design_kinematic,
    )
    from tsmpc.synthesis.certificates import Certificate
    from tsmpc.synthesis.dynamic import DynamicDesign, certify_dynamic, design_dynamic
    from tsmpc.synthesis.kinematic import KinematicDesign, certify_kinematic, design_kinematic
    from tsmpc.synthesis.paper_as_run import FeasibilityDesign, design_feasibility

#: public name → the submodule that defines it
_EXPORTS = {
    "Certificate": "certificates",
    "DynamicDesign": "dynamic",
    "FeasibilityDesign": "paper_as_run",
    "KinematicDesign": "kinematic",
    "certify_dynamic": "dynamic",
    "certify_kinematic": "kinematic",
    "design_dynamic": "dynamic",
    "design_feasibility": "paper_as_run",
    "design_kinematic": "kinematic",
    "load_or_design_dynamic": "cache",
    "load_or_design_feasibility": "cache",
    "load_or_design_kinematic": "cache",
}

__all__ = [
    "Certificate", "DynamicDesign", "FeasibilityDesign", "KinematicDesign", "certify_dynamic",
    "certify_kinematic", "design_dynamic", "design_feasibility", "design_kinematic",
    "load_or_design_dynamic", "load_or_design_feasibility", "load_or_design_kinematic",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
