"""Effect registry: built-ins by name, user effects from a Python file or an entry point.

A plugin file defines one or more ``Effect`` subclasses (each with a unique ``name``); every
subclass defined in the file is registered. A package may also publish effects under the
entry-point group ``zerocal.effects`` (``name = "module:Class"``).
"""

from __future__ import annotations

import importlib.util
import inspect
import sys
from collections.abc import Iterable, Mapping
from importlib.metadata import entry_points
from pathlib import Path

from hostpc.errors import EffectError
from hostpc.model.effect import Effect
from hostpc.model.effects import BUILTIN_EFFECTS

ENTRY_POINT_GROUP = "zerocal.effects"
VALID_HOOKS = ("joint", "geometry", "sensor", "frame")


def builtin_effects() -> dict[str, type[Effect]]:
    """Name -> class of every built-in effect."""
    return {cls.name: cls for cls in BUILTIN_EFFECTS}


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
    """Import a Python file and return the Effect subclasses it defines, by name."""
    path = Path(path)
    if not path.is_file():
        raise EffectError(f"plugin {path}: no such file")
    module_name = f"zerocal_plugin_{path.stem}_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise EffectError(f"plugin {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # a user's file may fail in any way: report it in one line
        sys.modules.pop(module_name, None)
        raise EffectError(f"plugin {path}: failed to import: {type(exc).__name__}: {exc}") from exc
    found: dict[str, type[Effect]] = {}
    for _, obj in inspect.getmembers(module, inspect.isclass):
        if issubclass(obj, Effect) and obj.__module__ == module_name and "name" in obj.__dict__:
            _check_effect_class(obj, f"plugin {path}")
            found[obj.name] = obj
    if not found:
        raise EffectError(f"plugin {path}: defines no Effect subclass with a `name`")
    return found


def entry_point_effects() -> dict[str, type[Effect]]:
    """Effects published by installed packages under the `zerocal.effects` group."""
    found: dict[str, type[Effect]] = {}
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = entry.load()
        except Exception as exc:
            raise EffectError(f"entry point {entry.name}: failed to load: {exc}") from exc
        if not (inspect.isclass(cls) and issubclass(cls, Effect)):
            raise EffectError(f"entry point {entry.name}: {cls!r} is not an Effect subclass")
        _check_effect_class(cls, f"entry point {entry.name}")
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
