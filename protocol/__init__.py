"""zerocal wire protocol, sans-IO: messages, framing, the Connection state machine, auth.

Imports only the standard library and pydantic; no sockets, no asyncio. See
docs/protocol.md for the message table, the byte layout and the error codes.
"""

from protocol.connection import (
    Connection,
    ConnectionClosed,
    ConnectionState,
    Event,
    Rejected,
    Role,
    StateChanged,
)
from protocol.errors import (
    FATAL_CODES,
    ErrorCode,
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
)
from protocol.framing import DEFAULT_MAX_FRAME_SIZE, Frame, FrameDecoder, encode_frame
from protocol.messages import PROTOCOL_VERSION, Message

DEFAULT_PORT = 47800
"""TCP port of the zerocal protocol when none is given (controller-stub, hostpc --robot)."""

__all__ = [
    "DEFAULT_MAX_FRAME_SIZE",
    "DEFAULT_PORT",
    "FATAL_CODES",
    "PROTOCOL_VERSION",
    "Connection",
    "ConnectionClosed",
    "ConnectionState",
    "ErrorCode",
    "Event",
    "Frame",
    "FrameDecoder",
    "LocalProtocolError",
    "Message",
    "ProtocolError",
    "Rejected",
    "RemoteProtocolError",
    "Role",
    "StateChanged",
    "encode_frame",
]
