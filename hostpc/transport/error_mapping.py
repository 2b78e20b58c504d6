"""How controller errors become `hostpc.errors` exceptions in the transport.

An error reply with a protocol-level code (bad frame/message, unknown kind, unexpected
message, version mismatch) is a `ProtocolViolation`; any other code (refused, auth, ...) is a
`ControllerRefusedError` carrying code and reason. `_os_error_text` words a socket failure.
"""

from __future__ import annotations

import os
import socket

from hostpc.errors import ProtocolViolation
from hostpc.transport.types import ControllerRefusedError
from protocol import messages as m
from protocol.errors import ErrorCode

_PROTOCOL_CODES = frozenset(
    {
        ErrorCode.BAD_FRAME,
        ErrorCode.FRAME_TOO_LARGE,
        ErrorCode.BAD_MESSAGE,
        ErrorCode.UNKNOWN_KIND,
        ErrorCode.UNEXPECTED_MESSAGE,
        ErrorCode.VERSION_MISMATCH,
    }
)


def _handshake_error(error: m.ErrorReply) -> Exception:
    text = f"controller refused the session: {error.message} ({error.code})"
    if error.code in _PROTOCOL_CODES:
        return ProtocolViolation(text)
    return ControllerRefusedError(text, error.code, error.reason)


def _os_error_text(exc: OSError) -> str:
    """A readable cause: "Connection refused", "Name or service not known" (a DNS failure's
    errno is a negative EAI_* code that os.strerror does not know)."""
    if isinstance(exc, socket.gaierror):
        return f"cannot resolve the host name ({exc.strerror or exc})"
    if exc.errno and exc.errno > 0:
        return os.strerror(exc.errno)
    return str(exc) or type(exc).__name__


def _reply_error(kind: str, error: m.ErrorReply) -> Exception:
    reason = f", reason {error.reason}" if error.reason else ""
    text = f"controller rejected {kind}: {error.message} (code {error.code}{reason})"
    if error.code in _PROTOCOL_CODES:
        return ProtocolViolation(text)
    return ControllerRefusedError(text, error.code, error.reason)
