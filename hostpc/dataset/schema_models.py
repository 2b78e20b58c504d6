"""The ``zerocal-dataset/1`` file as pydantic models (strict: numbers must be JSON numbers,
no strings, no booleans), and their one-line field errors.

This is the only module of hostpc.dataset that imports pydantic; ``hostpc.dataset.schema``
(the names every reader uses) imports it on first need, so a well-formed file, which its
plain checks accept, is read without pydantic (its import and the models' building were
~0.07 s of ``hostpc diagnose``'s CPU). Numbers here are in the file's units.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
)
from pydantic_core import PydanticCustomError

from hostpc.dataset.field_errors import FieldError, Loc, show
from hostpc.json_object import JsonObject


def _length(n: int) -> AfterValidator:
    """Validator: the list has exactly ``n`` entries."""

    def check(value: list[Any]) -> list[Any]:
        if len(value) != n:
            raise PydanticCustomError(
                "wrong_length", "expected {n} values, got {got}", {"n": n, "got": len(value)}
            )
        return value

    return AfterValidator(check)


def _wrong_shape(rows: int, cols: int, value: Any) -> PydanticCustomError:
    return PydanticCustomError(
        "wrong_shape",
        "expected a {rows}x{cols} matrix ({rows} lists of {cols} numbers), got {got}",
        {"rows": rows, "cols": cols, "got": show(value)},
    )


def _matrix(rows: int, cols: int) -> BeforeValidator:
    """Validator: a list of ``rows`` lists of ``cols`` entries (checked before the entries)."""

    def check(value: Any) -> Any:
        if isinstance(value, list) and (
            len(value) != rows
            or not all(isinstance(row, list) and len(row) == cols for row in value)
        ):
            raise _wrong_shape(rows, cols, value)
        return value

    return BeforeValidator(check)


def _square(*sizes: int) -> BeforeValidator:
    """Validator: a square matrix of one of ``sizes`` (the message names the first)."""

    def check(value: Any) -> Any:
        if isinstance(value, list) and (
            len(value) not in sizes
            or not all(isinstance(row, list) and len(row) == len(value) for row in value)
        ):
            raise _wrong_shape(sizes[0], sizes[0], value)
        return value

    return BeforeValidator(check)


Vec2 = Annotated[list[float], _length(2)]
Vec3 = Annotated[list[float], _length(3)]
Mat3 = Annotated[list[Vec3], _matrix(3, 3)]
Mat2 = Annotated[list[Vec2], _matrix(2, 2)]
#: a 3x3 covariance, or world_pose's 6x6 (the kind checks which it needs)
Covariance = Annotated[list[list[float]], _square(3, 6)]


class StrictSchema(BaseModel):
    """A JSON object with exactly these fields (a kind's own blocks subclass it too)."""

    # built on first use: a file reads only some of them (defer_build: no behaviour change)
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True, defer_build=True)


class UnitsSchema(StrictSchema):
    """``units``: the units of the file's numbers (default SI)."""

    length: Literal["m", "mm"] = "m"
    angle: Literal["rad", "deg"] = "rad"
    time: Literal["s", "ms"] = "s"


class JointRowSchema(StrictSchema):
    """One row of an explicit DH/MDH table (lengths and angles in the file's units)."""

    a: float
    alpha: float
    d: float
    theta: float
    type: Literal["revolute", "prismatic"] = "revolute"  # extension A: prismatic q adds to d


class RobotSchema(StrictSchema):
    """``robot``: ``{"name": ...}`` or ``{"convention", "joints", "mass"?, "com"?}``."""

    name: str | None = None
    convention: Literal["dh", "mdh"] | None = None
    joints: list[JointRowSchema] | None = None
    mass: list[float] | None = None
    com: list[Vec3] | None = None
    urdf: str | None = None  # extension A: a URDF file, relative to the dataset file
    base_link: str | None = None
    tip_link: str | None = None


class FramePoseSchema(StrictSchema):
    """A frame as ``xyz`` (length) and ``rpy`` (angle)."""

    xyz: Vec3
    rpy: Vec3


class TipFrameSchema(StrictSchema):
    """``frames.tool`` of sphere_probe: only ``xyz`` matters, ``rpy`` may be omitted."""

    xyz: Vec3
    rpy: Vec3 | None = None


class SphereSchema(StrictSchema):
    """``frames.sphere``: centre (length, base frame) and radius (length)."""

    center: Vec3
    radius: float


class SampleSchema(BaseModel):
    """One sample, all built-in methods together; the measurement kind checks which fields
    its method needs. Fields a plugin's kind declares arrive as extra fields (checked by
    that kind; any other extra field is an error)."""

    model_config = ConfigDict(strict=True, extra="allow", frozen=True)

    q: list[float] | None = None
    chain: Literal["left", "right"] | None = None
    q_head: list[float] | None = None
    q_arm: list[float] | None = None
    p: Vec3 | None = None
    cov: Covariance | None = None
    sigma: float | None = None
    group: Annotated[int, Field(ge=0, lt=2**31)] | None = None
    t: float | None = None
    approach: list[float] | None = None
    temperature: float | None = None
    speed: float | None = None
    extra: dict[str, float] | None = None
    uv: Mat2 | None = None


class DocumentSchema(BaseModel):
    """The whole document; unknown top-level fields are allowed and kept."""

    model_config = ConfigDict(strict=True, extra="allow", frozen=True)

    format: str
    method: str
    units: UnitsSchema = UnitsSchema()
    robot: RobotSchema
    frames: JsonObject
    known: list[str] = []
    samples: list[SampleSchema]


def _describe(error: Any) -> str:
    """One line for one pydantic error dict."""
    kind = error["type"]
    ctx = error.get("ctx") or {}
    got = show(error.get("input"))
    messages: dict[str, Callable[[], str]] = {
        "missing": lambda: "required field missing",
        "extra_forbidden": lambda: "unknown field",
        "float_type": lambda: f"expected a number, got {got}",
        "int_type": lambda: f"expected an integer, got {got}",
        "string_type": lambda: f"expected a string, got {got}",
        "list_type": lambda: f"expected a list, got {got}",
        "dict_type": lambda: f"expected a JSON object, got {got}",
        "model_type": lambda: f"expected a JSON object, got {got}",
        "model_attributes_type": lambda: f"expected a JSON object, got {got}",
        "literal_error": lambda: f"expected {ctx.get('expected')}, got {got}",
        "too_short": lambda: f"expected at least {ctx.get('min_length')} entries, got {got}",
        "greater_than_equal": lambda: f"must be >= {ctx.get('ge')}, got {got}",
        "less_than": lambda: f"must be < {ctx.get('lt')}, got {got}",
    }
    if kind in messages:
        return messages[kind]()
    return " ".join(str(error.get("msg", kind)).split())


@functools.cache
def _adapter(kind: Any) -> TypeAdapter[Any]:
    return TypeAdapter(kind)


def validate(kind: Any, value: Any, loc: Loc = ()) -> Any:
    """Validate ``value`` (a normalized JSON value) as ``kind`` (a model or a type) with
    pydantic (``hostpc.dataset.schema.validate`` comes here for any value its plain checks
    do not accept).

    Raises:
        FieldError: at the first offending value, located under ``loc``.
    """
    try:
        return _adapter(kind).validate_python(value, strict=True)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        first = errors[0]
        raise FieldError(loc + tuple(first["loc"]), _describe(first)) from None

