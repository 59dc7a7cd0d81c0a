"""Frozen dataclasses made per control step, built fast; named views of a block's state arrays.

A frozen dataclass's generated ``__init__`` sets each field through ``object.__setattr__`` (the
class forbids its own ``__setattr__``): ≈ 0.15 µs a field, 2 µs for a :class:`~tsmpc.control.cascade.Command`
of 12 fields, made at every ``Cascade.step``. :func:`quick_init` gives the class an ``__init__``
that writes the instance's dict in one call instead; the class stays a frozen dataclass (fields,
defaults, repr, equality, hashing and the frozen ``__setattr__`` are the generated ones).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, fields
from typing import Any, TypeVar, overload

__all__ = ["StateField", "quick_init"]

T = TypeVar("T", bound=type)


def quick_init(cls: T) -> T:
    """Replace the ``__init__`` of the frozen dataclass ``cls`` (plain defaults only, no
    ``__post_init__``) by one that writes its fields into the instance's dict at once."""
    fs = fields(cls)
    if hasattr(cls, "__post_init__") or any(f.default_factory is not MISSING or not f.init for f in fs):
        raise TypeError(f"quick_init: {cls.__name__} needs plain fields")
    params = ", ".join(f.name if f.default is MISSING else f"{f.name}=_d_{f.name}" for f in fs)
    body = ", ".join(f"{f.name}={f.name}" for f in fs)
    ns: dict[str, Any] = {f"_d_{f.name}": f.default for f in fs if f.default is not MISSING}
    exec(f"def __init__(self, {params}):\n    self.__dict__.update({body})\n", ns)
    init = ns["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__module__ = cls.__module__
    setattr(cls, "__init__", init)  # noqa: B010
    return cls


class StateField:
    """A named view of an online block's state array (the array the compiled step updates in
    place): ``StateField("_s", slice(0, 2))`` reads and writes ``obj._s[0:2]``;
    ``StateField("_s", 2, float)`` the element ``obj._s[2]``, read through ``cast``."""

    def __init__(self, array: str, index: int | slice, cast: Callable[[Any], Any] | None = None) -> None:
        self.array, self.index, self.cast = array, index, cast

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> StateField: ...
    @overload
    def __get__(self, obj: object, owner: type | None = None) -> Any: ...

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        if obj is None:
            return self
        v = getattr(obj, self.array)[self.index]
        return v if self.cast is None else self.cast(v)

    def __set__(self, obj: Any, value: Any) -> None:
        getattr(obj, self.array)[self.index] = value
