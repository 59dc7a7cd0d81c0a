"""Control-oriented vehicle models (the paper's kinematic error model and dynamic model): the
kinematic error model and its exact TS form, the dynamic model, its TS form, ZOH discretisation
and the Apkarian augmentation, and the scheduling boxes of the TS polytopes.

What users import is re-exported here, by name (``from tsmpc.models import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.models.dynamic import (
        Discretization,
        DynamicTS,
        augment_apkarian,
        continuous_matrices,
        discretize,
        equilibrium,
        steady_states,
    )
    from tsmpc.models.kinematic import (
        KinematicTS,
        nonlinear_step,
        pose_to_errors,
        reference_input,
        wrap_angle,
    )
    from tsmpc.models.polytope import SchedulingBox

#: public name → the submodule that defines it
_EXPORTS = {
    "Discretization": "dynamic",
    "DynamicTS": "dynamic",
    "KinematicTS": "kinematic",
    "SchedulingBox": "polytope",
    "augment_apkarian": "dynamic",
    "continuous_matrices": "dynamic",
    "discretize": "dynamic",
    "equilibrium": "dynamic",
    "nonlinear_step": "kinematic",
    "pose_to_errors": "kinematic",
    "reference_input": "kinematic",
    "steady_states": "dynamic",
    "wrap_angle": "kinematic",
}

__all__ = [
    "Discretization", "DynamicTS", "KinematicTS", "SchedulingBox", "augment_apkarian",
    "continuous_matrices", "discretize", "equilibrium", "nonlinear_step", "pose_to_errors",
    "reference_input", "steady_states", "wrap_angle",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
