"""Measurement models by name: built-ins, entry points (``zerocal.measurements``) and plugin
files, like the effects' registry (``hostpc.model.registry``).

A plugin file given with ``--plugin`` may define ``MeasurementModel`` subclasses next to
its effects; an installed package publishes one as an entry point
``name = "module:Class"`` in the group ``zerocal.measurements`` (scanned once per process).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from hostpc.dataset.kinds import ENTRY_POINT_GROUP, measurement_kinds
from hostpc.errors import InputError
from hostpc.model.measurements.base import MeasurementModel
from hostpc.model.measurements.dual_loop import DualLoop
from hostpc.model.measurements.sphere_probe import SphereProbe
from hostpc.model.measurements.stereo_target import StereoTarget
from hostpc.model.measurements.world_point import WorldPoint
from hostpc.model.measurements.world_pose import WorldPose

__all__ = ["BUILTIN_MODELS", "ENTRY_POINT_GROUP", "measurement_model", "measurement_models"]

BUILTIN_MODELS: tuple[type[MeasurementModel], ...] = (StereoTarget, SphereProbe, DualLoop,
                                                      WorldPoint, WorldPose)


def measurement_models(plugins: Iterable[str | Path] = ()) -> dict[str, type[MeasurementModel]]:
    """Name -> class of every measurement model that can be fitted: the built-ins, then
    entry points, then the plugin files' (a file-format-only kind is left out)."""
    kinds = measurement_kinds(plugins, builtins=BUILTIN_MODELS)
    return {name: cls for name, cls in kinds.items() if issubclass(cls, MeasurementModel)}


def measurement_model(method: str, plugins: Iterable[str | Path] = ()) -> MeasurementModel:
    """The model of ``method``; InputError naming the known ones if there is none."""
    models = measurement_models(plugins)
    if method not in models:
        raise InputError(f"method {method!r} is not supported by the fit (known measurement "
                         f"models: {', '.join(models)}; a plugin's needs --plugin FILE)")
    return models[method]()
