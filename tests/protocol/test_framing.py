"""Framing: byte layout, incremental decoding in any split, limits, broken streams."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import ErrorCode, LocalProtocolError, RemoteProtocolError
from protocol.framing import MAGIC, MAX_ATTACHMENTS, FrameDecoder, encode_frame


def decode_all(decoder: FrameDecoder) -> list[tuple[bytes, list[bytes]]]:
    frames = []
    while (frame := decoder.next_frame()) is not None:
        frames.append((frame.header, [bytes(a) for a in frame.attachments]))
    return frames


def test_byte_layout_is_as_documented() -> None:
    data = encode_frame(b'{"k":1}', [b"abc", b""])
    magic, count, body_len = struct.unpack_from(">2sHI", data)
    assert (magic, count) == (MAGIC, 2)
    assert body_len == len(data) - 8 == 4 + 4 * 2 + 7 + 3
    assert struct.unpack_from(">III", data, 8) == (7, 3, 0)
    assert data[20:27] == b'{"k":1}' and data[27:] == b"abc"


def test_round_trip_one_byte_at_a_time() -> None:
    frames = [(b'{"a":1}', [b"\x00\x01\x02" * 100, b"x"]), (b"{}", []), (b"[]", [b""])]
    stream = b"".join(encode_frame(h, a) for h, a in frames)
    decoder = FrameDecoder()
    received = []
    for i in range(len(stream)):
        decoder.feed(stream[i : i + 1])
        received += decode_all(decoder)
    assert received == frames
    assert decoder.buffered == 0


frame_strategy = st.tuples(
    st.binary(min_size=0, max_size=64),
    st.lists(st.binary(min_size=0, max_size=300), max_size=4),
)


@settings(max_examples=100, deadline=None)
@given(frames=st.lists(frame_strategy, min_size=1, max_size=6), data=st.data())
def test_round_trip_in_random_splits(
    frames: list[tuple[bytes, list[bytes]]], data: st.DataObject
) -> None:
    stream = b"".join(encode_frame(h, a) for h, a in frames)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    decoder = FrameDecoder()
    received = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        decoder.feed(stream[start:end])
        received += decode_all(decoder)
    assert received == frames


def test_attachments_are_views_not_copies() -> None:
    decoder = FrameDecoder()
    decoder.feed(encode_frame(b"{}", [b"a" * 1000, b"b" * 10]))
    frame = decoder.next_frame()
    assert frame is not None
    assert all(isinstance(a, memoryview) for a in frame.attachments)
    assert frame.attachments[0].obj is frame.attachments[1].obj  # one buffer for the frame


def test_oversize_frame_rejected_from_its_prefix_alone() -> None:
    decoder = FrameDecoder(max_frame_size=1024)
    decoder.feed(struct.pack(">2sHI", MAGIC, 0, 10**9))  # no body sent at all
    with pytest.raises(RemoteProtocolError) as exc:
        decoder.next_frame()
    assert exc.value.code is ErrorCode.FRAME_TOO_LARGE and exc.value.fatal
    assert "exceeds the limit of 1024" in str(exc.value)
    decoder.feed(encode_frame(b"{}"))
    with pytest.raises(RemoteProtocolError):  # broken for good: cannot resynchronise
        decoder.next_frame()


def test_frame_at_the_limit_is_accepted() -> None:
    data = encode_frame(b"{}", [b"x" * 100])
    decoder = FrameDecoder(max_frame_size=len(data))
    decoder.feed(data)
    assert decoder.next_frame() is not None
    decoder = FrameDecoder(max_frame_size=len(data) - 1)
    decoder.feed(data)
    with pytest.raises(RemoteProtocolError):
        decoder.next_frame()


@pytest.mark.parametrize(
    ("stream", "message"),
    [
        (b"GET / HTTP/1.1\r\n", "bad frame magic"),
        (struct.pack(">2sHI", MAGIC, MAX_ATTACHMENTS + 1, 4 + 4 * 65), "attachments"),
        (struct.pack(">2sHI", MAGIC, 3, 4), "shorter than its length table"),
        (struct.pack(">2sHII", MAGIC, 0, 4 + 5, 2) + b"{}xyz", "lengths disagree"),
    ],
)
def test_broken_framing_is_a_fatal_remote_error(stream: bytes, message: str) -> None:
    decoder = FrameDecoder()
    decoder.feed(stream)
    with pytest.raises(RemoteProtocolError, match=message) as exc:
        decoder.next_frame()
    assert exc.value.fatal


def test_too_many_attachments_is_a_local_error() -> None:
    with pytest.raises(LocalProtocolError):
        encode_frame(b"{}", [b""] * (MAX_ATTACHMENTS + 1))
