"""Loading user plugins: Python files given on the command line, and entry points.

Both plugin points (effects, ``hostpc.model.registry``; measurement models,
``hostpc.model.measurements.registry``) load through here, so a file named twice is imported
once and the entry-point scan (slow: it reads every installed distribution's metadata) runs
once per process and group.
"""

from __future__ import annotations

import importlib.util
import inspect
import os
import sys
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType
from typing import Any

from hostpc.errors import EffectError
from hostpc.input_files import PLUGIN, check_input_file

_MODULES: dict[str, ModuleType] = {}


def import_plugin_file(path: str | os.PathLike[str]) -> ModuleType:
    """Import a Python file once (cached by its resolved path); EffectError in one line.

    A folder with an ``__init__.py`` is a plugin package (a measurement kind in one folder,
    docs/measurement-models.md): its ``__init__`` is imported as the package, its other
    modules by relative import (``from .model import ...``)."""
    path = Path(path)
    if not os.path.lexists(path):
        raise EffectError(f"plugin {path}: no such file")
    package = path.is_dir() and os.path.lexists(path / "__init__.py")
    source = path / "__init__.py" if package else path
    check_input_file(source, PLUGIN, f"plugin {source}")  # a regular file within its limit
    key = str(path.resolve())
    if key in _MODULES:
        return _MODULES[key]
    module_name = f"zerocal_plugin_{path.stem}_{abs(hash(key))}"
    spec = importlib.util.spec_from_file_location(
        module_name, source, submodule_search_locations=[str(path)] if package else None)
    if spec is None or spec.loader is None:
        raise EffectError(f"plugin {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except KeyboardInterrupt:
        sys.modules.pop(module_name, None)
        raise
    except BaseException as exc:  # a user's file may fail in any way, even `raise SystemExit(0)`
        sys.modules.pop(module_name, None)
        raise EffectError(f"plugin {path}: failed to import: {type(exc).__name__}: {exc}") from exc
    _MODULES[key] = module
    return module


def classes_defined_in(module: ModuleType, base: type) -> list[type[Any]]:
    """The subclasses of ``base`` that ``module`` itself defines and that set ``name``."""
    return [obj for _, obj in inspect.getmembers(module, inspect.isclass)
            if issubclass(obj, base) and obj.__module__ == module.__name__
            and "name" in obj.__dict__]


@cache
def _installed_entry_points() -> Any:
    """Every installed entry point, of every group: the distributions' metadata read once
    for all of hostpc's groups (each ``entry_points(group=...)`` call reads it all again).
    Python 3.11 returns SelectableGroups, 3.12 EntryPoints: both ``.select(group=...)``."""
    return entry_points()


@cache
def entry_point_objects(group: str) -> tuple[tuple[str, Any], ...]:
    """(entry name, loaded object) of every entry point in ``group``; scanned once."""
    found = []
    for entry in _installed_entry_points().select(group=group):
        try:
            found.append((entry.name, entry.load()))
        except Exception as exc:
            raise EffectError(f"entry point {entry.name}: failed to load: {exc}") from exc
    return tuple(found)
