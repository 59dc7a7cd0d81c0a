"""State and disturbance estimation: the TS-MHE-UIO of the slip, yaw rate,
speed and friction force, the paper's UIO form of it, and the measurement fusion beyond the paper.

What users import is re-exported here, by name (``from tsmpc.estimation import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.estimation.friction_step import FrictionStep
    from tsmpc.estimation.fusion import Fusion
    from tsmpc.estimation.mhe_paper_uio import PaperUIOMHE
    from tsmpc.estimation.mhe_uio import MHEUIO, Estimate, EstimatorStatus

#: public name → the submodule that defines it
_EXPORTS = {
    "Estimate": "mhe_uio",
    "EstimatorStatus": "mhe_uio",
    "FrictionStep": "friction_step",
    "Fusion": "fusion",
    "MHEUIO": "mhe_uio",
    "PaperUIOMHE": "mhe_paper_uio",
}

__all__ = ["MHEUIO", "Estimate", "EstimatorStatus", "FrictionStep", "Fusion", "PaperUIOMHE"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
