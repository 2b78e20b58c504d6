"""Effect registry: built-ins by name, user effects from a Python file or an entry point.

A plugin file defines one or more ``Effect`` subclasses (each with a unique ``name``); every
subclass defined in the file is registered. A package may also publish effects under the
entry-point group ``zerocal.effects`` (``name = "module:Class"``).
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from pathlib import Path

from hostpc.dataset.kind_registry import KindDescriptor, kind_descriptors
from hostpc.dataset.measurement_kind import MeasurementKind
from hostpc.errors import EffectError
from hostpc.model.effect import Effect
from hostpc.model.effects import BUILTIN_EFFECTS
from hostpc.model.measurements.base import MeasurementModel
from hostpc.plugins import classes_defined_in, entry_point_objects, import_plugin_file

ENTRY_POINT_GROUP = "zerocal.effects"
VALID_HOOKS = ("joint", "geometry", "sensor", "frame")


def builtin_effects() -> dict[str, type[Effect]]:
    """Name -> class of every built-in effect: hostpc.model.effects' and the frame effects
    the built-in kinds declare for their own frames (``own_frame_effects``)."""
    kinds = [d.model for d in kind_descriptors().values() if d.builtin]
    own: list[type[Effect]] = [cls for model in kinds if issubclass(model, MeasurementModel)
                               for cls in model.own_frame_effects]
    effects: list[type[Effect]] = [*BUILTIN_EFFECTS, *own]
    return {cls.name: cls for cls in effects}


def _check_effect_class(cls: type[Effect], origin: str) -> None:
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise EffectError(f"{origin}: effect class {cls.__name__} needs a `name` identifier")
    if getattr(cls, "hook", None) not in VALID_HOOKS:
        raise EffectError(
            f"{origin}: effect {name!r} has hook {getattr(cls, 'hook', None)!r}; "
            f"expected one of {', '.join(VALID_HOOKS)}"
        )


def load_plugin_file(path: str | Path) -> dict[str, type[Effect]]:
    """Import a Python file (once) and return the Effect subclasses it defines, by name.

    A file may define measurement models (or a folder a kind's descriptor) instead of (or
    besides) effects; a file that defines neither is an error."""
    module = import_plugin_file(path)
    found: dict[str, type[Effect]] = {}
    for cls in classes_defined_in(module, Effect):
        _check_effect_class(cls, f"plugin {path}")
        found[cls.name] = cls
    kinds = bool(classes_defined_in(module, MeasurementKind)) or any(
        isinstance(obj, KindDescriptor) for obj in vars(module).values())
    if not found and not kinds:
        raise EffectError(f"plugin {path}: defines no Effect subclass with a `name`")
    return found


def entry_point_effects() -> dict[str, type[Effect]]:
    """Effects published by installed packages under the `zerocal.effects` group (the scan
    runs once per process)."""
    found: dict[str, type[Effect]] = {}
    for entry_name, cls in entry_point_objects(ENTRY_POINT_GROUP):
        if not (inspect.isclass(cls) and issubclass(cls, Effect)):
            raise EffectError(f"entry point {entry_name}: {cls!r} is not an Effect subclass")
        _check_effect_class(cls, f"entry point {entry_name}")
        found[cls.name] = cls
    return found


def available_effects(plugins: Iterable[str | Path] = ()) -> dict[str, type[Effect]]:
    """Built-ins, then entry points, then plugin files (later ones may not shadow built-ins)."""
    registry = builtin_effects()
    for source in (entry_point_effects(), *(load_plugin_file(p) for p in plugins)):
        for name, cls in source.items():
            if name in registry and registry[name] is not cls and name in builtin_effects():
                raise EffectError(f"effect {name!r} from a plugin clashes with a built-in effect")
            registry[name] = cls
    return registry


def parse_effect_list(
    spec: str | Iterable[str] | None, default: Iterable[str]
) -> list[str]:
    """Effect names from a CLI/API spec.

    ``None`` -> the default list; ``"a,b"`` or ``["a", "b"]`` -> exactly those;
    entries starting with ``+`` are added to the default, ``-name`` removes one from it.
    """
    default = list(default)
    if spec is None:
        return default
    items = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
    items = [s for s in items if s]
    relative = all(s[0] in "+-" for s in items) if items else False
    names = list(default) if relative else []
    for item in items:
        if item.startswith("-"):
            if item[1:] not in names:
                raise EffectError(
                    f"cannot remove effect {item[1:]!r}: it is not in the model "
                    f"({', '.join(names) or 'empty'})"
                )
            names.remove(item[1:])
            continue
        name = item.lstrip("+")
        if name not in names:
            names.append(name)
    if not names:
        raise EffectError("no effects to fit: name at least one (e.g. --effects joint_offsets)")
    return names


def instantiate(names: Iterable[str], registry: Mapping[str, type[Effect]]) -> list[Effect]:
    """Effect instances for the given names; an unknown name is one clear error."""
    effects = []
    for name in names:
        if name not in registry:
            raise EffectError(
                f"unknown effect {name!r}; known effects: {', '.join(sorted(registry))}"
            )
        effects.append(registry[name]())
    return effects
