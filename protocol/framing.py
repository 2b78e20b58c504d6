"""Length-prefixed frames: a JSON header plus zero or more binary attachments.

Byte layout (all integers unsigned, big-endian; docs/protocol.md, "Framing")::

    offset      size   field
    0           2      magic b"ZC"
    2           2      K: number of attachments
    4           4      L: length of everything after this 8-byte prefix
    8           4      H: header length
    12          4*K    attachment lengths A_1..A_K
    12+4K       H      header: one UTF-8 JSON object (the message)
    12+4K+H     sum A  attachments, back to back (raw bytes, e.g. uint8 image rows)

    L = 4 + 4K + H + sum(A_i);  the whole frame is 8 + L bytes.

The receiver checks `8 + L` against its maximum frame size as soon as the 8-byte prefix has
arrived, before buffering the body, so a huge length prefix costs nothing. Attachments are
handed out as `memoryview` slices of one immutable `bytes` object per frame (no copies).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import ErrorCode, LocalProtocolError, RemoteProtocolError

MAGIC = b"ZC"
PREFIX = struct.Struct(">2sHI")  # magic, attachment count, body length
HEADER_LEN = struct.Struct(">I")
PREFIX_SIZE = PREFIX.size  # 8
MAX_ATTACHMENTS = 64
DEFAULT_MAX_FRAME_SIZE = 64 * 1024 * 1024
_U32_MAX = 2**32 - 1

Buffer = bytes | bytearray | memoryview


@dataclass(frozen=True)
class Frame:
    """One decoded frame: the raw JSON header and the attachments (views into one buffer)."""

    header: bytes
    attachments: tuple[memoryview, ...] = ()


def encode_frame_parts(header: bytes, attachments: Sequence[Buffer] = ()) -> list[Buffer]:
    """Encode a frame as a list of buffers for `writelines` (attachments are not copied).

    header: the UTF-8 JSON of the message. attachments: raw byte buffers (C-contiguous).
    Raises LocalProtocolError if the frame cannot be represented (too many attachments or
    more than 4 GiB).
    """
    n_attachments = len(attachments)
    if n_attachments > MAX_ATTACHMENTS:
        raise LocalProtocolError(
            ErrorCode.BAD_FRAME, f"{n_attachments} attachments; at most {MAX_ATTACHMENTS}"
        )
    sizes = [memoryview(a).nbytes for a in attachments]
    body_len = 4 + 4 * n_attachments + len(header) + sum(sizes)
    if body_len > _U32_MAX:
        raise LocalProtocolError(ErrorCode.FRAME_TOO_LARGE, f"frame of {body_len} bytes")
    prefix = PREFIX.pack(MAGIC, n_attachments, body_len) + struct.pack(
        f">I{n_attachments}I", len(header), *sizes
    )
    return [prefix, header, *attachments]


def encode_frame(header: bytes, attachments: Sequence[Buffer] = ()) -> bytes:
    """Encode a frame as one bytes object (one copy of the attachments)."""
    return b"".join(encode_frame_parts(header, attachments))


class FrameDecoder:
    """Incremental frame decoder: feed bytes in any split, take complete frames out.

    After a framing error (bad magic, oversize, inconsistent lengths) the decoder is broken
    for good: a byte stream cannot be resynchronised, so the connection must close.
    """

    def __init__(self, max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> None:
        if max_frame_size < PREFIX_SIZE + 4:
            raise ValueError(f"max_frame_size {max_frame_size} too small")
        self.max_frame_size = max_frame_size
        self._buffer = bytearray()
        self._broken: RemoteProtocolError | None = None

    @property
    def buffered(self) -> int:
        """Bytes received but not yet returned as a frame."""
        return len(self._buffer)

    def feed(self, data: Buffer) -> None:
        """Append received bytes."""
        self._buffer += data

    def next_frame(self) -> Frame | None:
        """Return the next complete frame, or None if more bytes are needed.

        Raises RemoteProtocolError (fatal code) if the stream is not valid framing.
        """
        if self._broken is not None:
            raise self._broken
        try:
            return self._next_frame()
        except RemoteProtocolError as exc:
            self._broken = exc
            self._buffer = bytearray()
            raise

    def _next_frame(self) -> Frame | None:
        buffer = self._buffer
        if len(buffer) >= 2 and buffer[:2] != MAGIC:
            raise RemoteProtocolError(
                ErrorCode.BAD_FRAME, f"bad frame magic {bytes(buffer[:2])!r}, expected {MAGIC!r}"
            )
        if len(buffer) < PREFIX_SIZE:
            return None
        _, n_attachments, body_len = PREFIX.unpack_from(buffer)
        frame_size = PREFIX_SIZE + body_len
        if frame_size > self.max_frame_size:
            raise RemoteProtocolError(
                ErrorCode.FRAME_TOO_LARGE,
                f"frame of {frame_size} bytes exceeds the limit of {self.max_frame_size}",
            )
        if n_attachments > MAX_ATTACHMENTS:
            raise RemoteProtocolError(
                ErrorCode.BAD_FRAME, f"{n_attachments} attachments; at most {MAX_ATTACHMENTS}"
            )
        table_len = 4 + 4 * n_attachments
        if body_len < table_len:
            raise RemoteProtocolError(
                ErrorCode.BAD_FRAME,
                f"body length {body_len} shorter than its length table ({table_len})",
            )
        if len(buffer) < frame_size:
            return None
        lengths = struct.unpack_from(f">I{n_attachments}I", buffer, PREFIX_SIZE)
        header_len, sizes = lengths[0], lengths[1:]
        if table_len + header_len + sum(sizes) != body_len:
            raise RemoteProtocolError(
                ErrorCode.BAD_FRAME,
                f"lengths disagree: header {header_len} + attachments {sum(sizes)} "
                f"+ table {table_len} != body {body_len}",
            )
        with memoryview(buffer) as whole:
            frame = bytes(whole[:frame_size])
        del buffer[:frame_size]
        start = PREFIX_SIZE + table_len
        header = frame[start : start + header_len]
        view = memoryview(frame)
        position = start + header_len
        attachments = []
        for size in sizes:
            attachments.append(view[position : position + size])
            position += size
        return Frame(header=header, attachments=tuple(attachments))
