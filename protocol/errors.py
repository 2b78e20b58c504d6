"""Protocol errors and the error codes carried by `ErrorReply`.

Two exception classes, split by who broke the protocol (as h11 does):

- `LocalProtocolError`: *we* tried to do something the protocol forbids (send a request
  before the hello, send after close, send a server-only message from a client).
- `RemoteProtocolError`: the *peer* sent something the protocol forbids (bad frame, invalid
  JSON, unknown message kind, a reply to a request we never sent).

Both carry an `ErrorCode` so a server can turn them into an error reply without guessing.
"""

from __future__ import annotations

from enum import StrEnum


class ErrorCode(StrEnum):
    """Machine-readable error codes of `ErrorReply.code` (docs/protocol.md, "Error codes").

    Framing and message errors come from the protocol layer; the rest from the controller.
    Codes in `FATAL_CODES` close the connection after the error reply is sent.
    """

    BAD_FRAME = "bad_frame"  # framing broken (magic, inconsistent lengths): fatal
    FRAME_TOO_LARGE = "frame_too_large"  # length prefix beyond the receiver's limit: fatal
    BAD_MESSAGE = "bad_message"  # frame fine, header not valid JSON or fields invalid
    UNKNOWN_KIND = "unknown_kind"  # header names a message kind this peer does not know
    UNEXPECTED_MESSAGE = "unexpected_message"  # valid message, wrong state or direction
    VERSION_MISMATCH = "version_mismatch"  # hello with an unsupported protocol version: fatal
    AUTH_REQUIRED = "auth_required"  # request needs an authenticated session
    AUTH_FAILED = "auth_failed"  # wrong proof (wrong token): fatal
    REFUSED = "refused"  # controller refuses (reason: joint_limit, offset_limit, estop, ...)
    BUSY = "busy"  # another motion is in progress
    UNKNOWN_ROLLBACK = "unknown_rollback"  # rollback id not known to the controller
    INTERNAL = "internal"  # the controller failed while handling the request


FATAL_CODES: frozenset[ErrorCode] = frozenset(
    {
        ErrorCode.BAD_FRAME,
        ErrorCode.FRAME_TOO_LARGE,
        ErrorCode.VERSION_MISMATCH,
        ErrorCode.AUTH_FAILED,
    }
)


class ProtocolError(Exception):
    """Base class: the protocol was broken; `code` says how."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code

    @property
    def fatal(self) -> bool:
        """True if the connection cannot continue after this error."""
        return self.code in FATAL_CODES


class LocalProtocolError(ProtocolError):
    """We tried to do something the protocol forbids (a bug in the caller)."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol forbids."""
