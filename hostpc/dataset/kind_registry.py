"""The measurement kinds a dataset file may name: built-ins, entry points, plugin files.

``measurement_kinds(plugins)`` is what the dataset layer reads and writes with; the model
layer's registry (``hostpc.model.measurements.registry``) extends the same lookup with the
prediction. A package publishes a measurement model under the entry-point group
``zerocal.measurements`` (``name = "module:Class"``); a plugin file (``--plugin``) may
define one or more ``MeasurementModel`` subclasses next to its effects.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Iterable

from hostpc.dataset.builtin_kinds import DualLoopFile, SphereProbeFile, StereoTargetFile
from hostpc.dataset.kind import FRAME_KINDS, MeasurementKind
from hostpc.dataset.world_kinds import WorldPointFile, WorldPoseFile
from hostpc.errors import EffectError
from hostpc.plugins import classes_defined_in, entry_point_objects, import_plugin_file

ENTRY_POINT_GROUP = "zerocal.measurements"
BUILTIN_KINDS: tuple[type[MeasurementKind], ...] = (
    StereoTargetFile, SphereProbeFile, DualLoopFile, WorldPointFile, WorldPoseFile)


def check_kind_class(cls: type[MeasurementKind], origin: str) -> None:
    """Raise EffectError unless ``cls`` names itself and declares known frame kinds."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise EffectError(f"{origin}: measurement class {cls.__name__} needs a `name` identifier")
    for frame, kind in cls.frames.items():
        if kind not in FRAME_KINDS:
            raise EffectError(f"{origin}: measurement {name!r} frame {frame!r} has kind "
                              f"{kind!r}; expected one of {', '.join(FRAME_KINDS)}")


def entry_point_kinds() -> dict[str, type[MeasurementKind]]:
    """Measurement models published under ``zerocal.measurements`` (scanned once)."""
    found: dict[str, type[MeasurementKind]] = {}
    for entry_name, cls in entry_point_objects(ENTRY_POINT_GROUP):
        if not (inspect.isclass(cls) and issubclass(cls, MeasurementKind)):
            raise EffectError(f"entry point {entry_name}: {cls!r} is not a measurement model")
        check_kind_class(cls, f"entry point {entry_name}")
        found[cls.name] = cls
    return found


def plugin_file_kinds(path: str | os.PathLike[str]) -> dict[str, type[MeasurementKind]]:
    """The measurement models a plugin file defines, by name (maybe none)."""
    module = import_plugin_file(path)
    found: dict[str, type[MeasurementKind]] = {}
    for cls in classes_defined_in(module, MeasurementKind):
        check_kind_class(cls, f"plugin {path}")
        found[cls.name] = cls
    return found


def measurement_kinds(plugins: Iterable[str | os.PathLike[str]] = (),
                      builtins: Iterable[type[MeasurementKind]] = BUILTIN_KINDS
                      ) -> dict[str, type[MeasurementKind]]:
    """Name -> class: built-ins, then entry points, then plugin files; a plugin may not
    shadow a built-in."""
    registry = {cls.name: cls for cls in builtins}
    builtin_names = set(registry)
    for source in (entry_point_kinds(), *(plugin_file_kinds(p) for p in plugins)):
        for name, cls in source.items():
            if name in builtin_names:
                raise EffectError(f"measurement model {name!r} from a plugin clashes with a "
                                  "built-in one")
            registry[name] = cls
    return registry
