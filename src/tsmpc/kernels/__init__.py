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
* The cache heals or is named (issue 24): the cache folder must be a writable folder *before*
  numba is imported (numba silently falls back to the package's ``__pycache__`` otherwise), so an
  unusable ``NUMBA_CACHE_DIR`` is refused with one line naming it (:func:`cache_problem`; the CLI
  exits 2, a library caller gets numpy and the line); a cache entry numba cannot load (corrupt,
  truncated, unreadable) is deleted and the kernels compiled again, once; if that fails too, one
  line names the folder.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["cache_problem", "compile_lock", "enabled", "failure", "forget_stale", "in_cache", "load",
           "numba_cache_dir", "warmup"]

_MODULES = ("mpc", "mhe", "plant", "lqr", "blocks")
_LOADED: dict[str, ModuleType] | None = None
_FAILED = False
_FAILURE: str | None = None


def enabled() -> bool:
    """False when ``TSMPC_NO_JIT`` is set to a true value (1, true, yes, on)."""
    return os.environ.get("TSMPC_NO_JIT", "").strip().lower() not in ("1", "true", "yes", "on")


def numba_cache_dir() -> Path:
    """Where numba stores the compiled kernels: ``$NUMBA_CACHE_DIR`` if the user set it, else the
    ``numba`` folder next to the design cache."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    from tsmpc.paths import cache_root

    return cache_root() / "numba"


def cache_problem() -> str | None:
    """None when the kernel cache folder is usable (or the kernels are off); else one line naming
    ``NUMBA_CACHE_DIR`` (or the default folder) and why it is not."""
    if not enabled():
        return None
    from tsmpc.paths import folder_problem

    cache = numba_cache_dir()
    problem = folder_problem(cache)
    if problem is None:
        return None
    who = "NUMBA_CACHE_DIR" if os.environ.get("NUMBA_CACHE_DIR") else "the kernel cache"
    return (f"{who} {cache}: {problem}; fix or unset it (TSMPC_NO_JIT=1 runs without compiled "
            "kernels)")


def failure() -> str | None:
    """Why the compiled kernels are unavailable (None when they are, or not tried yet)."""
    return _FAILURE


def _tree_folder(cache: Path) -> Path:
    """numba's user-provided cache keeps each source folder in ``<name>_<sha1 of its path>``."""
    here = os.path.dirname(os.path.abspath(__file__))
    return cache / f"{os.path.basename(here)}_{hashlib.sha1(here.encode()).hexdigest()}"


@contextlib.contextmanager
def compile_lock(name: str) -> Iterator[None]:
    """Hold the cache's lock ``name`` (an exclusive ``flock`` on ``<cache folder>/<name>.lock``)
    while this process compiles or loads a kernel. A second process that needs the same machine
    code meanwhile — a sweep's worker, a test beside the one compiling — waits and then loads it
    from the cache instead of compiling it again (numba would: minutes of CPU each for the batch
    kernel). The lock is the kernel's; a process that dies releases it. Without ``fcntl``
    (Windows) or a writable cache folder there is no lock: each process compiles for itself."""
    from tsmpc.io import file_lock

    try:
        folder = _tree_folder(numba_cache_dir())
    except OSError:
        yield
        return
    with file_lock(folder / f"{name}.lock"):
        yield


def in_cache(function: str) -> bool:
    """Whether numba's cache holds machine code of ``function`` (``"<module>.<name>"`` of this
    package's kernels, e.g. ``"engine.run"``): its first call then loads rather than compiles."""
    try:
        return any(_tree_folder(numba_cache_dir()).glob(f"{function}-*.nbi"))
    except OSError:
        return False


def _cold(cache: Path) -> bool:
    """True if some kernel module of this source tree has no entry in the cache yet."""
    folder = _tree_folder(cache)
    try:
        names = {p.name.split(".")[0] for p in folder.glob("*.nbi")}
    except OSError:
        return True
    return not set(_MODULES) <= names


def load(name: str) -> Any:
    """The kernel module ``name`` (mpc, mhe, plant, lqr, blocks), compiled or loaded from the cache; None
    when the kernels are off or numba is unavailable (the caller then uses numpy)."""
    global _LOADED, _FAILED, _FAILURE
    if not enabled() or _FAILED:
        return None
    if _LOADED is None:
        try:
            _LOADED = _import_all()
        except Exception as err:  # a broken numba must never stop a simulation
            _FAILED = True
            _FAILURE = " ".join(f"{type(err).__name__}: {err}".split())[:500]
            print(f"tsmpc: compiled kernels unavailable ({_FAILURE}); using numpy", file=sys.stderr)
            return None
    return _LOADED[name]


class KernelCacheError(RuntimeError):
    """The kernel cache folder is unusable, or its entries cannot be loaded nor rebuilt."""


def _purge(folder: Path, modules: tuple[str, ...] = _MODULES) -> int:
    """Delete this tree's cache entries of the kernel ``modules``; returns how many."""
    n = 0
    for p in folder.glob("*.nb[ic]"):
        if p.name.split(".")[0] in modules:
            p.unlink()
            n += 1
    return n


def _compile_all(modules: tuple[str, ...] = _MODULES) -> dict[str, ModuleType]:
    import importlib

    mods = {m: importlib.import_module(f"tsmpc.kernels.{m}") for m in modules}
    for m in mods.values():
        m.warm()  # compile (or load) every signature now, not inside the first timed step
    return mods


def _import_all() -> dict[str, ModuleType]:
    cache = numba_cache_dir()
    problem = cache_problem()
    if problem is not None:  # numba would silently cache in the package's __pycache__ instead
        raise KernelCacheError(problem)
    if "NUMBA_CACHE_DIR" not in os.environ:
        # Must be set before numba is imported: numba reads it once.
        os.environ["NUMBA_CACHE_DIR"] = str(cache)
    with compile_lock("kernels"):  # another process compiling them: wait, then load
        return _import_locked(cache)


def _import_locked(cache: Path) -> dict[str, ModuleType]:
    cold = _cold(cache)
    if cold:
        print("tsmpc: compiling kernels (first run only)…", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    mods: dict[str, ModuleType] = {}
    for m in _MODULES:  # one module at a time: a broken entry costs its module's compile only
        try:
            mods.update(_compile_all((m,)))
        except Exception as err:  # a corrupt, truncated or unreadable cache entry: rebuild it once
            mods.update(_rebuild(_tree_folder(cache), m, err))
            cold = True
    if cold:
        print(f"tsmpc: kernels compiled in {time.perf_counter() - t0:.1f} s (cached in {cache})",
              file=sys.stderr, flush=True)
    return mods


def _rebuild(folder: Path, module: str, err: Exception) -> dict[str, ModuleType]:
    """Delete the cache entries of the kernel ``module`` whose loading raised ``err`` and compile
    it again, once; a :class:`KernelCacheError` naming the folder when that fails too."""
    try:
        removed = _purge(folder, (module,))
    except OSError as rm_err:
        raise KernelCacheError(f"the kernel cache {folder} cannot be loaded ({type(err).__name__}: "
                               f"{err}) nor cleaned ({rm_err.strerror or rm_err})") from None
    if not removed:
        raise err
    print(f"tsmpc: the kernel cache in {folder} could not be loaded ({type(err).__name__}); "
          f"compiling the {module} kernels again…", file=sys.stderr, flush=True)
    sys.modules.pop(f"tsmpc.kernels.{module}", None)
    try:
        return _compile_all((module,))
    except Exception as err2:
        raise KernelCacheError(f"the kernel cache {folder} is unusable even after a rebuild "
                               f"({type(err2).__name__}: {err2})") from None


def warmup() -> tuple[bool, float]:
    """Compile (or load) every kernel now; returns (kernels on, seconds spent)."""
    t0 = time.perf_counter()
    ok = load("mpc") is not None
    return ok, time.perf_counter() - t0


def forget_stale(folder: Path, prefix: str, sources: tuple[str, ...], stamp_name: str,
                 blocks: tuple[str, ...]) -> None:
    """numba keys a cached function by its own file only: a kernel's machine code that contains
    code of other modules (the run engine: kernels/mpc.py, mhe.py, lqr.py, plant.py; the inner
    block's call: kernels/blocks.py, lqr.py; both: the ``@jitable`` blocks of
    :data:`tsmpc.kernels.jit.BLOCK_MODULES`) would outlive an edit of one of them. So the cache
    entries ``<prefix>.*`` carry the hash of those ``sources`` (kernel modules by name) and
    ``blocks`` (modules by dotted name) in a file beside them, ``stamp_name``, and are deleted when
    it differs: the next call compiles afresh."""
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import read_bytes, read_text

    here = Path(__file__).parent
    top = here.parent.parent  # the folder holding the tsmpc package
    files = [here / f"{m}.py" for m in sources] + [top / (m.replace(".", "/") + ".py")
                                                   for m in blocks]
    digest = hashlib.sha256(b"".join(read_bytes(f, "kernel source") for f in files)).hexdigest()
    stamp = folder / stamp_name
    try:
        if read_text(stamp, f"{prefix} cache stamp", limit=1024).strip() == digest:
            return
    except (TsmpcError, OSError):
        pass
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for p in folder.glob(f"{prefix}.*.nb[ic]"):
            p.unlink()
        stamp.write_text(digest)
    except OSError:  # an unwritable cache: numba refuses it too (cache_problem)
        pass
