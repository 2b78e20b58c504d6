"""Shared building blocks of every protocol message: field types and the base models.

`_Message` (attachments, extra fields refused), `Request` (carries `id`), `Reply` (names
`reply_to`), the protocol version and the constrained field types the message families use.
Units follow docs/conventions.md.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr

PROTOCOL_VERSION = 1
"""Version negotiated by hello; a peer with another version is refused (version_mismatch)."""

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
JointVector = Annotated[list[FiniteFloat], Field(max_length=64)]
"""(n,) joint angles or offsets, radians, joint 1 first."""
RequestId = Annotated[int, Field(ge=0, le=2**53)]
Nonce = Annotated[str, Field(pattern=r"^[0-9a-f]{32,128}$")]
Digest = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]
ShortText = Annotated[str, Field(max_length=200)]
Text = Annotated[str, Field(max_length=4000)]
Bits = Annotated[list[bool], Field(max_length=1024)]
Pattern = Literal["target", "chessboard"]
ImageEncoding = Literal["raw", "png"]


class _Message(BaseModel):
    """Base of every message: unknown fields are refused; attachments ride alongside."""

    model_config = ConfigDict(extra="forbid")
    kind: str
    _attachments: tuple[bytes | memoryview, ...] = PrivateAttr(default=())

    @property
    def attachments(self) -> tuple[bytes | memoryview, ...]:
        """Binary attachments sent in the same frame (empty for most messages)."""
        return self._attachments

    def with_attachments(self, *attachments: bytes | memoryview) -> _Message:
        """Attach binary payloads (not copied); returns self for chaining."""
        self._attachments = tuple(attachments)
        return self

    def expected_attachments(self) -> int:
        """How many attachments a frame carrying this message must have."""
        return 0


class Request(_Message):
    """A client-to-server message that expects exactly one reply naming its `id`."""

    id: RequestId
    read_only: ClassVar[bool] = False
    """True if the request is allowed before auth: a cheap read that neither moves the robot
    nor writes state (`capture` is a read but not cheap, so it needs auth)."""


class Reply(_Message):
    """A server-to-client answer to the request whose id is `reply_to`."""

    reply_to: RequestId


# --- handshake -----------------------------------------------------------------------------
