"""Reading received headers: JSON depth guard, validation, error-code mapping, id recovery.

`parse_frame` turns a received frame into a message or raises `RemoteProtocolError` with the
code the peer is answered with; `_find_id` recovers the request id of an unreadable header so
the error reply can name it. Stdlib + pydantic only (sans-IO).
"""

from __future__ import annotations

import json
import re
from typing import Any

from pydantic import ValidationError

from protocol.errors import ErrorCode, RemoteProtocolError
from protocol.framing import Frame
from protocol.message_base import _Message
from protocol.messages import MESSAGE_ADAPTER

MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays/objects accepted in a header (the protocol's messages nest at
most a few levels); deeper headers are answered with `bad_message` before any JSON parser
recurses into them."""


def parse_frame(frame: Frame) -> _Message:
    """Validate one received frame as a message (strict JSON types, depth and attachment
    count checked); raise RemoteProtocolError with the matching code otherwise."""
    depth = json_nesting_depth(frame.header, MAX_JSON_DEPTH)
    if depth > MAX_JSON_DEPTH:
        raise RemoteProtocolError(
            ErrorCode.BAD_MESSAGE,
            f"header nests deeper than {MAX_JSON_DEPTH} levels of arrays/objects",
        )
    try:
        # strict: the wire's JSON types are the schema's (no "2" for 2, no "0.1" for 0.1)
        message: _Message = MESSAGE_ADAPTER.validate_json(frame.header, strict=True)
    except ValidationError as exc:
        raise _validation_error(exc) from None
    if len(frame.attachments) != message.expected_attachments():
        raise RemoteProtocolError(
            ErrorCode.BAD_MESSAGE,
            f"{message.kind} needs {message.expected_attachments()} attachments, "
            f"frame has {len(frame.attachments)}",
        )
    if frame.attachments:
        message.with_attachments(*frame.attachments)
    return message


def _validation_error(exc: ValidationError) -> RemoteProtocolError:
    """Map a pydantic failure on a received header to a protocol error code."""
    error = exc.errors(include_url=False)[0]
    if error["type"] == "union_tag_invalid":
        kind = (error.get("ctx") or {}).get("tag", "?")
        return RemoteProtocolError(ErrorCode.UNKNOWN_KIND, f"unknown message kind {kind!r}")
    if error["type"] in ("json_invalid", "json_type"):
        return RemoteProtocolError(
            ErrorCode.BAD_MESSAGE, f"header is not valid JSON: {error['msg']}"
        )
    location = ".".join(str(part) for part in error["loc"][1:]) or "<header>"
    return RemoteProtocolError(ErrorCode.BAD_MESSAGE, f"{location}: {error['msg']}")


_JSON_STRUCTURE = re.compile(rb'"(?:[^"\\]|\\.)*"|[\[\]{}]', re.DOTALL)
"""A JSON string (skipped: brackets inside it do not count) or a bracket."""


def json_nesting_depth(text: bytes, stop_above: int | None = None) -> int:
    """Deepest nesting of arrays/objects in JSON `text` (no parsing, no recursion; a scan
    that stops as soon as the depth exceeds `stop_above`)."""
    depth = deepest = 0
    for match in _JSON_STRUCTURE.finditer(text):
        token = match.group()
        if token in (b"[", b"{"):
            depth += 1
            if depth > deepest:
                deepest = depth
                if stop_above is not None and deepest > stop_above:
                    break
        elif token in (b"]", b"}"):
            depth -= 1
    return deepest


def _find_id(header: bytes) -> int | None:
    """Best effort: the request id of an unparseable message, so the error can name it."""
    if json_nesting_depth(header, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        return None
    try:
        document: Any = json.loads(header)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    if isinstance(document, dict):
        value = document.get("id")
        if type(value) is int and 0 <= value <= 2**53:
            return value
    return None
