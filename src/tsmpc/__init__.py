"""tsmpc — Takagi-Sugeno MPC for autonomous-vehicle trajectory tracking.

Implements the guidance system of Alcalá, Puig & Quevedo, "TS-MPC for autonomous vehicles
including a dynamic TS-MHE-UIO": kinematic TS-MPC (outer loop), gain-scheduled TS-LQR designed
with LMIs (inner loop), TS-MHE with an unknown-input observer for slip and friction force, a
nonlinear MPC baseline, a planner and a nonlinear vehicle simulator.

Sub-packages mirror the paper's blocks: :mod:`tsmpc.models`, :mod:`tsmpc.vehicle`, :mod:`tsmpc.synthesis`,
:mod:`tsmpc.control`, :mod:`tsmpc.estimation`, :mod:`tsmpc.planning`, :mod:`tsmpc.sim`,
:mod:`tsmpc.report`. Importing ``tsmpc`` is cheap: heavy solvers load on first use.
"""

from importlib.metadata import PackageNotFoundError, version

from tsmpc.config import Config, load_config
from tsmpc.errors import (
    CertificateError,
    ConfigError,
    DataFormatError,
    NonFiniteError,
    SolverError,
    TsmpcError,
)

try:
    __version__ = version("tsmpc")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = [
    "CertificateError",
    "Config",
    "ConfigError",
    "DataFormatError",
    "NonFiniteError",
    "SolverError",
    "TsmpcError",
    "__version__",
    "load_config",
]
