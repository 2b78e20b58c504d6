"""The one registry of measurement kinds: built-ins and plugins alike.

A measurement kind is one folder (``hostpc/kinds/<name>/`` for the built-ins) that publishes
one ``KindDescriptor``: its file face and model (one class: ``MeasurementModel`` extends the
file face ``MeasurementKind``), its acquisition method (``"module:Class"``, imported only
when a run needs it, so this pure layer never imports I/O), the frames ``--known`` may hold,
and its ``--robot sim`` world. Every caller asks this registry by name; nothing else keeps a
table keyed by a kind's name.

Where kinds come from (``kind_descriptors(plugins)``):
- entry points of the group ``zerocal.measurements`` (scanned once per process): zerocal
  publishes its own built-ins there (``pyproject.toml``), so this generic layer finds them
  without importing ``hostpc.kinds`` (an import contract forbids that); an installed package
  publishes a descriptor or a bare ``MeasurementModel`` class the same way;
- plugin files or folders (``--plugin``): every ``KindDescriptor`` at module level, and
  every ``MeasurementKind`` subclass the file defines that no descriptor names.
A plugin may not shadow a built-in.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from hostpc.dataset.measurement_kind import FRAME_KINDS, MeasurementKind
from hostpc.errors import EffectError
from hostpc.plugins import classes_defined_in, entry_point_objects, import_plugin_file

ENTRY_POINT_GROUP = "zerocal.measurements"
#: the module prefix of zerocal's own kinds (a plugin may not take their names)
BUILTIN_PREFIX = "hostpc.kinds."
#: the kind a plain ``hostpc calibrate`` (and ``--robot sim`` without a method) uses
DEFAULT_METHOD = "stereo_target"


@dataclass(frozen=True)
class SimDefault:
    """A kind's default simulated world (``hostpc calibrate --robot sim``).

    scenario: packaged scenario file of controller_stub; overrides: merged into it;
    known: frames the simulated cell declares as measured (surveyed)."""

    scenario: str = "default.yaml"
    overrides: Mapping[str, Any] = field(default_factory=dict)
    known: tuple[str, ...] = ()


@dataclass(frozen=True)
class KindOption:
    """A ``hostpc calibrate`` option of a kind's acquisition (flag ``--key-with-dashes``),
    recorded in the run's settings as ``RunSettings.options[key]``.

    help: its help text; metavar / choices: as argparse's; number: a finite float within
    [least, most]; path: a file, recorded as its absolute path. default: its value when not
    given; it is recorded only when the value differs from it, or always with
    record_default. exclusive: a value other than the default is refused for a method whose
    kind does not declare the option. needs: (key, value) another option must have for this
    one to be given."""

    key: str
    help: str
    metavar: str | None = None
    choices: tuple[str, ...] | None = None
    default: str | None = None
    record_default: bool = False
    number: bool = False
    least: float | None = None
    most: float | None = None
    path: bool = False
    exclusive: bool = False
    needs: tuple[str, str] | None = None

    @property
    def flag(self) -> str:
        return "--" + self.key.replace("_", "-")


@dataclass(frozen=True)
class KindDescriptor:
    """Everything zerocal knows about one measurement kind, registered once.

    model: the kind's class, the file face (``MeasurementKind``) and, when it can be
    fitted, the prediction (a ``hostpc.model.measurements.MeasurementModel``);
    method: ``"module:Class"`` of its acquisition ``hostpc.methods.base.Method`` (None: the
    kind is measured offline and imported, no ``hostpc calibrate``);
    known_frames: the frames ``--known`` may hold (None: any);
    sim: its ``--robot sim`` world (None: stereo_target's);
    cli_options: the method's own ``hostpc calibrate`` options (``KindOption``, e.g.
    ``--probe-io``; an option several kinds take is one object they share);
    csv_rows: what ``hostpc import`` reads from a metrology CSV row for it, ``"point"`` (x,
    y, z; a marker per reflector) or ``"pose"`` (x, y, z and an orientation); None: not
    imported from a CSV."""

    name: str
    model: type[MeasurementKind]
    method: str | None = None
    known_frames: tuple[str, ...] | None = None
    sim: SimDefault | None = None
    csv_rows: str | None = None
    cli_options: tuple[KindOption, ...] = ()

    @property
    def builtin(self) -> bool:
        return self.model.__module__.startswith(BUILTIN_PREFIX)


def check_kind_class(cls: type[MeasurementKind], origin: str) -> None:
    """Raise EffectError unless ``cls`` names itself and declares known frame kinds."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise EffectError(f"{origin}: measurement class {cls.__name__} needs a `name` identifier")
    for frame, kind in cls.frames.items():
        if kind not in FRAME_KINDS:
            raise EffectError(f"{origin}: measurement {name!r} frame {frame!r} has kind "
                              f"{kind!r}; expected one of {', '.join(FRAME_KINDS)}")


def _descriptor(obj: object, origin: str) -> KindDescriptor:
    """A published object as a descriptor: a KindDescriptor, or a bare kind class."""
    if isinstance(obj, KindDescriptor):
        descriptor = obj
    elif inspect.isclass(obj) and issubclass(obj, MeasurementKind):
        descriptor = KindDescriptor(name=getattr(obj, "name", ""), model=obj)
    else:
        raise EffectError(f"{origin}: {obj!r} is not a measurement model")
    check_kind_class(descriptor.model, origin)
    if descriptor.name != descriptor.model.name:
        raise EffectError(f"{origin}: kind {descriptor.name!r} names a model called "
                          f"{descriptor.model.name!r}")
    return descriptor


def entry_point_kinds() -> dict[str, KindDescriptor]:
    """Kinds published under ``zerocal.measurements`` (zerocal's own among them)."""
    found: dict[str, KindDescriptor] = {}
    for entry_name, obj in entry_point_objects(ENTRY_POINT_GROUP):
        descriptor = _descriptor(obj, f"entry point {entry_name}")
        if descriptor.name in found:
            raise EffectError(f"entry point {entry_name}: measurement model "
                              f"{descriptor.name!r} is published twice")
        found[descriptor.name] = descriptor
    if DEFAULT_METHOD not in found:
        raise EffectError(f"zerocal's built-in measurement kinds are not registered (no "
                          f"{DEFAULT_METHOD!r} in the entry points {ENTRY_POINT_GROUP!r}): "
                          "reinstall zerocal (pip install -e .)")
    return found


def plugin_file_kinds(path: str | os.PathLike[str]) -> dict[str, KindDescriptor]:
    """The kinds a plugin file (or folder) defines, by name (maybe none)."""
    module = import_plugin_file(path)
    origin = f"plugin {path}"
    found = {d.name: d for d in (_descriptor(obj, origin) for obj in vars(module).values()
                                 if isinstance(obj, KindDescriptor))}
    described = {d.model for d in found.values()}
    for cls in classes_defined_in(module, MeasurementKind):
        if cls not in described and getattr(cls, "name", None) not in found:
            descriptor = _descriptor(cls, origin)
            found[descriptor.name] = descriptor
    return found


def kind_descriptors(plugins: Iterable[str | os.PathLike[str]] = ()
                     ) -> Mapping[str, KindDescriptor]:
    """Name -> descriptor: entry points (built-ins first), then plugin files; a plugin may
    not shadow a built-in."""
    published = entry_point_kinds()
    registry = {name: d for name, d in published.items() if d.builtin}
    builtin_names = set(registry)
    for source in ({n: d for n, d in published.items() if not d.builtin},
                   *(plugin_file_kinds(p) for p in plugins)):
        for name, descriptor in source.items():
            if name in builtin_names:
                raise EffectError(f"measurement model {name!r} from a plugin clashes with a "
                                  "built-in one")
            registry[name] = descriptor
    return MappingProxyType(registry)


def kind_descriptor(name: str, plugins: Iterable[str | os.PathLike[str]] = ()
                    ) -> KindDescriptor | None:
    """The descriptor of ``name`` (None if no kind has that name)."""
    return kind_descriptors(plugins).get(name)


def csv_row_kinds(rows: str | None = None) -> tuple[str, ...]:
    """The kinds ``hostpc import`` writes (with ``rows``: those whose CSV rows are that)."""
    return tuple(name for name, d in kind_descriptors().items()
                 if d.csv_rows is not None and rows in (None, d.csv_rows))


def csv_row_shape(method: str) -> str | None:
    """What a metrology CSV row of ``method`` holds (``KindDescriptor.csv_rows``)."""
    descriptor = kind_descriptor(method)
    return descriptor.csv_rows if descriptor is not None else None


def kind_options() -> tuple[KindOption, ...]:
    """The ``hostpc calibrate`` options of the registered kinds (plugin files' excluded:
    the command line is built before ``--plugin`` is read), each once: the default kind's
    first, then the others' in registry order."""
    kinds = kind_descriptors()
    ordered = [kinds[DEFAULT_METHOD], *(d for n, d in kinds.items() if n != DEFAULT_METHOD)]
    found: dict[str, KindOption] = {}
    for descriptor in ordered:
        for option in descriptor.cli_options:
            found.setdefault(option.key, option)
    return tuple(found.values())


def measurement_kinds(plugins: Iterable[str | os.PathLike[str]] = ()
                      ) -> dict[str, type[MeasurementKind]]:
    """Name -> class (file face, and model where it has one) of every registered kind."""
    return {name: d.model for name, d in kind_descriptors(plugins).items()}
