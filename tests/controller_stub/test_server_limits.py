"""The server's limits against slow, stalled, greedy or numerous clients (real sockets on
127.0.0.1, short limits from the scenario), and that a well-behaved client keeps working."""

from __future__ import annotations

import asyncio
import struct
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.network.session import (
    PRE_AUTH_MAX_FRAME_SIZE,
    SESSION_READ_CHUNK,
    WRITE_HIGH_WATER,
)
from controller_stub.scenario.spec import scenario_from_dict
from protocol import messages as m
from protocol.connection import Connection
from protocol.framing import MAGIC, FrameDecoder, encode_frame
from protocol.session_states import ConnectionState, Role
from tests.controller_stub.test_server import SCENARIO, TOKEN, RawClient

StartServer = Callable[..., Awaitable[ControllerServer]]


@pytest.fixture
async def start_server() -> AsyncIterator[StartServer]:
    """Factory: `await start_server(**server_overrides)`; closed at teardown."""
    servers: list[ControllerServer] = []

    async def _start(**server: Any) -> ControllerServer:
        scenario = scenario_from_dict({**SCENARIO, "server": {"token": TOKEN, **server}})
        instance = ControllerServer.from_scenario(scenario)
        await instance.start("127.0.0.1", 0)
        servers.append(instance)
        return instance

    yield _start
    for instance in servers:
        await instance.close()


async def closed_within(reader: asyncio.StreamReader, seconds: float) -> tuple[bytes, float]:
    """Read until the server closes (bytes received, seconds it took); fails after `seconds`."""
    started = time.monotonic()
    received = bytearray()
    async with asyncio.timeout(seconds):
        while chunk := await reader.read(1 << 16):
            received += chunk
    return bytes(received), time.monotonic() - started


def errors_in(data: bytes) -> list[str]:
    decoder = FrameDecoder()
    decoder.feed(data)
    codes = []
    while (frame := decoder.next_frame()) is not None:
        codes.append(m.MESSAGE_ADAPTER.validate_json(frame.header).code)
    return codes


async def assert_well_behaved_client_works(server: ControllerServer) -> None:
    good = await RawClient.open(server)
    try:
        reply = await good.request(m.Heartbeat(id=good.conn.next_id()))
        assert reply.kind == "heartbeat_reply"
    finally:
        await good.close()


async def hello_only(server: ControllerServer) -> RawClient:
    """A connected client that said hello but holds no token (read-only session)."""
    reader, writer = await asyncio.open_connection(*server.address)
    client = RawClient(reader, writer)
    client.conn = Connection(Role.CLIENT, token=None)
    writer.write(client.conn.initiate())
    while client.conn.state is not ConnectionState.AUTHENTICATING:
        await client.pump()
    return client


async def test_a_client_that_never_says_hello_is_closed(start_server: StartServer) -> None:
    server = await start_server(handshake_timeout_s=0.3)
    reader, writer = await asyncio.open_connection(*server.address)
    try:
        received, took = await closed_within(reader, 3.0)
        assert received == b"" and 0.25 < took
        await assert_well_behaved_client_works(server)
    finally:
        writer.close()


async def test_an_unauthenticated_session_is_closed_at_the_deadline_despite_heartbeats(
    start_server: StartServer,
) -> None:
    server = await start_server(handshake_timeout_s=0.5)
    client = await hello_only(server)
    try:
        started = time.monotonic()
        replies = 0
        while not client.conn.closed and time.monotonic() - started < 2.0:
            client.writer.write(client.conn.send(m.Heartbeat(id=client.conn.next_id())))
            replies += sum(e.kind == "heartbeat_reply" for e in await client.pump()
                           if isinstance(e, m.HeartbeatReply))
            await asyncio.sleep(0.05)
        assert client.conn.closed and replies >= 3  # heartbeats answered, then closed
        assert 0.4 < time.monotonic() - started < 1.5
        await assert_well_behaved_client_works(server)  # authenticated in time: served
    finally:
        await client.close()


@pytest.mark.parametrize("prelude", ["nothing", "authenticated"])
async def test_a_declared_length_that_never_completes_is_closed_after_the_deadline(
    start_server: StartServer, prelude: str
) -> None:
    server = await start_server(handshake_timeout_s=0.3)  # idle timeout stays 300 s
    if prelude == "nothing":
        reader, writer = await asyncio.open_connection(*server.address)
    else:
        client = await (
            RawClient.open(server) if prelude == "authenticated" else hello_only(server)
        )
        reader, writer = client.reader, client.writer
    try:
        await asyncio.sleep(0.4)  # past the auth deadline: an authenticated session stays open
        frame = encode_frame(m.Heartbeat(id=77).model_dump_json().encode())
        writer.write(frame[:12])  # the prefix declares the whole frame; the rest never comes
        received, took = await closed_within(reader, 3.0)
        assert received == b"" and took < 2.0
        if prelude != "nothing":
            assert took > 0.25  # the frame deadline, not the hello deadline, closed it
        await assert_well_behaved_client_works(server)
    finally:
        writer.close()


async def test_frames_before_auth_are_capped_at_64_kib(start_server: StartServer) -> None:
    server = await start_server()  # max_frame_bytes stays 64 MiB for authenticated sessions
    for opener in (None, hello_only):
        if opener is None:
            reader, writer = await asyncio.open_connection(*server.address)
        else:
            client = await opener(server)
            reader, writer = client.reader, client.writer
        try:
            writer.write(struct.pack(">2sHI", MAGIC, 0, PRE_AUTH_MAX_FRAME_SIZE))  # 8 bytes over
            received, _ = await closed_within(reader, 3.0)  # at once: no waiting for the body
            assert errors_in(received) == ["frame_too_large"]
        finally:
            writer.close()
    await assert_well_behaved_client_works(server)


async def test_idle_sessions_are_closed_and_heartbeats_keep_them_alive(
    start_server: StartServer,
) -> None:
    server = await start_server(idle_timeout_s=0.4)
    client = await RawClient.open(server)
    try:
        for _ in range(6):  # 1.2 s in all, three times the idle timeout
            await asyncio.sleep(0.2)
            reply = await client.request(m.Heartbeat(id=client.conn.next_id()))
            assert reply.kind == "heartbeat_reply"
        received, took = await closed_within(client.reader, 3.0)
        assert received == b"" and 0.3 < took < 2.0
        assert server.session_count == 0
    finally:
        await client.close()


async def test_waiting_for_an_own_request_is_not_idleness(start_server: StartServer) -> None:
    scenario = scenario_from_dict(
        {
            **SCENARIO,
            "server": {"token": TOKEN, "idle_timeout_s": 0.3},
            "motion": {"time_scale": 1.0, "max_joint_speed": 1.0},
        }
    )
    server = ControllerServer.from_scenario(scenario)
    await server.start("127.0.0.1", 0)
    client = await RawClient.open(server)
    try:
        q = [float(v) + 0.8 for v in server.sim.joint_positions()]  # 0.8 s of motion
        reply = await client.request(m.MoveJoints(id=client.conn.next_id(), q=q, speed=1.0))
        assert reply.kind == "move_done" and reply.completed
    finally:
        await client.close()
        await server.close()


async def test_session_limit_refuses_with_an_error_and_recovers(start_server: StartServer) -> None:
    server = await start_server(max_sessions=3)
    clients = [await RawClient.open(server) for _ in range(3)]
    try:
        reader, writer = await asyncio.open_connection(*server.address)
        writer.write(Connection(Role.CLIENT, token=TOKEN).initiate())
        received, _ = await closed_within(reader, 3.0)
        writer.close()
        assert errors_in(received) == ["busy"]
        assert b"too many sessions" in received and server.sessions_refused == 1
        for client in clients:  # the sessions that got in are unaffected
            assert (await client.request(m.Heartbeat(id=client.conn.next_id()))).kind == (
                "heartbeat_reply"
            )
        await clients.pop().close()
        for _ in range(100):
            if server.session_count < 3:
                break
            await asyncio.sleep(0.01)
        await assert_well_behaved_client_works(server)  # a slot is free again
    finally:
        for client in clients:
            await client.close()


async def test_a_client_that_never_reads_cannot_grow_server_memory(
    start_server: StartServer,
) -> None:
    server = await start_server()
    greedy = await RawClient.open(server)
    n_requests = 30_000  # ~40 MB of state replies if they were all produced
    greedy.writer.write(
        b"".join(greedy.conn.send(m.GetState(id=greedy.conn.next_id())) for _ in range(n_requests))
    )
    try:
        seen, stable_since = -1, time.monotonic()
        while time.monotonic() - stable_since < 0.3:  # until the server stops making progress
            await asyncio.sleep(0.05)
            if server.requests_seen != seen:
                seen, stable_since = server.requests_seen, time.monotonic()
        (session,) = [s for s in server._sessions if s.peer.endswith(str(greedy_port(greedy)))]
        assert server.requests_seen < n_requests // 2  # it stopped reading
        assert len(session._tasks) <= server.max_requests_in_flight
        assert session.conn.buffered <= SESSION_READ_CHUNK
        assert session.writer.transport.get_write_buffer_size() <= WRITE_HIGH_WATER + 64 * 1024
        await assert_well_behaved_client_works(server)  # nobody else notices
    finally:
        greedy.writer.transport.abort()
    for _ in range(200):
        if server.session_count == 0:
            break
        await asyncio.sleep(0.01)
    assert server.session_count == 0


def greedy_port(client: RawClient) -> int:
    return int(client.writer.get_extra_info("sockname")[1])
