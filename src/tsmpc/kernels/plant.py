"""Plant block: the T_d/h RK4 steps of :class:`tsmpc.vehicle.plant.Plant` between two inner steps in
one compiled call (linear and Pacejka tyres). The arithmetic is the plant's own
(:func:`tsmpc.vehicle.single_track.rk4_steps` over :func:`~tsmpc.vehicle.single_track.plant_rhs`, one
definition),
compiled in; this module adds the finiteness test and carries the record
(:class:`~tsmpc.vehicle.single_track.PlantParams`) as a float vector, the form the engine's and the
batch's arrays hold."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tsmpc.vehicle.single_track import PlantParams, rk4_steps

__all__ = ["pack", "rk4_block", "unpack", "warm"]

#: The record's fields in the constants vector (:func:`pack`), by name: the batch's vector
#: right-hand side (tsmpc.kernels.batch) reads its lanes' constants with these.
(_M, _I, _A, _B, _CF, _KD, _VF, _VE, _MG, _FZF, _FZR, _CC, _EE, _MUT0, _SCALE, _LIN, _CR, _COMB) = (
    PlantParams._fields.index(f) for f in (
        "mass", "inertia", "a", "b", "C_f", "drag", "v_floor", "v_eps", "mg", "fz_f", "fz_r", "shape_c",
        "curvature_e", "mu_tyre", "grip_scale", "linear", "C_r", "combined"))
N_CST = len(PlantParams._fields)


def _forget_stale_entries() -> None:
    """numba keys this module's cache entries by this file only, but their arithmetic is
    vehicle/single_track.py's, compiled in: entries compiled from another version of it are deleted (a
    stamp of its hash beside them), so the first call compiles afresh (the engine's cache does the
    same for all its blocks, ``tsmpc.sim.engine._forget_stale_machine_code``)."""
    import hashlib
    from pathlib import Path

    from tsmpc import kernels
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import read_bytes, read_text

    source = Path(__file__).resolve().parents[1] / "vehicle" / "single_track.py"
    try:
        digest = hashlib.sha256(read_bytes(source, "kernel source")).hexdigest()
        folder = kernels._tree_folder(kernels.numba_cache_dir())
        stamp = folder / "plant.blocks-sha256"
        try:
            if read_text(stamp, "plant cache stamp", limit=1024).strip() == digest:
                return
        except TsmpcError:  # no stamp yet, or not a readable one: compile afresh
            pass
        folder.mkdir(parents=True, exist_ok=True)
        for entry in folder.glob("plant.*.nb[ic]"):
            entry.unlink()
        stamp.write_text(digest)
    except (OSError, TsmpcError):  # an unwritable cache: numba refuses it too (kernels.cache_problem)
        pass


_forget_stale_entries()  # before the first call below loads an entry


def pack(plant) -> np.ndarray:
    """The constants of a :class:`~tsmpc.vehicle.plant.Plant` as the kernel's vector (its record's
    fields in order, the flags as 1.0 / 0.0)."""
    return np.array([float(v) for v in plant.params], dtype=np.float64)


@njit(cache=True, fastmath=False)
def unpack(cst):
    """The :class:`~tsmpc.vehicle.single_track.PlantParams` of a constants vector."""
    return PlantParams(cst[_M], cst[_I], cst[_A], cst[_B], cst[_CF], cst[_KD], cst[_VF], cst[_VE], cst[_MG],
                       cst[_FZF], cst[_FZR], cst[_CC], cst[_EE], cst[_MUT0], cst[_SCALE], cst[_LIN] != 0.0,
                       cst[_CR], cst[_COMB] != 0.0)


@njit(cache=True, fastmath=False)
def rk4_block(x, F, d, mu, n, h, cst):
    """``n`` RK4 steps of length h from x (6,) with u = (F, δ) and μ held; returns (x⁺ (6,), ok) —
    ok False if the input, the state or the result is not finite."""
    out = np.empty(6)
    X, Y, th, v, al, om = x[0], x[1], x[2], x[3], x[4], x[5]
    if not (math.isfinite(X) and math.isfinite(Y) and math.isfinite(th) and math.isfinite(v)
            and math.isfinite(al) and math.isfinite(om) and math.isfinite(F) and math.isfinite(d)
            and math.isfinite(mu)):
        out[:] = x
        return out, False
    X, Y, th, v, al, om = rk4_steps(unpack(cst), X, Y, th, v, al, om, F, d, mu, n, h)
    out[0], out[1], out[2], out[3], out[4], out[5] = X, Y, th, v, al, om
    ok = (math.isfinite(X) and math.isfinite(Y) and math.isfinite(th) and math.isfinite(v)
          and math.isfinite(al) and math.isfinite(om))
    return out, ok


def warm() -> None:
    """Compile (or load from the cache) the signature the plant uses."""
    cst = np.array([683.0, 560.0, 0.7, 1.0, 25000.0, 0.4, 0.5, 0.05, 6700.0, 3800.0, 2900.0, 1.3, -1.0,
                    0.9, 0.0, 0.0, 25000.0, 0.0])
    rk4_block(np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]), 100.0, 0.01, 0.9, 2, 0.001, cst)
