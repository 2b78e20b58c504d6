"""Connection: a client and a server wired together in memory, no sockets."""

from __future__ import annotations

import json
import typing
from collections.abc import Callable, Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import messages as m
from protocol.connection import Connection
from protocol.errors import ErrorCode, LocalProtocolError
from protocol.framing import FrameDecoder, encode_frame
from protocol.measurement_messages import (
    Capture,
    CaptureDone,
    ImageInfo,
    MeasureTargets,
    MeasureTracker,
    ReflectorObservation,
    SensorRead,
    SensorReading,
    TargetObservation,
    TargetsMeasured,
    TrackerMeasured,
)
from protocol.message_base import PROTOCOL_VERSION, Request, _Message
from protocol.session_states import (
    ALLOWED_REQUESTS,
    ConnectionClosed,
    ConnectionState,
    Rejected,
    Role,
    StateChanged,
)

TOKEN = "shared-secret"
Q = [0.1, -1.2, 1.3, -0.4, 0.5, 2.6]

Chunker = Callable[[bytes], Iterator[bytes]]


def whole(data: bytes) -> Iterator[bytes]:
    yield data


def byte_by_byte(data: bytes) -> Iterator[bytes]:
    for i in range(len(data)):
        yield data[i : i + 1]


def deliver(data: bytes, receiver: Connection, chunker: Chunker = whole) -> list[object]:
    events: list[object] = []
    for chunk in chunker(data):
        events += receiver.receive_data(chunk)
    return events


def messages_only(events: list[object]) -> list[_Message]:
    return [e for e in events if isinstance(e, _Message)]


def connected_pair(
    client_token: str | None = TOKEN, server_token: str = TOKEN, chunker: Chunker = whole
) -> tuple[Connection, Connection]:
    """Run the handshake; returns (client, server)."""
    client = Connection(Role.CLIENT, token=client_token)
    server = Connection(Role.SERVER, token=server_token, robot_name="ur5e")
    deliver(client.initiate(), server, chunker)
    deliver(server.data_to_send(), client, chunker)
    auth = client.data_to_send()
    if auth:
        deliver(auth, server, chunker)
        deliver(server.data_to_send(), client, chunker)
    return client, server


def request_samples(next_id: Callable[[], int]) -> list[Request]:
    return [
        m.GetState(id=next_id()),
        m.ReadIo(id=next_id()),
        m.MoveJoints(id=next_id(), q=Q, speed=0.25),
        m.GuardedMove(id=next_id(), q=Q, speed=0.1, io_line=3),
        m.Abort(id=next_id()),
        Capture(id=next_id(), pattern="chessboard", view=4, encoding="png"),
        MeasureTargets(id=next_id()),
        MeasureTracker(id=next_id()),
        SensorRead(id=next_id(), sensor="string_pot", request={"what": "length", "average": 4}),
        m.GetOffsets(id=next_id()),
        m.SetOffsets(id=next_id(), offsets=[0.001] * 6),
        m.RollbackOffsets(id=next_id(), rollback_id="rb-7"),
        m.Heartbeat(id=next_id()),
    ]


def reply_for(request: Request) -> _Message:
    i = request.id
    replies: dict[str, _Message] = {
        "get_state": m.State(
            reply_to=i,
            robot_name="ur5e",
            n_joints=6,
            mode="idle",
            time=1.5,
            q=Q,
            zero_offsets=[0.0] * 6,
            q_min=[-6.0] * 6,
            q_max=[6.0] * 6,
            digital_inputs=[True, False],
            digital_outputs=[False, True],
            camera={"image_width": 1280, "nested": {"x": [1, 2]}},
            authenticated=True,
        ),
        "read_io": m.IoState(reply_to=i, digital_inputs=[True], digital_outputs=[False], time=2),
        "move_joints": m.MoveDone(reply_to=i, completed=False, q=Q, duration_s=0.5, reason="x"),
        "guarded_move": m.GuardedMoveDone(
            reply_to=i, contact=True, q_latched=Q, q=Q, io_line=3, duration_s=1.0, speed_mps=0.01
        ),
        "abort": m.Aborted(reply_to=i, was_moving=True),
        "capture": CaptureDone(
            reply_to=i,
            pattern="chessboard",
            view=4,
            q=Q,
            time=3.0,
            images=[
                ImageInfo(camera="left", width=4, height=2, nbytes=8),
                ImageInfo(camera="right", width=4, height=2, nbytes=8),
            ],
        ).with_attachments(bytes(range(8)), bytes(range(8, 16))),
        "measure_targets": TargetsMeasured(
            reply_to=i,
            q=Q,
            time=3.5,
            targets=[
                TargetObservation(
                    chain="left",
                    p=[0.01, -0.02, 0.45],
                    cov=[[1e-9, 0.0, 2e-10], [0.0, 1e-9, 0.0], [2e-10, 0.0, 4e-8]],
                )
            ],
        ),
        "measure_tracker": TrackerMeasured(
            reply_to=i, q=Q, time=3.6, lost=["smr2"],
            reflectors=[ReflectorObservation(name="smr1", p=[2.1, 0.4, 0.3],
                                               cov=[[1e-10, 0, 0], [0, 1e-10, 0], [0, 0, 1e-10]])],
            description={"acceptance_deg": 55.0, "reflectors": {"smr1": [0.0, 0.0, 0.05]}},
        ),
        "sensor_read": SensorReading(reply_to=i, sensor="string_pot", q=Q, time=3.7,
                                       reading={"length": 0.8125, "sigma": 1e-5}),
        "get_offsets": m.Offsets(reply_to=i, offsets=[0.002] * 6),
        "set_offsets": m.OffsetsSet(
            reply_to=i, offsets=[0.001] * 6, previous=[0.0] * 6, rollback_id="rb-1"
        ),
        "rollback_offsets": m.OffsetsRolledBack(
            reply_to=i, offsets=[0.0] * 6, replaced=[0.001] * 6
        ),
        "heartbeat": m.HeartbeatReply(reply_to=i, time=4.0),
    }
    return replies[request.kind]


def all_kinds() -> set[str]:
    union = typing.get_args(m.Message)[0]
    return {cls.model_fields["kind"].default for cls in typing.get_args(union)}


@pytest.mark.parametrize("chunker", [whole, byte_by_byte], ids=["whole", "byte-by-byte"])
def test_handshake_authenticates_both_ends(chunker: Chunker) -> None:
    client, server = connected_pair(chunker=chunker)
    assert client.state is server.state is ConnectionState.READY
    assert client.authenticated and server.authenticated
    assert client.robot_name == "ur5e" and server.peer_name == "zerocal"
    assert client.peer_version == server.peer_version == PROTOCOL_VERSION


@pytest.mark.parametrize("chunker", [whole, byte_by_byte], ids=["whole", "byte-by-byte"])
def test_client_and_server_agree_on_every_message_kind(chunker: Chunker) -> None:
    client, server = connected_pair(chunker=chunker)
    seen: set[str] = {"hello", "hello_reply", "auth", "auth_reply"}
    for request in request_samples(client.next_id):
        received = messages_only(deliver(client.send(request), server, chunker))
        assert received == [request]
        reply = reply_for(request)
        got = messages_only(deliver(server.send(reply), client, chunker))
        assert got == [reply]
        assert [bytes(a) for a in got[0].attachments] == [bytes(a) for a in reply.attachments]
        seen |= {request.kind, reply.kind}
    event = m.IoEdge(line=0, value=True, time=0.25, q_latched=Q)
    assert messages_only(deliver(server.send(event), client, chunker)) == [event]
    request = m.Heartbeat(id=client.next_id())
    server.receive_data(client.send(request))
    error = m.ErrorReply(reply_to=request.id, code="refused", message="no", reason="estop")
    assert messages_only(deliver(server.send(error), client, chunker)) == [error]
    seen |= {"io_edge", "error"}
    assert seen == all_kinds()
    assert client.pending_requests() == {} and server.pending_requests() == {}


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_whole_conversation_in_random_splits(data: st.DataObject) -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(Role.SERVER, token=TOKEN)
    reference_client, reference_server = connected_pair()
    requests = request_samples(reference_client.next_id)

    def split_deliver(stream: bytes, receiver: Connection) -> list[object]:
        cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=12)))
        events: list[object] = []
        for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
            if end > start:  # b"" would mean end of stream
                events += receiver.receive_data(stream[start:end])
        return events

    split_deliver(client.initiate(), server)
    split_deliver(server.data_to_send(), client)
    split_deliver(client.data_to_send(), server)
    split_deliver(server.data_to_send(), client)
    assert client.state is ConnectionState.READY
    stream = b"".join(client.send(r) for r in requests)
    assert messages_only(split_deliver(stream, server)) == requests
    replies = [reply_for(r) for r in requests]
    stream = b"".join(server.send(r) for r in replies)
    assert messages_only(split_deliver(stream, client)) == replies


def test_version_mismatch_is_a_clear_error_on_both_sides() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(Role.SERVER, token=TOKEN)
    hello = json.loads(first_header(client.initiate()))
    hello["protocol_version"] = PROTOCOL_VERSION + 1
    events = server.receive_data(encode_frame(json.dumps(hello).encode()))
    rejected = [e for e in events if isinstance(e, Rejected)]
    assert rejected and rejected[0].code is ErrorCode.VERSION_MISMATCH and rejected[0].fatal
    assert "client speaks protocol version 2, this server speaks version 1" in rejected[0].message
    assert server.state is ConnectionState.CLOSED
    events = client.receive_data(server.data_to_send())
    errors = messages_only(events)
    assert errors[0].kind == "error" and errors[0].code == "version_mismatch"
    assert "protocol version" in errors[0].message
    assert client.state is ConnectionState.CLOSED


def test_client_refuses_a_server_with_another_version() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    hello = json.loads(first_header(client.initiate()))
    reply = m.HelloReply(
        reply_to=hello["id"],
        protocol_version=PROTOCOL_VERSION + 5,
        server_name="future",
        robot_name="ur5e",
        server_nonce="ab" * 16,
    )
    events = client.receive_data(encode_frame(reply.model_dump_json().encode()))
    rejected = [e for e in events if isinstance(e, Rejected)]
    assert rejected[0].code is ErrorCode.VERSION_MISMATCH
    assert "server speaks protocol version 6" in rejected[0].message
    assert client.state is ConnectionState.CLOSED


def first_header(data: bytes) -> bytes:
    decoder = FrameDecoder()
    decoder.feed(data)
    frame = decoder.next_frame()
    assert frame is not None
    return frame.header


def test_wrong_token_is_refused_and_closes() -> None:
    client = Connection(Role.CLIENT, token="wrong")
    server = Connection(Role.SERVER, token=TOKEN)
    server.receive_data(client.initiate())
    client.receive_data(server.data_to_send())
    events = server.receive_data(client.data_to_send())
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.AUTH_FAILED]
    assert server.state is ConnectionState.CLOSED
    reply = messages_only(client.receive_data(server.data_to_send()))
    assert reply[0].code == "auth_failed"
    assert client.state is ConnectionState.CLOSED
    assert b"wrong" not in server.data_to_send()  # nothing further, and no token echoed


def test_token_never_crosses_the_wire() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(Role.SERVER, token=TOKEN)
    wire = client.initiate()
    server.receive_data(wire)
    back = server.data_to_send()
    client.receive_data(back)
    proof = client.data_to_send()
    server.receive_data(proof)
    assert server.state is ConnectionState.READY
    assert TOKEN.encode() not in wire + back + proof + server.data_to_send()


def test_client_detects_a_server_that_does_not_hold_the_token() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(Role.SERVER, token=TOKEN)
    server.receive_data(client.initiate())
    client.receive_data(server.data_to_send())
    server.receive_data(client.data_to_send())
    reply = json.loads(first_header(server.data_to_send()))
    reply["server_proof"] = "0" * 64
    events = client.receive_data(encode_frame(json.dumps(reply).encode()))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.AUTH_FAILED]
    assert client.state is ConnectionState.CLOSED


def test_unauthenticated_session_may_read_but_not_write() -> None:
    client, server = connected_pair(client_token=None)
    assert client.state is server.state is ConnectionState.AUTHENTICATING
    read = m.GetState(id=client.next_id())
    assert messages_only(server.receive_data(client.send(read))) == [read]
    for write in (
        m.MoveJoints(id=client.next_id(), q=Q, speed=0.5),
        m.GuardedMove(id=client.next_id(), q=Q, speed=0.5, io_line=0),
        m.SetOffsets(id=client.next_id(), offsets=Q),
        m.RollbackOffsets(id=client.next_id(), rollback_id="rb-1"),
    ):
        events = server.receive_data(client.send(write))
        assert not messages_only(events)  # the application never sees it
        assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.AUTH_REQUIRED]
        error = messages_only(client.receive_data(server.data_to_send()))[0]
        assert error.code == "auth_required" and error.reply_to == write.id
    assert server.state is ConnectionState.AUTHENTICATING  # refusal is not fatal
    with pytest.raises(LocalProtocolError):
        server.send(m.IoEdge(line=0, value=True, time=0.0, q_latched=Q))  # no events yet


def test_write_requests_need_auth_by_table() -> None:
    unauthenticated = ALLOWED_REQUESTS[ConnectionState.AUTHENTICATING]
    for kind in ("move_joints", "guarded_move", "set_offsets", "rollback_offsets"):
        assert kind not in unauthenticated
        assert kind in ALLOWED_REQUESTS[ConnectionState.READY]


def test_request_before_hello_is_refused() -> None:
    server = Connection(Role.SERVER, token=TOKEN)
    request = m.GetState(id=5)
    events = server.receive_data(encode_frame(request.model_dump_json().encode()))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.UNEXPECTED_MESSAGE]
    error = json.loads(first_header(server.data_to_send()))
    assert error["code"] == "unexpected_message" and error["reply_to"] == 5
    assert "first message must be hello" in error["message"]


@pytest.mark.parametrize(
    ("header", "code", "reply_to"),
    [
        (b"{not json", ErrorCode.BAD_MESSAGE, None),
        (b'{"kind": "teleport", "id": 9}', ErrorCode.UNKNOWN_KIND, 9),
        (b'{"id": 3}', ErrorCode.BAD_MESSAGE, 3),
        (b'{"kind": "move_joints", "id": 4, "q": "up", "speed": 0.5}', ErrorCode.BAD_MESSAGE, 4),
        (b'{"kind": "move_joints", "id": 4, "q": [1.0], "speed": 7}', ErrorCode.BAD_MESSAGE, 4),
        (b'{"kind": "heartbeat", "id": 4, "extra": 1}', ErrorCode.BAD_MESSAGE, 4),
        (b'{"kind": "state", "reply_to": 1}', ErrorCode.BAD_MESSAGE, None),
        (b"[1, 2, 3]", ErrorCode.BAD_MESSAGE, None),
        (b"\xff\xfe", ErrorCode.BAD_MESSAGE, None),
    ],
)
def test_malformed_messages_get_an_error_and_the_session_survives(
    header: bytes, code: ErrorCode, reply_to: int | None
) -> None:
    client, server = connected_pair()
    events = server.receive_data(encode_frame(header))
    rejected = [e for e in events if isinstance(e, Rejected)]
    assert [(r.code, r.reply_to, r.fatal) for r in rejected] == [(code, reply_to, False)]
    error = messages_only(client.receive_data(server.data_to_send()))
    assert error[0].code == code.value and error[0].reply_to == reply_to
    request = m.Heartbeat(id=client.next_id())
    assert messages_only(server.receive_data(client.send(request))) == [request]


def test_oversize_frame_gets_an_error_and_closes() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(Role.SERVER, token=TOKEN, max_frame_size=4096)
    server.receive_data(client.initiate())
    client.receive_data(server.data_to_send())
    events = server.receive_data(encode_frame(b"{}", [b"x" * 5000]))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.FRAME_TOO_LARGE]
    assert StateChanged(ConnectionState.AUTHENTICATING, ConnectionState.CLOSED) in events
    assert server.state is ConnectionState.CLOSED
    error = messages_only(client.receive_data(server.data_to_send()))[0]
    assert error.code == "frame_too_large" and "exceeds the limit of 4096" in error.message
    assert client.state is ConnectionState.CLOSED


def test_pre_auth_frame_limit_is_small_and_grows_after_auth() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    server = Connection(
        Role.SERVER, token=TOKEN, max_frame_size=1 << 20, pre_auth_max_frame_size=2048
    )
    assert server.max_frame_size == 2048
    deliver(client.initiate(), server)
    deliver(server.data_to_send(), client)
    assert server.state is ConnectionState.AUTHENTICATING and server.max_frame_size == 2048
    deliver(client.data_to_send(), server)  # auth
    deliver(server.data_to_send(), client)
    assert server.state is ConnectionState.READY and server.max_frame_size == 1 << 20
    events = server.receive_data(
        encode_frame(b'{"kind": "heartbeat", "id": 9, "x": "' + b"y" * 4000 + b'"}')
    )
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.BAD_MESSAGE]
    assert server.state is ConnectionState.READY  # big frames are fine after auth

    anonymous = Connection(Role.CLIENT, token=None)
    server = Connection(
        Role.SERVER, token=TOKEN, max_frame_size=1 << 20, pre_auth_max_frame_size=2048
    )
    deliver(anonymous.initiate(), server)
    deliver(server.data_to_send(), anonymous)
    events = server.receive_data(encode_frame(b"{}", [b"x" * 3000])[:8])  # the prefix is enough
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.FRAME_TOO_LARGE]
    assert server.state is ConnectionState.CLOSED


def test_capture_needs_an_authenticated_session() -> None:
    client, server = connected_pair(client_token=None)
    events = server.receive_data(client.send(Capture(id=client.next_id())))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.AUTH_REQUIRED]
    assert "capture" not in ALLOWED_REQUESTS[ConnectionState.AUTHENTICATING]


def test_wrong_attachment_count_is_rejected() -> None:
    client, server = connected_pair()
    request = Capture(id=client.next_id())
    server.receive_data(client.send(request))
    reply = reply_for(request)
    header = reply.model_dump_json().encode()
    events = client.receive_data(encode_frame(header, [b"only one"]))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.BAD_MESSAGE]


def test_local_protocol_errors() -> None:
    client = Connection(Role.CLIENT, token=TOKEN)
    with pytest.raises(LocalProtocolError, match="before the hello"):
        client.send(m.GetState(id=1))
    client, server = connected_pair()
    with pytest.raises(LocalProtocolError, match="client cannot send"):
        client.send(m.HeartbeatReply(reply_to=1, time=0.0))
    with pytest.raises(LocalProtocolError, match="server cannot send"):
        server.send(m.Heartbeat(id=1))
    with pytest.raises(LocalProtocolError, match="not pending"):
        server.send(m.HeartbeatReply(reply_to=999, time=0.0))
    request = m.Heartbeat(id=client.next_id())
    server.receive_data(client.send(request))
    with pytest.raises(LocalProtocolError, match="cannot answer heartbeat"):
        server.send(m.Aborted(reply_to=request.id, was_moving=False))
    with pytest.raises(LocalProtocolError, match="already in flight"):
        client.send(m.Heartbeat(id=request.id))
    capture = Capture(id=client.next_id())
    server.receive_data(client.send(capture))
    with pytest.raises(LocalProtocolError, match="attachments"):
        server.send(reply_for(capture).with_attachments())


def test_client_rejects_unsolicited_reply() -> None:
    client, server = connected_pair()
    stray = m.HeartbeatReply(reply_to=12345, time=0.0)
    events = client.receive_data(encode_frame(stray.model_dump_json().encode()))
    assert [e.code for e in events if isinstance(e, Rejected)] == [ErrorCode.UNEXPECTED_MESSAGE]
    assert client.state is ConnectionState.READY


def test_end_of_stream_closes() -> None:
    client, server = connected_pair()
    events = server.receive_data(b"")
    assert isinstance(events[-1], ConnectionClosed)
    assert server.state is ConnectionState.CLOSED
    assert server.receive_data(b"more") == []
    with pytest.raises(LocalProtocolError, match="closed"):
        server.send(m.IoEdge(line=0, value=True, time=0.0, q_latched=Q))
