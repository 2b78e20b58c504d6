"""The session state table and the events a `Connection` reports.

States and roles, which message moves the session to which state (`TRANSITIONS`), which
requests a server executes in each state (`ALLOWED_REQUESTS`) and how it refuses the rest
(`REFUSAL_CODE`), plus the non-message events (`StateChanged`, `Rejected`,
`ConnectionClosed`). States (docs/protocol.md, "State machine")::

    AWAITING_HELLO --hello_reply--> AUTHENTICATING --auth_reply--> READY
          |                               |                          |
          +------ fatal error / end of stream (any state) -----------+--> CLOSED
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from protocol.errors import ErrorCode
from protocol.message_base import _Message
from protocol.messages import READ_ONLY_KINDS, REQUEST_TYPES


class Role(StrEnum):
    """Which end of the connection this object is."""

    CLIENT = "client"
    SERVER = "server"


class ConnectionState(StrEnum):
    """Session state, the same on both ends once each has seen the same messages."""

    AWAITING_HELLO = "awaiting_hello"
    AUTHENTICATING = "authenticating"
    READY = "ready"
    CLOSED = "closed"


S = ConnectionState

TRANSITIONS: dict[tuple[ConnectionState, str], ConnectionState] = {
    (S.AWAITING_HELLO, "hello_reply"): S.AUTHENTICATING,
    (S.AUTHENTICATING, "auth_reply"): S.READY,
}
"""(state, kind of the message passing) -> next state. The server applies it when it sends
the message, the client when it receives it. Fatal errors and end of stream go to CLOSED."""

ALLOWED_REQUESTS: dict[ConnectionState, frozenset[str]] = {
    S.AWAITING_HELLO: frozenset({"hello"}),
    S.AUTHENTICATING: READ_ONLY_KINDS | {"auth"},
    S.READY: frozenset(REQUEST_TYPES) - {"hello", "auth"},
    S.CLOSED: frozenset(),
}
"""Requests the server executes in each state (it refuses the rest with an error code)."""

REFUSAL_CODE: dict[ConnectionState, ErrorCode] = {
    S.AWAITING_HELLO: ErrorCode.UNEXPECTED_MESSAGE,
    S.AUTHENTICATING: ErrorCode.AUTH_REQUIRED,
    S.READY: ErrorCode.UNEXPECTED_MESSAGE,
}
"""The code of the error reply to a request that is not allowed in a state (except that a
repeated hello or auth is always `unexpected_message`)."""


@dataclass(frozen=True)
class StateChanged:
    """Event: the session moved from `old` to `new` (e.g. authenticated, closed)."""

    old: ConnectionState
    new: ConnectionState


@dataclass(frozen=True)
class Rejected:
    """Event: the peer sent something invalid. A server has queued an error reply for it.

    fatal: the connection is now CLOSED (flush `data_to_send()`, then close the socket).
    """

    code: ErrorCode
    message: str
    reply_to: int | None
    fatal: bool


@dataclass(frozen=True)
class ConnectionClosed:
    """Event: the peer ended the stream."""


Event = _Message | StateChanged | Rejected | ConnectionClosed


def refusal_text(kind: str, state: ConnectionState, code: ErrorCode) -> str:
    if code is ErrorCode.AUTH_REQUIRED:
        return f"{kind} needs an authenticated session (send auth with the shared token)"
    if state is S.AWAITING_HELLO:
        return f"{kind} before hello: the first message must be hello"
    return f"{kind} is not allowed in state {state}"
