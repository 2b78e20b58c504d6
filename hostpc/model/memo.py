"""What a problem build derives from a dataset's immutable parts, computed once per dataset.

`hostpc.fit`, `hostpc.diagnose`, the ladder's models and every candidate effect build a
problem from the same dataset; its robot chain, the gravity torques of its poses and the
whitening of its covariances do not change between those builds (the dataset's arrays are
read-only, its dataclasses frozen), so they are kept with the object they come from (by a
weak reference: the entry goes with the dataset). A value is keyed by the owner's
identity (``Samples``, ``RobotDescription``: ``eq=False`` dataclasses) and a name; arrays
handed out are read-only, so no caller can change what the next build gets.
"""

from __future__ import annotations

import functools
import threading
import weakref
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

__all__ = ["memoised", "recall", "remember"]

T = TypeVar("T")

#: id(owner) -> (weak reference to the owner, its values by key); the dataset's dataclasses
#: compare by value and are unhashable, so they are looked up by identity
_VALUES: dict[int, tuple[weakref.ref[Any], dict[Hashable, Any]]] = {}
_LOCK = threading.Lock()


def _forget(ident: int, ref: weakref.ref[Any]) -> None:
    with _LOCK:
        entry = _VALUES.get(ident)
        if entry is not None and entry[0] is ref:
            del _VALUES[ident]


def memoised(owner: object, key: Hashable, compute: Callable[[], T]) -> T:
    """``compute()`` the first time for (owner, key), the same value afterwards.

    owner: an immutable object compared by identity (a dataset's ``Samples`` or
    ``RobotDescription``); key: what is derived from it (include any other input, e.g. the
    chain). numpy arrays in the value (or a tuple of them) are made read-only."""
    ident = id(owner)
    with _LOCK:
        entry = _VALUES.get(ident)
        if entry is not None and entry[0]() is owner and key in entry[1]:
            cached: T = entry[1][key]
            return cached
    value = compute()
    for array in value if isinstance(value, tuple) else (value,):
        if isinstance(array, np.ndarray):
            array.setflags(write=False)
    remember(owner, key, value)
    return value


def recall(owner: object, key: Hashable) -> Any:
    """The value last ``remember``-ed for (owner, key), or None."""
    with _LOCK:
        entry = _VALUES.get(id(owner))
        if entry is None or entry[0]() is not owner:
            return None
        return entry[1].get(key)


def remember(owner: object, key: Hashable, value: object) -> None:
    """Keep ``value`` for (owner, key) in place of any earlier one (a one-value slot, e.g.
    the latest evaluation of a problem); the caller makes it immutable."""
    ident = id(owner)
    with _LOCK:
        entry = _VALUES.get(ident)
        if entry is None or entry[0]() is not owner:
            ref: weakref.ref[Any] = weakref.ref(owner, functools.partial(_forget, ident))
            entry = (ref, {})
            _VALUES[ident] = entry
        entry[1][key] = value
