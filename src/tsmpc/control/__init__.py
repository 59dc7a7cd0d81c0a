"""Controllers: the guidance cascade of paper Fig. 1 as one object with
``step()`` (:class:`Cascade`), its outer TS-MPC and inner TS-LQR, the NL-MPC of the paper's
comparison, the speed governor and the outer-loop baselines (pure pursuit, Stanley, kinematic LQR,
LTV-MPC).

What users import is re-exported here, by name (``from tsmpc.control import …``); the submodules
load on first use. The modules not re-exported are implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tsmpc._exports import lazy_exports

if TYPE_CHECKING:
    from tsmpc.control.baselines import BASELINES, build_baseline
    from tsmpc.control.cascade import EVENT_NAMES, Cascade, Command, Measurement
    from tsmpc.control.governor import Governor, GovernorParams
    from tsmpc.control.kinematic_lqr import KinematicLQR
    from tsmpc.control.ltv_mpc import LTVMPC
    from tsmpc.control.nl_mpc import NLMPC
    from tsmpc.control.paper_as_run import AsRunLQR
    from tsmpc.control.pure_pursuit import PurePursuit
    from tsmpc.control.stanley import Stanley
    from tsmpc.control.ts_lqr import TSLQR, InnerCommand
    from tsmpc.control.ts_mpc import TSMPC, MPCResult, MPCStatus

#: public name → the submodule that defines it
_EXPORTS = {
    "AsRunLQR": "paper_as_run",
    "BASELINES": "baselines",
    "Cascade": "cascade",
    "Command": "cascade",
    "EVENT_NAMES": "cascade",
    "Governor": "governor",
    "GovernorParams": "governor",
    "InnerCommand": "ts_lqr",
    "KinematicLQR": "kinematic_lqr",
    "LTVMPC": "ltv_mpc",
    "MPCResult": "ts_mpc",
    "MPCStatus": "ts_mpc",
    "Measurement": "cascade",
    "NLMPC": "nl_mpc",
    "PurePursuit": "pure_pursuit",
    "Stanley": "stanley",
    "TSLQR": "ts_lqr",
    "TSMPC": "ts_mpc",
    "build_baseline": "baselines",
}

__all__ = [
    "BASELINES", "EVENT_NAMES", "LTVMPC", "NLMPC", "TSLQR", "TSMPC", "AsRunLQR", "Cascade", "Command",
    "Governor", "GovernorParams", "InnerCommand", "KinematicLQR", "MPCResult", "MPCStatus", "Measurement",
    "PurePursuit", "Stanley", "build_baseline",
]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
