"""Read back an output folder of ``tsmpc compare`` / ``tsmpc run``.

The folder holds ``timeseries.npz`` (keys ``<METHOD>_<signal>``, see
:func:`tsmpc.sim.log.save_logs_npz`), ``metrics.json`` and ``config.toml``; :func:`load_run` turns
them back into the :class:`~tsmpc.sim.log.RunLog` objects, the config and the metrics, so figures,
reports and animations can be made again without re-simulating.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from tsmpc.config import Config, load_config
from tsmpc.errors import DataFormatError
from tsmpc.sim.log import RunLog

__all__ = ["RunDir", "load_logs_npz", "load_run"]

_ARRAY_FIELDS = tuple(f.name for f in fields(RunLog) if f.name not in
                      {"method", "scenario", "Tc", "Td", "wall_s", "termination", "events", "meta"})
# Optional arrays (added after the first file format): absent in older files.
_OPTIONAL: frozenset[str] = frozenset()


@dataclass(frozen=True)
class RunDir:
    """An output folder read back: logs by method, the run's config and its metrics."""

    path: Path
    logs: dict[str, RunLog]
    config: Config
    metrics: dict[str, Any]


def load_logs_npz(path: str | Path, metrics: dict[str, Any] | None = None) -> dict[str, RunLog]:
    """Logs by method from a ``timeseries.npz`` written by :func:`~tsmpc.sim.log.save_logs_npz`.

    ``metrics`` (the ``metrics.json`` content) supplies the scenario name, the rates, the wall time,
    the termination and the events; without it the rates are inferred from the time stamps.
    """
    import io
    import zipfile

    from tsmpc.textfile import read_bytes

    path = Path(path)
    raw = read_bytes(path, "time-series file (NPZ)", limit=MAX_NPZ_BYTES)
    try:
        data = np.load(io.BytesIO(raw), allow_pickle=False)
        if not hasattr(data, "files"):
            raise ValueError("a single array, not an archive of time series")
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DataFormatError(f"{path}: not a readable NPZ file ({err}); the run may have "
                              "been cut short") from None
    try:
        return _logs_from(data, path, metrics)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, AttributeError, TypeError,
            IndexError) as err:
        raise DataFormatError(f"{path}: damaged NPZ file ({type(err).__name__}: {err})") from None


#: Largest time-series file read [bytes].
MAX_NPZ_BYTES = 4 * 1024**3


def _logs_from(data: Any, path: Path, metrics: dict[str, Any] | None) -> dict[str, RunLog]:
    with data:
        # Every log has t_outer: the method is what precedes it (method names may hold "_").
        methods = [key[: -len("_t_outer")] for key in data.files if key.endswith("_t_outer")]
        if not methods:
            raise DataFormatError(f"{path}: no time series inside")
        metrics = metrics or {}
        sc = metrics.get("scenario", {})
        logs: dict[str, RunLog] = {}
        for m in methods:
            arrays: dict[str, Any] = {}
            for name in _ARRAY_FIELDS:
                key = f"{m}_{name}"
                if key in data.files:
                    arrays[name] = data[key]
                elif name not in _OPTIONAL:
                    raise DataFormatError(f"{path}: {key} missing")
            t_o, t_i = arrays["t_outer"], arrays["t_inner"]
            Tc = float(sc.get("Tc", t_o[1] - t_o[0] if t_o.size > 1 else 0.1))
            Td = float(sc.get("Td", t_i[1] - t_i[0] if t_i.size > 1 else 0.01))
            mm = metrics.get("methods", {}).get(m, {})
            logs[m] = RunLog(method=m, scenario=str(sc.get("name", path.parent.name)), Tc=Tc, Td=Td,
                             wall_s=float(mm.get("wall_s", 0.0)),
                             termination=str(mm.get("termination", "completed")),
                             events=dict(mm.get("events", {})), meta=dict(sc), **arrays)
    return logs


def load_run(run_dir: str | Path) -> RunDir:
    """Read an output folder of ``tsmpc compare`` / ``tsmpc run``.

    Raises:
        DataFormatError: the folder, its ``timeseries.npz`` or its ``metrics.json`` is missing or
            unreadable (the message names the file).
    """
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import read_text

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DataFormatError(f"{run_dir}: not a folder (expected the --out folder of tsmpc compare/run)")
    marker = run_dir / "PARTIAL"
    if marker.exists():  # an unfinished run: its files are incomplete or from an earlier run
        try:
            status = json.loads(read_text(marker, "PARTIAL marker", limit=1 << 20)).get("status", "?")
        except (TsmpcError, ValueError, AttributeError, RecursionError):
            status = "unreadable"
        raise DataFormatError(f"{run_dir}: holds an unfinished run (PARTIAL says {str(status)[:40]!r}); "
                              "its files are incomplete: run it again")
    mpath = run_dir / "metrics.json"
    try:
        metrics = json.loads(read_text(mpath, "run's metrics (JSON)", limit=256 << 20))
    except (TsmpcError, ValueError, RecursionError) as err:
        raise DataFormatError(f"{mpath}: cannot read the run's metrics ({err})") from None
    if not isinstance(metrics, dict):
        raise DataFormatError(f"{mpath}: expected a JSON object")
    cpath = run_dir / "config.toml"
    cfg = load_config(cpath) if cpath.is_file() else Config()
    logs = load_logs_npz(run_dir / "timeseries.npz", metrics)
    return RunDir(run_dir, logs, cfg, metrics)
