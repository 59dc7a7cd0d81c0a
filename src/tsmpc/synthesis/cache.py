"""On-disk cache of the LMI designs (the paper's LMI designs): a run never re-solves an unchanged design.

A design is stored as one JSON file named by the SHA-256 of every input it depends on (the
settings, the box, the vehicle, the sample time, the formulation version). Floats are written with
``repr`` precision, so a cached design is bit-identical to a fresh one. The certificates are
recomputed on load (cheap, numpy only) — a corrupted or tampered file is re-solved, never trusted.

Location: ``$TSMPC_CACHE_DIR`` or ``~/.cache/tsmpc``. Writes are atomic (temp file + rename).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from contextlib import AbstractContextManager
from dataclasses import asdict, fields
from dataclasses import replace as dc_replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tsmpc.config import Config, DynamicLMIFormulation
from tsmpc.errors import TsmpcError
from tsmpc.io import atomic_write_text, file_lock
from tsmpc.synthesis.certificates import Certificate, check
from tsmpc.synthesis.dynamic import DynamicDesign, certify_dynamic, design_dynamic
from tsmpc.synthesis.kinematic import KinematicDesign, certify_kinematic, design_kinematic
from tsmpc.synthesis.paper_as_run import (
    FeasibilityDesign,
    certify_vertices,
    design_feasibility,
    vertex_models,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "cache_dir",
    "design_from_dict",
    "design_to_dict",
    "dynamic_key",
    "kinematic_key",
    "load_or_design_dynamic",
    "load_or_design_feasibility",
    "load_or_design_kinematic",
]

#: Bump when a formulation changes, so old cache entries are not reused.
FORMAT_VERSION = 4


def cache_dir() -> Path:
    """``$TSMPC_CACHE_DIR`` or ``~/.cache/tsmpc`` (an empty HOME: an explicit private fallback,
    :func:`tsmpc.paths.cache_root`)."""
    from tsmpc.paths import cache_root

    return cache_root()


def _hash(kind: str, payload: dict[str, Any]) -> str:
    text = json.dumps({"kind": kind, "format": FORMAT_VERSION, **payload}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def kinematic_key(cfg: Config) -> str:
    """Hash of every input of the kinematic design."""
    return _hash("kinematic", {"box": cfg.kinematic_box.model_dump(mode="json"),
                               "lmi": cfg.kinematic_lmi.model_dump(mode="json"), "Tc": cfg.rates.Tc})


def dynamic_key(cfg: Config) -> str:
    """Hash of every input of the dynamic design."""
    lmi = cfg.dynamic_lmi.model_dump(mode="json")
    if lmi.get("formulation") == "guaranteed-cost":  # ours: the keys of existing designs do not change
        del lmi["formulation"]
    if lmi.get("feasible_point") == "solver":  # the default: earlier keys do not change
        del lmi["feasible_point"]
    return _hash("dynamic", {"box": cfg.dynamic_box.model_dump(mode="json"),
                             "lmi": lmi,
                             # unset optional fields (per-axle stiffness) are left out, so the
                             # keys of existing designs do not change
                             "vehicle": cfg.vehicle.model_dump(mode="json", exclude_none=True),
                             "Td": cfg.rates.Td})


def design_to_dict(design: Any) -> dict[str, Any]:
    """JSON-ready dict: arrays as nested lists, certificates as {name, margin, holds}."""
    out: dict[str, Any] = {"type": type(design).__name__}
    for f in fields(design):
        value = getattr(design, f.name)
        if isinstance(value, np.ndarray):
            out[f.name] = value.tolist()
        elif f.name == "certificates":
            out[f.name] = [{**asdict(c), "holds": c.holds} for c in value]
        else:
            out[f.name] = value
    return out


def design_from_dict(data: dict[str, Any], cls: type[DataclassInstance] | None = None) -> Any:
    """Inverse of :func:`design_to_dict` (``cls``: the design class the record must be; None:
    a kinematic or dynamic design, as the record says). Raises ValueError for another type."""
    if cls is None:
        designs: dict[str, type[DataclassInstance]] = {"KinematicDesign": KinematicDesign,
                                                       "DynamicDesign": DynamicDesign}
        cls = designs[data["type"]]
    elif data.get("type") != cls.__name__:
        raise ValueError(f"not a {cls.__name__} record")
    kwargs: dict[str, Any] = {}
    for f in fields(cls):
        value = data[f.name]
        if f.name == "certificates":
            value = tuple(Certificate(c["name"], float(c["margin"]), float(c["relative"]))
                          for c in value)
        elif isinstance(value, list):
            value = np.asarray(value, dtype=float)
        kwargs[f.name] = value
    return cls(**kwargs)


def _recheck(design: KinematicDesign | DynamicDesign, cfg: Config) -> tuple[Certificate, ...]:
    """Recompute the certificates of a loaded design on this machine (raises on failure)."""
    if isinstance(design, KinematicDesign):
        from tsmpc.models.kinematic import KinematicTS

        ts = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
        certs = certify_kinematic(ts.A_vertices, ts.B, np.diag(cfg.kinematic_lmi.Q),
                                  np.diag(cfg.kinematic_lmi.R), design.Y, design.K, design.Z,
                                  np.diag(np.square(cfg.kinematic_lmi.u_bar)), P=design.P, S=design.S)
    else:
        _, _, certs = certify_dynamic(design.K, design.P, cfg.dynamic_box, cfg.vehicle,
                                      cfg.dynamic_lmi, design.Td)
    check(certs, "cached design")
    return tuple(certs)


#: Certificates recomputed in this process, by the exact text of the cache entry they were
#: recomputed from (its SHA-256; the entry's key hashes every input of the design). Rechecking
#: once per process is what a recheck guards against (another machine's or version's numbers;
#: a tampered file changes the text), and a sweep or ablation loads the same entries hundreds
#: of times: the dynamic grid costs ≈ 0.2 s each time.
_RECHECKED: dict[str, tuple[Certificate, ...]] = {}


def _rechecked(design: KinematicDesign | DynamicDesign, cfg: Config, text: str) -> tuple[Certificate, ...]:
    """:func:`_recheck`, once per process for each entry text."""
    digest = hashlib.sha256(text.encode()).hexdigest()
    if digest not in _RECHECKED:
        _RECHECKED[digest] = _recheck(design, cfg)  # (raises: nothing is remembered)
    return _RECHECKED[digest]


def _entry_lock(path: Path, use_cache: bool) -> AbstractContextManager[bool]:
    """The lock of the cache entry ``path`` (``<entry>.lock`` beside it): two processes that need
    the same design at once (a sweep's workers, the run engine's warm-up beside a test) solve it
    once — the second waits, then loads the first one's entry. No lock without a cache."""
    return file_lock(path.with_suffix(".lock")) if use_cache else contextlib.nullcontext(False)


def _load_or_design(cfg: Config, kind: str, directory: Path | None, use_cache: bool) -> Any:
    key = kinematic_key(cfg) if kind == "kinematic" else dynamic_key(cfg)
    path = (directory or cache_dir()) / f"{kind}-{key[:32]}.json"
    with _entry_lock(path, use_cache):
        return _load_or_solve(cfg, kind, key, path, use_cache)


def _load_or_solve(cfg: Config, kind: str, key: str, path: Path, use_cache: bool) -> Any:
    if use_cache and path.exists():
        try:  # a regular file of bounded size only (a folder, a FIFO: re-solved, never blocks)
            from tsmpc.textfile import read_text

            text = read_text(path, "design cache entry", limit=64 * 1024 * 1024)
            design = design_from_dict(json.loads(text))
            if design.inputs_hash == key:
                # the certificates reported are the ones recomputed here, not the stored ones
                return dc_replace(design, certificates=_rechecked(design, cfg, text))
        except (TsmpcError, KeyError, ValueError, TypeError, AttributeError, RecursionError,
                OSError):
            pass  # unreadable or stale entry: re-solve and overwrite it
    if kind == "kinematic":
        design = design_kinematic(cfg.kinematic_box, cfg.kinematic_lmi, cfg.rates.Tc, inputs_hash=key)
    else:
        design = design_dynamic(cfg.dynamic_box, cfg.vehicle, cfg.dynamic_lmi, cfg.rates.Td,
                                inputs_hash=key)
    if use_cache:
        try:
            atomic_write_text(path, json.dumps(design_to_dict(design)))
        except OSError as err:  # a read-only home must not stop a run; the design is still returned
            import sys

            print(f"tsmpc: cannot cache the {kind} design in {path} ({err.strerror or err}); it "
                  "will be solved again next time", file=sys.stderr)
    return design


def load_or_design_kinematic(
    cfg: Config, directory: Path | None = None, *, use_cache: bool = True
) -> KinematicDesign:
    """The kinematic design of ``cfg``, from the cache when its inputs are unchanged."""
    return _load_or_design(cfg, "kinematic", directory, use_cache)


def load_or_design_dynamic(
    cfg: Config, directory: Path | None = None, *, use_cache: bool = True
) -> DynamicDesign:
    """The dynamic design of ``cfg``, from the cache when its inputs are unchanged (the published
    run's feasibility design, :mod:`tsmpc.synthesis.paper_as_run`, when ``cfg`` selects it)."""
    if cfg.dynamic_lmi.formulation == DynamicLMIFormulation.FEASIBILITY_EULER:
        return load_or_design_feasibility(cfg, directory, use_cache=use_cache)  # type: ignore[return-value]
    return _load_or_design(cfg, "dynamic", directory, use_cache)


def load_or_design_feasibility(
    cfg: Config, directory: Path | None = None, *, use_cache: bool = True
) -> FeasibilityDesign:
    """The feasibility design of ``cfg`` from the design cache (keyed like every dynamic design,
    :func:`dynamic_key`), solved and stored when missing (the published run's design,
    :mod:`tsmpc.synthesis.paper_as_run`). The vertex certificates are recomputed on load; a stale
    or tampered entry is re-solved."""

    key = dynamic_key(cfg)
    path = (directory or cache_dir()) / f"dynamic-{key[:32]}.json"
    with _entry_lock(path, use_cache):
        return _load_or_solve_feasibility(cfg, key, path, use_cache)


def _load_or_solve_feasibility(cfg: Config, key: str, path: Path, use_cache: bool) -> FeasibilityDesign:
    from tsmpc.textfile import read_text

    lmi = cfg.dynamic_lmi
    if use_cache and path.exists():
        try:
            # a regular file of bounded size only (a folder, a FIFO: re-solved, never blocks)
            d = design_from_dict(json.loads(read_text(path, "design cache entry",
                                                      limit=64 * 1024 * 1024)), FeasibilityDesign)
            if d.inputs_hash == key:
                A, B = vertex_models(cfg.dynamic_box, cfg.vehicle, d.Td, d.bandwidth)
                check(certify_vertices(A, B, lmi, d.K, d.P), "cached feasibility design")
                return d
        except (TsmpcError, KeyError, ValueError, TypeError, AttributeError, RecursionError, OSError,
                np.linalg.LinAlgError):
            pass  # unreadable or stale entry: re-solve and overwrite it
    d = design_feasibility(cfg.dynamic_box, cfg.vehicle, lmi, cfg.rates.Td, inputs_hash=key)
    if use_cache:
        try:
            atomic_write_text(path, json.dumps(design_to_dict(d)))
        except OSError:
            pass  # a read-only home must not stop a run
    return d
