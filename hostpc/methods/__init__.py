"""Measurement methods and the shared calibration procedure.

A method is one `hostpc.methods.base.Method` subclass (plan candidates, acquire one sample
per pose, build the dataset) in its kind's folder (`hostpc/kinds/<name>/method.py`), named
by the kind's descriptor as "module:Class" and imported on first use;
`hostpc.calibrate.runner` runs every method through the same procedure (journal, resume,
planning, fit, guarded push, verify, report).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from pathlib import Path

from hostpc.dataset.kind_registry import kind_descriptors
from hostpc.errors import InputError
from hostpc.methods.base import Method


def method_names(plugins: Iterable[str | Path] = ()) -> tuple[str, ...]:
    """The kinds that can be measured live (`hostpc calibrate --method`)."""
    return tuple(name for name, kind in kind_descriptors(plugins).items()
                 if kind.method is not None)


def method_class(name: str, plugins: Iterable[str | Path] = ()) -> type[Method]:
    """The Method class of kind `name`; InputError if unknown or not built yet."""
    kind = kind_descriptors(plugins).get(name)
    if kind is None or kind.method is None:
        raise InputError(f"--method {name!r}: unknown (known: {', '.join(method_names(plugins))})")
    module_name, _, class_name = kind.method.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            raise InputError(f"--method {name!r} is not available in this build") from None
        raise
    cls: type[Method] = getattr(module, class_name)
    return cls


__all__ = ["method_class", "method_names"]
