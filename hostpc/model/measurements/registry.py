"""The measurement models that can be fitted, by name: the fitting layer's view of the one
kind registry (``hostpc.dataset.kind_registry``: built-ins, entry points
``zerocal.measurements`` and plugin files, ``--plugin``).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from hostpc.dataset.kind_registry import measurement_kinds
from hostpc.errors import InputError
from hostpc.model.measurements.base import MeasurementModel

__all__ = ["measurement_model", "measurement_models"]


def measurement_models(plugins: Iterable[str | Path] = ()) -> dict[str, type[MeasurementModel]]:
    """Name -> class of every measurement model that can be fitted: the built-ins, then
    entry points, then the plugin files' (a file-format-only kind is left out)."""
    kinds = measurement_kinds(plugins)
    return {name: cls for name, cls in kinds.items() if issubclass(cls, MeasurementModel)}


def measurement_model(method: str, plugins: Iterable[str | Path] = ()) -> MeasurementModel:
    """The model of ``method``; InputError naming the known ones if there is none."""
    models = measurement_models(plugins)
    if method not in models:
        raise InputError(f"method {method!r} is not supported by the fit (known measurement "
                         f"models: {', '.join(models)}; a plugin's needs --plugin FILE)")
    return models[method]()
