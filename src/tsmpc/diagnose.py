"""Which configuration field a failed LMI design most likely blames (issue 24).

A design that cannot be solved or certified for a valid configuration is an input problem: the
CLI exits 2 and names the field most likely responsible. The designs depend on few inputs
(SPEC §6): the kinematic design on ``kinematic_box``, ``kinematic_lmi`` and ``rates.Tc``; the
dynamic one on ``dynamic_box``, ``dynamic_lmi``, ``vehicle`` and ``rates.Td``. The defaults are
designed and certified (the test suite does it), so the suspects are the inputs that differ from
them, the one furthest from its default (relative change, log scale) first.
"""

from __future__ import annotations

import math
from typing import Any

from tsmpc.config import Config

__all__ = ["DESIGN_INPUTS", "explain_design_failure", "suspect_fields"]

#: The config sections / fields each design depends on (SPEC §6).
DESIGN_INPUTS: dict[str, tuple[str, ...]] = {
    "kinematic": ("kinematic_box", "kinematic_lmi", "rates.Tc"),
    "dynamic": ("dynamic_box", "dynamic_lmi", "vehicle", "rates.Td"),
}


def _leaves(prefix: str, value: Any) -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_leaves(f"{prefix}.{k}", v))
        return out
    return {prefix: value}


def _distance(a: Any, b: Any) -> float:
    """How far value ``a`` is from the default ``b`` (log-scale relative change; 1 for changes
    that are not numbers)."""
    def nums(x: Any) -> list[float] | None:
        if isinstance(x, bool):
            return None
        if isinstance(x, int | float):
            return [float(x)]
        if isinstance(x, list | tuple) and all(isinstance(v, int | float) and not isinstance(v, bool)
                                              for v in x):
            return [float(v) for v in x]
        return None

    na, nb = nums(a), nums(b)
    if na is None or nb is None or len(na) != len(nb):
        return 1.0
    d = 0.0
    for x, y in zip(na, nb, strict=True):
        if x == y:
            continue
        if x != 0 and y != 0 and (x > 0) == (y > 0):
            d = max(d, abs(math.log10(abs(x) / abs(y))))
        else:
            d = max(d, 1.0 + abs(x - y) / (abs(x) + abs(y)))
    return d


def suspect_fields(kind: str, cfg: Config) -> list[tuple[str, Any, Any]]:
    """(field, value, default) of the design's inputs that differ from the defaults, the one
    furthest from its default first."""
    here, base = cfg.model_dump(mode="json"), Config().model_dump(mode="json")
    rows = []
    for name in DESIGN_INPUTS[kind]:
        section, _, leaf = name.partition(".")
        mine = here[section] if not leaf else {leaf: here[section][leaf]}
        theirs = base[section] if not leaf else {leaf: base[section][leaf]}
        a, b = _leaves(section, mine), _leaves(section, theirs)
        for key, value in a.items():
            if value != b.get(key):
                rows.append((_distance(value, b.get(key)), key, value, b.get(key)))
    rows.sort(key=lambda r: -r[0])
    return [(k, v, d) for _, k, v, d in rows]


def explain_design_failure(kind: str, cfg: Config, err: BaseException) -> str:
    """One line: which design failed and on which inputs, why (the solver's words, shortened to
    1000 characters) and the field most likely responsible."""
    reason = " ".join(str(err).split()) or type(err).__name__
    if len(reason) > 1000:
        reason = reason[:1000] + "…"
    suspects = suspect_fields(kind, cfg)
    if suspects:
        key, value, default = suspects[0]
        more = f" (also changed: {', '.join(k for k, _, _ in suspects[1:4])})" if len(suspects) > 1 else ""
        blame = f"most likely field: {key} = {value!r} (default {default!r}){more}"
    else:
        blame = "the design's inputs are the defaults"
    return (f"no certified {kind} LMI design for this config ({', '.join(DESIGN_INPUTS[kind])}): "
            f"{type(err).__name__}: {reason}; {blame}")
