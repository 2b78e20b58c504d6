"""Where a ``zerocal-dataset/1`` document breaks the format, in one line: a field path
(``samples[3].cov``) and a message. Apart from ``hostpc.dataset.schema`` so that the
pydantic models (``schema_models``) and the plain checks share it without a cycle."""

from __future__ import annotations

import json
import re
from typing import Any

Loc = tuple[str | int, ...]
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class FieldError(Exception):
    """A value of the document breaks the format; ``loc`` says where, ``message`` what."""

    def __init__(self, loc: Loc, message: str) -> None:
        super().__init__(format_error(loc, message))
        self.loc = loc
        self.message = message


def format_loc(loc: Loc) -> str:
    """``("samples", 3, "p", 1)`` -> ``"samples[3].p[1]"``."""
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        elif not _NAME.fullmatch(part):
            text += f"[{show(part)}]"
        else:
            text += f".{part}" if text else part
    return text


def format_error(loc: Loc, message: str) -> str:
    """One line: ``"<field path>: <message>"`` (just the message at the top level)."""
    return f"{format_loc(loc)}: {message}" if loc else message


def show(value: Any, limit: int = 40) -> str:
    """A short JSON-like rendering of an offending value for an error message."""
    if isinstance(value, str):
        text = repr(value)
        return text if len(text) <= limit else text[: limit - 4] + "...'"
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    text = text.replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."
