"""Run log: every signal of a closed-loop run as named arrays (the paper's Table 5 metrics).

The simulator fills a :class:`RunLog`; metrics, figures and writers read it. Outer-loop signals are
sampled every T_c (length K), inner-loop signals every T_d (length K · T_c/T_d). Units are SI.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

# The atomic writers live in tsmpc.io (below synthesis, planning and sim); re-exported here.
from tsmpc.io import atomic_write_bytes, atomic_write_text

__all__ = ["RunLog", "atomic_write_bytes", "atomic_write_text", "save_logs_mat", "save_logs_npz"]


@dataclass(frozen=True)
class RunLog:
    """Signals of one run. Outer arrays have K rows, inner arrays K·(T_c/T_d) rows."""

    method: str
    scenario: str
    Tc: float
    Td: float
    # outer loop, every T_c
    t_outer: NDArray[np.float64]  #: (K,) time [s]
    ref: NDArray[np.float64]  #: (K, 5) x_d, y_d, θ_d, v_d, ω_d
    state_outer: NDArray[np.float64]  #: (K, 6) true plant state X, Y, θ, v, α, ω
    errors: NDArray[np.float64]  #: (K, 3) true e_x, e_y, e_θ
    errors_measured: NDArray[np.float64]  #: (K, 3) errors the MPC saw (noisy pose)
    u_c: NDArray[np.float64]  #: (K, 2) MPC output v_ref, ω_ref
    x_pred: NDArray[np.float64]  #: (K, N+1, 3) MPC predicted errors
    mpc_time_s: NDArray[np.float64]  #: (K,) wall time of each MPC step
    mpc_status: NDArray[np.str_]  #: (K,) MPC status strings
    mpc_iterations: NDArray[np.int64]  #: (K,) QPs (or NLP solves) per step
    mpc_qp_iterations: NDArray[np.int64]  #: (K,) inner solver iterations
    mpc_clipped: NDArray[np.int64]  #: (K,) scheduling values clipped into the box
    # inner loop, every T_d
    t_inner: NDArray[np.float64]  #: (M,)
    state: NDArray[np.float64]  #: (M, 6) true plant state at the start of each inner step
    estimate: NDArray[np.float64]  #: (M, 3) v̂, α̂, ω̂
    measurement: NDArray[np.float64]  #: (M, 2) measured v, ω
    #: (M,) the MHE's friction estimate (its window fit) [N]; the force compensated differs from it
    #: by the mass estimate's inertia terms (fusion.mass_estimate) and, after a declared step of
    #: the friction, by the one-step estimate (lqr.friction_step)
    F_fr_hat: NDArray[np.float64]
    F_fr_raw: NDArray[np.float64]  #: (M,) raw UIO formula [N]
    F_fr_true: NDArray[np.float64]  #: (M,) true (μ(road) − μ_o) M g [N]
    mu_road: NDArray[np.float64]  #: (M,)
    command: NDArray[np.float64]  #: (M, 2) plant input F_xR [N], δ [rad]
    saturated: NDArray[np.bool_]  #: (M,) an inner saturation was active
    mhe_time_s: NDArray[np.float64]  #: (M,)
    lqr_time_s: NDArray[np.float64]  #: (M,)
    mhe_status: NDArray[np.str_]  #: (M,)
    # run facts
    wall_s: float = 0.0
    termination: str = "completed"  #: "completed" or the reason the run stopped early
    events: dict[str, int] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_outer(self) -> int:
        """K, number of MPC steps logged."""
        return int(self.t_outer.size)

    @property
    def simulated_s(self) -> float:
        """Simulated time [s]."""
        return self.n_outer * self.Tc

    def arrays(self) -> dict[str, NDArray[Any]]:
        """Every array field by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)}

    def _flat(self) -> dict[str, Any]:
        out: dict[str, Any] = {f"{self.method}_{k}": v for k, v in self.arrays().items()}
        return out

    def to_npz_bytes(self) -> bytes:
        """Compressed NPZ of every array."""
        buf = io.BytesIO()
        arrays: dict[str, Any] = self.arrays()  # (mypy matches **dict[str, NDArray] to allow_pickle)
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()

    def save_npz(self, path: str | Path) -> None:
        """Write every array to a compressed NPZ file (atomically)."""
        atomic_write_bytes(path, self.to_npz_bytes())


def save_logs_npz(logs: dict[str, RunLog], path: str | Path) -> None:
    """Arrays of several runs in one NPZ, keys ``<METHOD>_<signal>``."""
    buf = io.BytesIO()
    data: dict[str, Any] = {}
    for log in logs.values():
        data.update(log._flat())
    np.savez_compressed(buf, **data)
    atomic_write_bytes(path, buf.getvalue())


def save_logs_mat(logs: dict[str, RunLog], path: str | Path) -> None:
    """Arrays of several runs in one MATLAB .mat file, one struct per method."""
    import scipy.io

    buf = io.BytesIO()
    mdict = {log.method: {k: (v.astype(object) if v.dtype.kind == "U" else v)
                          for k, v in log.arrays().items()} for log in logs.values()}
    scipy.io.savemat(buf, mdict, do_compression=True, long_field_names=True)
    atomic_write_bytes(path, buf.getvalue())
