"""The ``zerocal-dataset/1`` file's structure and types, and one-line field errors.

The models (pydantic, in ``hostpc.dataset.schema_models``; ``schema.SampleSchema`` etc.
name them here) check structure and types only (strict: numbers must be JSON numbers, no
strings, no booleans); the checks that need the method, the units or several fields at
once live in ``hostpc.dataset.reading``. Numbers here are in the file's units.

:func:`validate` first tries plain checks that accept only what the models accept and
return what they return (a well-formed file is then read without importing pydantic:
~0.07 s of the 0.42 s CPU ``hostpc diagnose --ladder`` took); any value they do not accept
goes to the models, so every error message stays the models' own.

Every failure is a :class:`FieldError` carrying the location of the offending value
(``("samples", 3, "cov")``) and a one-line message; ``io`` prefixes the file name and
turns it into ``hostpc.errors.DatasetError``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from hostpc.dataset.field_errors import FieldError as FieldError
from hostpc.dataset.field_errors import Loc as Loc
from hostpc.dataset.field_errors import format_error as format_error
from hostpc.dataset.field_errors import format_loc as format_loc
from hostpc.dataset.field_errors import show as show
from hostpc.json_object import JsonObject

if TYPE_CHECKING:
    from hostpc.dataset.schema_models import Covariance as Covariance
    from hostpc.dataset.schema_models import DocumentSchema as DocumentSchema
    from hostpc.dataset.schema_models import FramePoseSchema as FramePoseSchema
    from hostpc.dataset.schema_models import JointRowSchema as JointRowSchema
    from hostpc.dataset.schema_models import Mat2 as Mat2
    from hostpc.dataset.schema_models import Mat3 as Mat3
    from hostpc.dataset.schema_models import RobotSchema as RobotSchema
    from hostpc.dataset.schema_models import SampleSchema as SampleSchema
    from hostpc.dataset.schema_models import SphereSchema as SphereSchema
    from hostpc.dataset.schema_models import StrictSchema as StrictSchema
    from hostpc.dataset.schema_models import TipFrameSchema as TipFrameSchema
    from hostpc.dataset.schema_models import UnitsSchema as UnitsSchema
    from hostpc.dataset.schema_models import Vec2 as Vec2
    from hostpc.dataset.schema_models import Vec3 as Vec3

FORMAT_TAG = "zerocal-dataset/1"


#: the fields of ``SampleSchema`` and ``DocumentSchema``, in their order (a test holds
#: them equal to the models' fields)
SAMPLE_FIELDS: tuple[str, ...] = (
    "q", "chain", "q_head", "q_arm", "p", "cov", "sigma", "group", "t", "approach",
    "temperature", "speed", "extra", "uv",
)
DOCUMENT_FIELDS: tuple[str, ...] = (
    "format", "method", "units", "robot", "frames", "known", "samples",
)


class _Unsure(Exception):
    """A plain check cannot vouch for the value: the models decide (and word any error)."""


def _number(value: Any) -> float:
    """A strict ``float`` as the models return it (an int becomes a float)."""
    if type(value) is float:
        return value
    if type(value) is int and abs(value) <= 2**53:  # exact as a float
        return float(value)
    raise _Unsure


def _numbers(value: Any, depth: int) -> list[Any]:
    """``list[float]`` (depth 1), ``list[list[float]]`` (2), ... as the models return it."""
    if type(value) is not list:
        raise _Unsure
    if depth == 1:
        return [_number(item) for item in value]
    return [_numbers(item, depth - 1) for item in value]


def _vec3(value: Any) -> list[float]:
    numbers = _numbers(value, 1)
    if len(numbers) != 3:
        raise _Unsure
    return numbers


def _text(value: Any) -> str:
    if type(value) is not str:
        raise _Unsure
    return value


_PLAIN: dict[Any, Callable[[Any], Any]] = {
    float: _number,
    str: _text,
    list[float]: lambda value: _numbers(value, 1),
    list[list[float]]: lambda value: _numbers(value, 2),
    list[list[list[float]]]: lambda value: _numbers(value, 3),
}
"""The plain checks of the types the column reader asks for (``reading_columns``)."""

_UNIT_CHOICES = {"length": ("m", "mm"), "angle": ("rad", "deg"), "time": ("s", "ms")}


def _units(value: Any) -> SimpleNamespace:
    """``UnitsSchema``: the file's units, defaults m, rad, s."""
    if type(value) is not dict:
        raise _Unsure
    units = {name: choices[0] for name, choices in _UNIT_CHOICES.items()}
    for name, unit in value.items():
        if name not in _UNIT_CHOICES or type(unit) is not str \
                or unit not in _UNIT_CHOICES[name]:
            raise _Unsure
        units[name] = unit
    return SimpleNamespace(**units)


_ROBOT_FIELDS = ("name", "convention", "joints", "mass", "com", "urdf", "base_link",
                 "tip_link")


def _document(doc: Any) -> SimpleNamespace:
    """``DocumentSchema`` of a document whose robot is a built-in ``name`` and whose samples
    are read by columns (``samples`` empty): the attributes the reader uses."""
    if type(doc) is not dict or doc.get("samples") != [] \
            or not {"format", "method", "robot", "frames"} <= doc.keys():
        raise _Unsure
    robot = doc["robot"]
    if type(robot) is not dict or robot.keys() != {"name"}:
        raise _Unsure
    known = doc.get("known", [])
    if type(known) is not list or type(doc["frames"]) is not dict:
        raise _Unsure
    return SimpleNamespace(
        format=_text(doc["format"]), method=_text(doc["method"]),
        units=_units(doc.get("units", {})),
        robot=SimpleNamespace(**{**dict.fromkeys(_ROBOT_FIELDS), "name": _text(robot["name"])}),
        frames=doc["frames"], known=[_text(name) for name in known], samples=[],
    )


def _frame_pose(value: Any) -> SimpleNamespace:
    """``FramePoseSchema``: ``{"xyz", "rpy"}``."""
    if type(value) is not dict or value.keys() != {"xyz", "rpy"}:
        raise _Unsure
    return SimpleNamespace(xyz=_vec3(value["xyz"]), rpy=_vec3(value["rpy"]))


def validate(kind: Any, value: Any, loc: Loc = ()) -> Any:
    """Validate ``value`` (a normalized JSON value) as ``kind`` (a model or a type).

    Raises:
        FieldError: at the first offending value, located under ``loc``.
    """
    check = _PLAIN.get(kind) if isinstance(kind, type | type(list[float])) else None
    if check is not None:
        try:
            return check(value)
        except _Unsure:
            pass
    from hostpc.dataset import schema_models

    return schema_models.validate(kind, value, loc)


def _plain_or_model(check: Callable[[Any], Any], model: str, value: Any, loc: Loc) -> Any:
    try:
        return check(value)
    except _Unsure:
        from hostpc.dataset import schema_models

        return schema_models.validate(getattr(schema_models, model), value, loc)


def validate_document(doc: Any) -> DocumentSchema:
    """``validate(DocumentSchema, doc)``; a plain record of the same attributes where the
    plain checks accept the document."""
    result: DocumentSchema = _plain_or_model(_document, "DocumentSchema", doc, ())
    return result


def validate_frame_pose(value: Any, loc: Loc) -> FramePoseSchema:
    """``validate(FramePoseSchema, value, loc)``, plainly where it can."""
    result: FramePoseSchema = _plain_or_model(_frame_pose, "FramePoseSchema", value, loc)
    return result


def validate_vec3(value: Any, loc: Loc) -> list[float]:
    """``validate(Vec3, value, loc)``, plainly where it can."""
    result: list[float] = _plain_or_model(_vec3, "Vec3", value, loc)
    return result


def _points(value: Any) -> dict[str, list[float]]:
    if type(value) is not dict:
        raise _Unsure
    return {_text(name): _vec3(point) for name, point in value.items()}


def validate_points(value: Any, loc: Loc) -> dict[str, list[float]]:
    """``validate(dict[str, Vec3], value, loc)`` (named points), plainly where it can."""
    try:
        return _points(value)
    except _Unsure:
        from hostpc.dataset import schema_models

        result: dict[str, list[float]] = schema_models.validate(
            dict[str, schema_models.Vec3], value, loc)
        return result


_MODELS = ("Covariance", "DocumentSchema", "FramePoseSchema", "JointRowSchema", "Mat2",
           "Mat3", "RobotSchema", "SampleSchema", "SphereSchema", "StrictSchema",
           "TipFrameSchema", "UnitsSchema", "Vec2", "Vec3")


def __getattr__(name: str) -> Any:
    """``schema.SampleSchema`` etc.: the models, imported (with pydantic) on first use."""
    if name in _MODELS:
        from hostpc.dataset import schema_models

        return getattr(schema_models, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class DuplicateKeys(JsonObject):
    """A JSON object in which some key appeared more than once (see ``pairs_hook``)."""

    duplicates: tuple[str, ...] = ()


class NonFinite:
    """Stands for a ``NaN``/``Infinity`` token of the JSON text until its path is known."""

    def __init__(self, token: str) -> None:
        self.token = token


def pairs_hook(pairs: Sequence[tuple[str, Any]]) -> JsonObject:
    """``json`` object hook that remembers duplicate keys instead of keeping the last."""
    result: JsonObject = {}
    duplicates: list[str] = []
    for key, value in pairs:
        if key in result:
            duplicates.append(key)
        result[key] = value
    if not duplicates:
        return result
    marked = DuplicateKeys(result)
    marked.duplicates = tuple(duplicates)
    return marked


_MAX_DEPTH = 64


def normalize(value: Any, loc: Loc = (), depth: int = 0) -> Any:
    """Copy a JSON-like value into plain dict/list/str/int/float/bool/None.

    Tuples and numpy arrays become lists, numpy scalars Python scalars.

    Raises:
        FieldError: a non-finite number, a duplicate key, a non-string key, nesting deeper
            than 64 levels, or a value JSON cannot hold.
    """
    if depth > _MAX_DEPTH:
        raise FieldError(loc, "nested too deeply")
    if isinstance(value, NonFinite):
        raise FieldError(loc, f"not a finite number ({value.token} is not allowed)")
    if value is None or isinstance(value, bool | str):
        return value
    if hasattr(value, "tolist") and callable(value.tolist) and not isinstance(value, list):
        try:
            value = value.tolist()  # numpy array or scalar
        except (TypeError, ValueError) as exc:
            raise FieldError(loc, f"unsupported value of type {type(value).__name__}") from exc
        if value is None or isinstance(value, bool | str):
            return value
    if isinstance(value, int):
        if abs(value) > 1.7976931348623157e308:
            raise FieldError(loc, "not a finite number (out of range)")
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise FieldError(loc, "not a finite number")
        return value
    if isinstance(value, dict):
        if isinstance(value, DuplicateKeys):
            raise FieldError(loc, f"duplicate key {show(value.duplicates[0])}")
        result: JsonObject = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise FieldError(loc, f"keys must be strings, got {show(key)}")
            result[key] = normalize(item, (*loc, key), depth + 1)
        return result
    if isinstance(value, list | tuple):
        return [normalize(item, (*loc, i), depth + 1) for i, item in enumerate(value)]
    raise FieldError(loc, f"unsupported value of type {type(value).__name__}")
