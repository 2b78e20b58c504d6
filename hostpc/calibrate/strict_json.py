"""Strict reading of a JSON file a decision depends on (FIT.json, a run's result.json).

Nothing in such a file is trusted: the text is refused if ``json`` would bend it (a
duplicated key, whose second value would silently win; a NaN / Infinity literal; an
integer with thousands of digits; nesting without end), and the fields a decision reads are
validated by a pydantic model in strict mode (``StrictFile``: ``"false"`` is not false,
``"0.1"`` is not a number). Either failure is one InputError line naming the file and the
field, ending with the file's remedy (the command that makes a good one).
"""

from __future__ import annotations

import json
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from hostpc.errors import InputError
from hostpc.json_object import JsonObject


class StrictFile(BaseModel):
    """Base of a strict file model: strict types, unknown keys ignored, frozen."""

    model_config = ConfigDict(strict=True, extra="ignore", frozen=True)


Model = TypeVar("Model", bound=StrictFile)


class _Refused(ValueError):
    """A JSON text refused by the parser hooks (duplicated key, non-finite literal)."""


def _no_duplicates(pairs: list[tuple[str, Any]]) -> JsonObject:
    result: JsonObject = {}
    for key, value in pairs:
        if key in result:
            raise _Refused(f"key {key!r} appears twice in one object")
        result[key] = value
    return result


def _no_constant(token: str) -> Any:
    raise _Refused(f"{token} is not a number JSON allows")


def parse_strict_json(text: str, source: str, remedy: str) -> Any:
    """The JSON document of ``text``; InputError for anything `json` would bend."""
    try:
        return json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_no_constant)
    except _Refused as exc:
        raise InputError(f"{source}: {exc}; {remedy}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: "
                         f"{exc.msg}); {remedy}") from None
    except RecursionError:
        raise InputError(f"{source}: not valid JSON (nested too deeply); {remedy}") from None
    except ValueError as exc:  # an integer literal with thousands of digits
        raise InputError(f"{source}: not valid JSON ({exc}); {remedy}") from None


_EXPECTED = {
    "finite_number": "expected a finite number",
    "float_type": "expected a finite number (a JSON number, not a string)",
    "int_type": "expected an integer (a JSON number without a fraction)",
    "bool_type": "expected true or false (a JSON boolean, not a string)",
    "string_type": "expected a string",
    "dict_type": "expected an object",
    "model_type": "expected an object",
    "list_type": "expected a list",
    "missing": "required field missing",
    "too_short": "expected at least one entry",
}
"""How a pydantic error type reads in the one-line message."""


def _field(loc: tuple[int | str, ...]) -> str:
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(top level)"


def validate_strict(model: type[Model], document: Any, source: str, remedy: str) -> Model:
    """``document`` validated by ``model``; InputError naming the first field it refuses."""
    try:
        return model.model_validate(document)
    except ValidationError as exc:
        first = exc.errors()[0]
        value = first.get("input")
        shown = repr(value) if not isinstance(value, dict | list) else type(value).__name__
        why = _EXPECTED.get(first["type"], first["msg"].lower())
        got = "" if first["type"] == "missing" else f", got {shown[:80]}"
        raise InputError(f"{source}: {_field(tuple(first['loc']))}: {why}{got}; "
                         f"{remedy}") from None
