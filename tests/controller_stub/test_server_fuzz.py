"""Fuzz a RUNNING controller stub over real loopback sockets.

The stub runs in a background thread with its own event loop; hypothesis throws random
bytes, truncated frames, huge length prefixes, invalid JSON, wrong field types and unknown
message kinds at it, each on a fresh connection. Every reply must be valid framing carrying
valid messages, the connection must end, and a well-behaved client (a plain blocking socket
driven by `protocol.Connection`) is checked after every example. No hostpc imports.
"""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import struct
import threading
import typing
from collections.abc import Iterator
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from protocol import messages as m
from protocol.connection import Connection
from protocol.framing import MAGIC, FrameDecoder, encode_frame
from protocol.measurement_messages import Capture
from protocol.message_base import Request, _Message
from protocol.session_states import ConnectionState, Role

TOKEN = "fuzz-token"
SCENARIO = {
    "camera": {"image_width": 64, "image_height": 48, "fx": 70.0, "fy": 70.0, "cx": 32, "cy": 24},
    "server": {"token": TOKEN, "max_frame_bytes": 65536},
}


class _ErrorCollector(logging.Handler):
    """Collects ERROR log records (handler crashes, protocol-layer failures)."""

    def __init__(self, sink: list[str]) -> None:
        super().__init__(logging.ERROR)
        self.sink = sink

    def emit(self, record: logging.LogRecord) -> None:
        self.sink.append(record.getMessage())


class ThreadedStub:
    """A ControllerServer on 127.0.0.1:0 served by an event loop in a daemon thread."""

    def __init__(self, scenario: dict[str, Any]) -> None:
        self.loop = asyncio.new_event_loop()
        self.unhandled: list[str] = []
        self.loop.set_exception_handler(lambda _, context: self.unhandled.append(str(context)))
        self._log_handler = _ErrorCollector(self.unhandled)
        logging.getLogger("controller_stub").addHandler(self._log_handler)
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server = ControllerServer.from_scenario(scenario_from_dict(scenario))
        self.address = self.call(self.server.start("127.0.0.1", 0))

    def call(self, coroutine: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout=10)

    def close(self) -> None:
        logging.getLogger("controller_stub").removeHandler(self._log_handler)
        self.call(self.server.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)
        self.loop.close()


class BlockingClient:
    """A well-behaved client: blocking socket + sans-IO Connection."""

    def __init__(self, address: tuple[str, int], token: str | None = TOKEN) -> None:
        self.sock = socket.create_connection(address, timeout=5)
        self.conn = Connection(Role.CLIENT, token=token)
        self.sock.sendall(self.conn.initiate())
        target = ConnectionState.READY if token else ConnectionState.AUTHENTICATING
        while self.conn.state is not target:
            self._pump()

    def _pump(self) -> list[object]:
        data = self.sock.recv(1 << 20)
        if not data:
            raise ConnectionError("server closed the connection")
        events = self.conn.receive_data(data)
        outgoing = self.conn.data_to_send()
        if outgoing:
            self.sock.sendall(outgoing)
        return events

    def request(self, request: Request) -> _Message:
        self.sock.sendall(self.conn.send(request))
        while True:
            for event in self._pump():
                if getattr(event, "reply_to", None) == request.id:
                    return typing.cast(_Message, event)

    def heartbeat(self) -> float:
        reply = self.request(m.Heartbeat(id=self.conn.next_id()))
        assert isinstance(reply, m.HeartbeatReply), reply
        return reply.time

    def close(self) -> None:
        self.sock.close()


@pytest.fixture(scope="module")
def running_stub() -> Iterator[ThreadedStub]:
    stub = ThreadedStub(SCENARIO)
    yield stub
    stub.close()


@pytest.fixture(scope="module")
def good_client(running_stub: ThreadedStub) -> Iterator[BlockingClient]:
    client = BlockingClient(running_stub.address)
    yield client
    client.close()


# ------------------------------------------------------------------------ strategies

ALL_KINDS = sorted(
    cls.model_fields["kind"].default for cls in typing.get_args(typing.get_args(m.Message)[0])
)
FIELD_NAMES = sorted(
    {
        name
        for cls in typing.get_args(typing.get_args(m.Message)[0])
        for name in cls.model_fields
        if name != "kind"
    }
)

json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**64), 2**64)
    | st.floats(allow_nan=False)
    | st.text(max_size=12),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=10,
)

headers = st.builds(
    lambda kind, fields: {"kind": kind, **fields},
    st.sampled_from(ALL_KINDS) | st.text(max_size=12),
    st.dictionaries(st.sampled_from(FIELD_NAMES) | st.text(max_size=8), json_values, max_size=6),
)


def valid_request_frame(kind: str) -> bytes:
    samples = {
        "get_state": m.GetState(id=1),
        "move_joints": m.MoveJoints(id=2, q=[0.0] * 6, speed=0.5),
        "capture": Capture(id=3),
        "set_offsets": m.SetOffsets(id=4, offsets=[0.0] * 6),
    }
    return encode_frame(samples[kind].model_dump_json().encode())


def nested(depth: int, opener: str) -> str:
    closer = "]" if opener == "[" else "}"
    inner = "1" if opener == "[" else ""
    if opener == "{":
        return '{"a":' * depth + "1" + "}" * depth
    return opener * depth + inner + closer * depth


deep_headers = st.tuples(
    st.sampled_from(ALL_KINDS), st.integers(33, 100_000), st.sampled_from(["[", "{"]),
    st.sampled_from(["id", "q", "offsets", "camera", "extra"]),
).map(
    lambda t: (
        "deep nesting",
        encode_frame(f'{{"kind":"{t[0]}","id":1,"{t[3]}":{nested(t[1], t[2])}}}'.encode()),
    )
)

WRONG_TYPES = ["\"2\"", "\"0.1\"", "2.0", "true", "null", "[]", "{}", "\"\""]
wrong_types = st.tuples(
    st.sampled_from(["move_joints", "set_offsets", "guarded_move", "capture", "get_state"]),
    st.sampled_from(["id", "q", "offsets", "speed", "io_line", "view", "q.0", "offsets.0"]),
    st.sampled_from(WRONG_TYPES),
).map(lambda t: ("wrong type", encode_frame(wrong_type_header(*t).encode())))

HUGE = ["1e308", "-1e308", "1e400", "-1e400", "1" + "0" * 400, "5e-324", "-0.0",
        "9007199254740993", "18446744073709551616", "NaN", "Infinity"]
huge_numbers = st.tuples(
    st.sampled_from(["move_joints", "set_offsets", "guarded_move", "capture"]),
    st.sampled_from(["id", "q.0", "offsets.0", "speed", "io_line", "view"]),
    st.sampled_from(HUGE),
).map(lambda t: ("huge number", encode_frame(wrong_type_header(*t).encode())))


def wrong_type_header(kind: str, field: str, value: str) -> str:
    """A valid request of `kind` for a 6-joint robot with `field` (or element 0 of a list
    field, "q.0") replaced by the raw JSON `value`."""
    fields = {"id": "5", "q": "[0.1,0.1,0.1,0.1,0.1,0.1]", "offsets": "[0,0,0,0,0,0]",
              "speed": "0.5", "io_line": "0", "view": "0"}
    wanted = {"move_joints": ["id", "q", "speed"], "set_offsets": ["id", "offsets"],
              "guarded_move": ["id", "q", "speed", "io_line"], "capture": ["id", "view"],
              "get_state": ["id"]}[kind]
    name, _, index = field.partition(".")
    parts = [f'"kind":"{kind}"']
    for key in wanted:
        text = fields[key]
        if key == name:
            text = f"[{value},0,0,0,0,0]" if index else value
        parts.append(f'"{key}":{text}')
    if name not in wanted:
        parts.append(f'"{name}":{value}')
    return "{" + ",".join(parts) + "}"


payloads = st.one_of(
    deep_headers,
    wrong_types,
    huge_numbers,
    st.binary(max_size=600).map(lambda b: ("random bytes", b)),
    st.tuples(
        st.sampled_from(["get_state", "move_joints", "capture", "set_offsets"]),
        st.floats(0.0, 0.999),
    ).map(
        lambda t: (
            "truncated frame",
            valid_request_frame(t[0])[: int(t[1] * len(valid_request_frame(t[0])))],
        )
    ),
    st.tuples(st.integers(0, 2**16 - 1), st.integers(65537, 2**32 - 1), st.binary(max_size=64)).map(
        lambda t: ("huge length prefix", struct.pack(">2sHI", MAGIC, t[0], t[1]) + t[2])
    ),
    st.binary(max_size=200).map(lambda b: ("invalid json", encode_frame(b))),
    headers.map(lambda h: ("fuzzed header", encode_frame(json.dumps(h).encode()))),
    st.tuples(headers, st.lists(st.binary(max_size=64), max_size=3)).map(
        lambda t: ("header with attachments", encode_frame(json.dumps(t[0]).encode(), t[1]))
    ),
)


def open_prelude(address: tuple[str, int], prelude: str) -> socket.socket:
    """A raw socket that has said nothing, said hello, or authenticated."""
    if prelude == "none":
        return socket.create_connection(address, timeout=5)
    client = BlockingClient(address, token=TOKEN if prelude == "authenticated" else None)
    return client.sock


def read_until_closed(sock: socket.socket) -> bytes:
    received = bytearray()
    while True:
        try:
            chunk = sock.recv(1 << 20)
        except ConnectionResetError:
            break
        if not chunk:
            break
        received += chunk
    return bytes(received)


@settings(
    max_examples=100,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    prelude=st.sampled_from(["none", "hello", "authenticated"]),
    attack=st.lists(payloads, min_size=1, max_size=3),
)
def test_fuzzed_clients_get_errors_or_closed_and_others_keep_working(
    running_stub: ThreadedStub,
    good_client: BlockingClient,
    prelude: str,
    attack: list[tuple[str, bytes]],
) -> None:
    sock = open_prelude(running_stub.address, prelude)
    try:
        try:
            for _, payload in attack:
                sock.sendall(payload)
            sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # the server already closed this connection: allowed
        sock.settimeout(5)
        received = read_until_closed(sock)  # must end: the server closes its side
    finally:
        sock.close()
    decoder = FrameDecoder()
    decoder.feed(received)
    while (frame := decoder.next_frame()) is not None:
        message = m.MESSAGE_ADAPTER.validate_json(frame.header)  # replies are valid messages
        assert not isinstance(message, Request)
        assert getattr(message, "code", None) != "internal"  # no handler crashed
    assert decoder.buffered == 0  # no partial frame: every reply was complete
    assert running_stub.unhandled == []  # no session died of an exception, nothing logged
    # the well-behaved client is unaffected
    assert good_client.heartbeat() >= 0.0


def test_huge_length_prefix_gets_an_error_and_the_server_closes(
    running_stub: ThreadedStub, good_client: BlockingClient
) -> None:
    sock = socket.create_connection(running_stub.address, timeout=5)
    try:
        sock.sendall(struct.pack(">2sHI", MAGIC, 0, 2**31))  # never half-closed by us
        received = read_until_closed(sock)
    finally:
        sock.close()
    decoder = FrameDecoder()
    decoder.feed(received)
    frame = decoder.next_frame()
    assert frame is not None
    error = m.MESSAGE_ADAPTER.validate_json(frame.header)
    assert error.kind == "error" and error.code == "frame_too_large"
    assert good_client.heartbeat() >= 0.0


def test_stalled_half_frame_does_not_block_others(
    running_stub: ThreadedStub, good_client: BlockingClient
) -> None:
    stalled = socket.create_connection(running_stub.address, timeout=5)
    try:
        stalled.sendall(encode_frame(b'{"kind": "heartbeat", "id": 1}')[:10])
        fresh = BlockingClient(running_stub.address)
        try:
            assert fresh.heartbeat() >= 0.0
        finally:
            fresh.close()
        assert good_client.heartbeat() >= 0.0
    finally:
        stalled.close()


def exchange(address: tuple[str, int], frame: bytes) -> list[_Message]:
    """Authenticate, send `frame`, then a heartbeat; every message received until its reply."""
    client = BlockingClient(address)
    try:
        client.sock.sendall(frame)
        client.sock.sendall(client.conn.send(m.Heartbeat(id=99)))
        received: list[_Message] = []
        while not any(getattr(e, "reply_to", None) == 99 for e in received):
            received += [e for e in client._pump() if isinstance(e, _Message)]
        return received
    finally:
        client.close()


@pytest.mark.parametrize(
    ("kind", "field", "value"),
    [
        ("get_state", "id", '"2"'),
        ("move_joints", "id", "2.0"),
        ("move_joints", "q.0", '"0.1"'),
        ("move_joints", "speed", '"0.5"'),
        ("move_joints", "speed", "true"),
        ("set_offsets", "offsets.0", '"0.001"'),
        ("set_offsets", "offsets", '"[0,0,0,0,0,0]"'),
        ("guarded_move", "io_line", '"0"'),
        ("guarded_move", "io_line", "0.0"),
        ("capture", "view", "true"),
        ("move_joints", "q.0", "1e400"),
        ("set_offsets", "offsets.0", "1" + "0" * 400),
        ("move_joints", "id", "18446744073709551616"),
    ],
)
def test_wrong_json_types_and_huge_numbers_are_bad_messages(
    running_stub: ThreadedStub, kind: str, field: str, value: str
) -> None:
    """No coercion ("2" is not 2, "0.1" is not 0.1, true is not 1): as docs/protocol.md says."""
    header = wrong_type_header(kind, field, value).encode()
    replies = exchange(running_stub.address, encode_frame(header))
    errors = [r for r in replies if isinstance(r, m.ErrorReply)]
    assert [e.code for e in errors] == ["bad_message"], replies
    assert not any(r.kind in ("move_done", "offsets_set", "state", "capture_done")
                   for r in replies)
    assert running_stub.unhandled == []


@pytest.mark.parametrize("depth", [33, 1000, 30_000])
def test_deep_nesting_is_a_bad_message_not_a_crash(running_stub: ThreadedStub, depth: int) -> None:
    header = f'{{"kind":"get_state","id":7,"x":{nested(depth, "[")}}}'.encode()
    replies = exchange(running_stub.address, encode_frame(header))
    errors = [r for r in replies if isinstance(r, m.ErrorReply)]
    assert [e.code for e in errors] == ["bad_message"] and "nests deeper" in errors[0].message
    assert running_stub.unhandled == []


@pytest.mark.parametrize("speed", [1e-300, 5e-324, 0.0009])
def test_motions_too_slow_to_end_are_refused(running_stub: ThreadedStub, speed: float) -> None:
    """A speed of 1e-300 once overflowed the simulated clock and broke every later reply."""
    request = m.MoveJoints(id=8, q=[0.1] * 6, speed=speed)
    replies = exchange(running_stub.address, encode_frame(request.model_dump_json().encode()))
    (error,) = [r for r in replies if isinstance(r, m.ErrorReply)]
    assert error.code == "refused" and error.reason == "speed"
    assert running_stub.unhandled == []
