"""Compiled kernels (numba) for the real-time core: MPC Riccati fast path, MHE-UIO banded solve,
plant RK4 block, TS-LQR step.

The kernels are *accelerators*: every one has a numpy implementation next to the code that calls
it, which stays the tests' oracle and is used whenever the kernels are off.

* ``TSMPC_NO_JIT=1`` switches every kernel off (debugging, or a platform without numba).
* numba compiles with ``cache=True`` into ``$NUMBA_CACHE_DIR`` — by default
  ``<design cache>/numba`` (``$TSMPC_CACHE_DIR/numba`` or ``~/.cache/tsmpc/numba``), set *before*
  numba is imported. The first run compiles (tens of seconds; a status line says so on stderr);
  later processes load the machine code from the cache. ``tsmpc warmup`` compiles ahead of time.
* Nothing here imports numba at ``import tsmpc``: :func:`load` is called by the online blocks when
  they are constructed, i.e. only by code that simulates.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["enabled", "load", "numba_cache_dir", "warmup"]

_MODULES = ("mpc", "mhe", "plant", "lqr")
_LOADED: dict[str, ModuleType] | None = None
_FAILED = False


def enabled() -> bool:
    """False when ``TSMPC_NO_JIT`` is set to a true value (1, true, yes, on)."""
    return os.environ.get("TSMPC_NO_JIT", "").strip().lower() not in ("1", "true", "yes", "on")


def numba_cache_dir() -> Path:
    """Where numba stores the compiled kernels: ``$NUMBA_CACHE_DIR`` if the user set it, else the
    ``numba`` folder next to the design cache."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("TSMPC_CACHE_DIR")
    return (Path(base) if base else Path.home() / ".cache" / "tsmpc") / "numba"


def _cold(cache: Path) -> bool:
    """True if some kernel module of this source tree has no entry in the cache yet.

    numba's user-provided cache keeps each source folder in ``<name>_<sha1 of its path>``."""
    here = os.path.dirname(os.path.abspath(__file__))
    folder = cache / f"{os.path.basename(here)}_{hashlib.sha1(here.encode()).hexdigest()}"
    try:
        names = {p.name.split(".")[0] for p in folder.glob("*.nbi")}
    except OSError:
        return True
    return not set(_MODULES) <= names


def load(name: str) -> Any:
    """The kernel module ``name`` (mpc, mhe, plant, lqr), compiled or loaded from the cache; None
    when the kernels are off or numba is unavailable (the caller then uses numpy)."""
    global _LOADED, _FAILED
    if not enabled() or _FAILED:
        return None
    if _LOADED is None:
        try:
            _LOADED = _import_all()
        except Exception as err:  # a broken numba must never stop a simulation
            _FAILED = True
            print(f"tsmpc: compiled kernels unavailable ({type(err).__name__}: {err}); using numpy",
                  file=sys.stderr)
            return None
    return _LOADED[name]


def _import_all() -> dict[str, ModuleType]:
    import importlib

    cache = numba_cache_dir()
    if "NUMBA_CACHE_DIR" not in os.environ:
        # Must be set before numba is imported: numba reads it once.
        cache.mkdir(parents=True, exist_ok=True)
        os.environ["NUMBA_CACHE_DIR"] = str(cache)
    cold = _cold(cache)
    if cold:
        print("tsmpc: compiling kernels (first run only)…", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    mods = {m: importlib.import_module(f"tsmpc.kernels.{m}") for m in _MODULES}
    for m in mods.values():
        m.warm()  # compile (or load) every signature now, not inside the first timed step
    if cold:
        print(f"tsmpc: kernels compiled in {time.perf_counter() - t0:.1f} s (cached in {cache})",
              file=sys.stderr, flush=True)
    return mods


def warmup() -> tuple[bool, float]:
    """Compile (or load) every kernel now; returns (kernels on, seconds spent)."""
    t0 = time.perf_counter()
    ok = load("mpc") is not None
    return ok, time.perf_counter() - t0
