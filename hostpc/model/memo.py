"""The caches of a problem, as objects you can see: no module state in the numerics.

- :class:`SharedValues`: what the problems built from one dataset share, computed once: the
  robot chain (a URDF is read once per file version), the rig's point sensitivity of the
  shared-error model. A problem holds it as ``problem.shared``; its views
  (``Problem.subset``) and extensions (``extend_problem``) carry the same object, and another
  build of the same dataset may be handed it (``build_problem(..., shared=problem.shared)``).
  Without one, ``build_problem`` starts a new one: a build never sees another's values.
- :class:`ProblemMemo`: one problem's own values (its latest evaluation, its round-off
  cost): ``problem.memo``, new for every problem (a view or an extension gets its own).

A value is keyed by what it is derived from: an owner object (held by the cache, so its
identity cannot be reused while the entry lives) and a key naming the rest of the input.
numpy arrays handed out are read-only, so no caller can change what the next one gets.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

__all__ = ["ProblemMemo", "SharedValues"]

T = TypeVar("T")


def _read_only(value: T) -> T:
    for array in value if isinstance(value, tuple) else (value,):
        if isinstance(array, np.ndarray):
            array.setflags(write=False)
    return value


class SharedValues:
    """What the problems of one dataset share (see the module docstring); the least recently
    used values beyond ``size`` are dropped (computed again when asked)."""

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._values: OrderedDict[tuple[int, Hashable], tuple[object, Any]] = OrderedDict()

    def value(self, owner: object, key: Hashable, compute: Callable[[], T]) -> T:
        """``compute()`` the first time for (owner, key), the same value afterwards.

        owner: the object the value is derived from, compared by identity (a dataset's
        ``RobotDescription``), or None when ``key`` says everything (a content digest)."""
        slot = (id(owner), key)
        entry = self._values.get(slot)
        if entry is not None and entry[0] is owner:
            self._values.move_to_end(slot)
            cached: T = entry[1]
            return cached
        value = _read_only(compute())
        self._values[slot] = (owner, value)
        while len(self._values) > self.size:
            self._values.popitem(last=False)
        return value

    def __len__(self) -> int:
        return len(self._values)


class ProblemMemo:
    """One problem's own values, by name (see the module docstring)."""

    def __init__(self) -> None:
        self._values: dict[str, Any] = {}

    def value(self, key: str, compute: Callable[[], T]) -> T:
        """``compute()`` the first time for key, the same (read-only) value afterwards."""
        if key not in self._values:
            self._values[key] = _read_only(compute())
        cached: T = self._values[key]
        return cached

    def recall(self, key: str) -> Any:
        """The value last ``remember``-ed for key, or None."""
        return self._values.get(key)

    def remember(self, key: str, value: object) -> None:
        """Keep ``value`` for key in place of any earlier one (a one-value slot, e.g. the
        latest evaluation); the caller makes it immutable."""
        self._values[key] = value

    def forget(self, prefix: str) -> None:
        """Drop every value whose key starts with ``prefix`` (computed again when asked)."""
        for key in [k for k in self._values if k.startswith(prefix)]:
            del self._values[key]

    def keys(self) -> tuple[str, ...]:
        """The keys of the values kept."""
        return tuple(self._values)
