"""The one name for raw JSON at a boundary.

zerocal's shell passes typed values (frozen dataclasses, pydantic models). A JSON object
exists only where a document is read or written: a file face parsing a dataset, the journal
reading a line, result.json being emitted. Those boundary functions, and only those, take or
return a ``JsonObject``; everything past the boundary is typed. ``grep JsonObject`` therefore
lists the boundaries, and ``grep "dict\\[str, Any\\]"`` should find almost nothing.
"""
from __future__ import annotations

import json
import sys
from json.encoder import encode_basestring_ascii as _string
from typing import Any

JsonObject = dict[str, Any]
"""A parsed JSON object (``json.loads`` of an object) or one about to be dumped."""


def dumps_indented(value: object) -> str:
    """``json.dumps(value, indent=2, allow_nan=False)``, character for character, without the
    standard library's pure-Python encoder (the one ``indent`` selects): that one passes each
    of a document's ~10^4 pieces up through a generator per nesting level; this one appends
    every piece once. Strings are escaped by the standard library's own function (C),
    numbers written by ``repr`` as json writes them. Anything it does not write itself (a
    non-string key, a non-finite float, a type JSON lacks, a cycle) is handed to
    ``json.dumps``, so every error is json's."""
    parts: list[str] = []
    try:
        _encode(value, parts, "\n")
    except (_NotPlain, RecursionError):
        return json.dumps(value, indent=2, allow_nan=False)
    return "".join(parts)


class _NotPlain(Exception):
    """A value ``dumps_indented`` leaves to ``json.dumps``."""


def _encode(value: object, parts: list[str], newline: str) -> None:
    """Append the pieces of ``value`` (nested at the indentation ``newline`` ends with);
    the tests of json's ``_make_iterencode``, in its order."""
    if isinstance(value, str):
        parts.append(_string(value))
    elif value is None:
        parts.append("null")
    elif value is True:
        parts.append("true")
    elif value is False:
        parts.append("false")
    elif isinstance(value, int):
        parts.append(int.__repr__(value))
    elif isinstance(value, float):
        if not _FINITE_LOW <= value <= _FINITE_HIGH:  # NaN and the infinities
            raise _NotPlain
        parts.append(float.__repr__(value))
    elif isinstance(value, list | tuple | dict):
        _encode_container(value, parts, newline)
    else:
        raise _NotPlain


def _encode_container(value: list[object] | tuple[object, ...] | dict[object, object],
                      parts: list[str], newline: str) -> None:
    if not value:
        parts.append("{}" if isinstance(value, dict) else "[]")
        return
    inner = newline + "  "
    separator = inner  # before the first item, then "," + inner
    if isinstance(value, dict):
        parts.append("{")
        for key, item in value.items():
            if not isinstance(key, str):  # json converts other keys: left to it
                raise _NotPlain
            parts.append(separator)
            parts.append(_string(key))
            parts.append(": ")
            _encode(item, parts, inner)
            separator = "," + inner
        parts.append(newline + "}")
        return
    parts.append("[")
    for item in value:
        parts.append(separator)
        if type(item) is float and _FINITE_LOW <= item <= _FINITE_HIGH:
            parts.append(float.__repr__(item))
        else:
            _encode(item, parts, inner)
        separator = "," + inner
    parts.append(newline + "]")


_FINITE_HIGH = sys.float_info.max
_FINITE_LOW = -_FINITE_HIGH
