"""Admission against hostile peers: eviction of unauthenticated sessions, the per-address
auth throttle (pure, with explicit times), and the server applying both on real sockets."""

from __future__ import annotations

import asyncio

import pytest

from controller_stub.network.server import ControllerServer
from protocol import messages as m
from protocol.admission import AuthThrottle, SessionSlots
from protocol.connection import Connection
from protocol.session_states import ConnectionState, Role
from tests.controller_stub.test_server import RawClient
from tests.controller_stub.test_server_limits import (
    StartServer,
    closed_within,
    errors_in,
    hello_only,
    start_server,
)

__all__ = ["start_server"]  # the fixture


def test_a_newcomer_evicts_the_oldest_unauthenticated_session() -> None:
    slots: SessionSlots[str] = SessionSlots(max_sessions=4, max_unauthenticated=2)
    assert slots.admit("a") == (True, [])
    slots.authenticated("a")
    assert slots.admit("b") == (True, [])
    assert slots.admit("c") == (True, [])
    assert slots.admit("d") == (True, ["b"])  # unauthenticated cap (2) reached
    slots.authenticated("c")
    assert slots.admit("e") == (True, [])
    assert slots.admit("f") == (True, ["d"])  # all 4 slots taken: oldest anonymous goes
    slots.authenticated("e")
    slots.authenticated("f")
    assert slots.admit("g") == (False, [])  # every slot authenticated: refused
    assert sorted(slots) == ["a", "c", "e", "f"] and slots.unauthenticated == 0


def test_eviction_takes_the_crowding_address_and_loiterers_first() -> None:
    slots: SessionSlots[str] = SessionSlots(max_sessions=10, max_unauthenticated=3)
    slots.admit("operator", "10.0.0.5")
    slots.admit("bot1", "10.0.0.9")
    slots.admit("bot2", "10.0.0.9")
    assert slots.admit("bot3", "10.0.0.9") == (True, ["bot1"])  # the crowding address
    slots.loitering("bot3")  # a heartbeat before authenticating
    assert slots.admit("bot4", "10.0.0.5") == (True, ["bot3"])  # loiterer before the oldest
    same: SessionSlots[str] = SessionSlots(max_sessions=10, max_unauthenticated=3)
    for name in ("a", "operator", "b"):
        same.admit(name, "127.0.0.1")
    same.loitering("a")
    same.loitering("b")
    assert same.admit("c", "127.0.0.1") == (True, ["a"])
    assert same.admit("d", "127.0.0.1") == (True, ["b"])  # the operator is kept
    assert same.admit("e", "127.0.0.1") == (True, ["operator"])  # no loiterer left: oldest


def test_failed_authentications_grow_the_delay_per_address() -> None:
    throttle = AuthThrottle(base_delay_s=0.1, max_delay_s=2.0, max_wait_s=5.0)
    assert throttle.reserve("10.0.0.1", 0.0) == 0.0
    delays = []
    for i in range(7):
        throttle.failed("10.0.0.1", float(i))
        delays.append(throttle.delay(throttle.failures("10.0.0.1", float(i))))
    assert delays == pytest.approx([0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0])
    # concurrent sessions from the address are served one delay apart ...
    assert throttle.reserve("10.0.0.1", 6.0) == pytest.approx(2.0)
    assert throttle.reserve("10.0.0.1", 6.0) == pytest.approx(4.0)
    assert throttle.reserve("10.0.0.1", 6.0) is None  # ... and refused beyond max_wait_s
    assert throttle.reserve("10.0.0.2", 6.0) == 0.0  # other addresses are not affected
    throttle.failed("10.0.0.3", 0.0)
    assert throttle.failures("10.0.0.3", 61.0) == 0  # forgotten after a quiet minute


async def test_abort_needs_an_authenticated_session(start_server: StartServer) -> None:
    server = await start_server()
    anonymous = await hello_only(server)
    try:
        reply = await anonymous.request(m.Abort(id=anonymous.conn.next_id()))
        assert reply.kind == "error" and reply.code == "auth_required"
        reply = await anonymous.request(m.GetState(id=anonymous.conn.next_id()))
        assert reply.kind == "state"  # cheap reads stay open
        operator = await RawClient.open(server)
        try:
            reply = await operator.request(m.Abort(id=operator.conn.next_id()))
            assert reply.kind == "aborted" and reply.was_moving is False
        finally:
            await operator.close()
    finally:
        await anonymous.close()


async def test_anonymous_sessions_cannot_lock_the_operator_out(start_server: StartServer) -> None:
    server = await start_server(max_sessions=6, max_unauthenticated_sessions=3)
    operators = [await RawClient.open(server) for _ in range(2)]
    anonymous = [await hello_only(server) for _ in range(3)]
    try:
        late = [await hello_only(server) for _ in range(2)]  # evict the two oldest
        for client in anonymous[:2]:
            received, _ = await closed_within(client.reader, 3.0)
            assert errors_in(received) == ["busy"] and b"evicted" in received
        anonymous = anonymous[2:] + late
        operators.append(await RawClient.open(server))  # always gets in
        for client in operators:
            assert (await client.request(m.Heartbeat(id=client.conn.next_id()))).kind == (
                "heartbeat_reply"
            )
        assert server.sessions_evicted >= 3
    finally:
        for client in operators + anonymous:
            client.writer.close()


async def wrong_token_attempt(server: ControllerServer) -> list[str]:
    reader, writer = await asyncio.open_connection(*server.address)
    conn = Connection(Role.CLIENT, token="wrong")
    writer.write(conn.initiate())
    codes = []
    try:
        async with asyncio.timeout(10.0):
            while data := await reader.read(1 << 16):
                events = conn.receive_data(data)
                codes += [e.code for e in events if isinstance(e, m.ErrorReply)]
                writer.write(conn.data_to_send())
    finally:
        writer.close()
    return codes


async def test_wrong_tokens_slow_the_address_down_and_a_login_does_not_reset_it(
    start_server: StartServer,
) -> None:
    server = await start_server()
    for _ in range(3):
        assert await wrong_token_attempt(server) == ["auth_failed"]
    now = asyncio.get_running_loop().time()
    assert server.auth_throttle.failures("127.0.0.1", now) == 3
    assert server.auth_throttle.delay(3) == pytest.approx(0.4)
    operator = await RawClient.open(server)  # served after its turn
    try:
        assert operator.conn.state is ConnectionState.READY
        # the operator's login does not hand a guesser on the same address a fresh budget
        assert server.auth_throttle.failures("127.0.0.1", now) == 3
        started = asyncio.get_running_loop().time()
        assert await wrong_token_attempt(server) == ["auth_failed"]
        assert asyncio.get_running_loop().time() - started >= 0.3
        assert server.auth_throttle.failures("127.0.0.1", now) == 4
    finally:
        await operator.close()


async def test_refusals_are_logged_once_per_interval_with_a_count(
    start_server: StartServer, caplog: pytest.LogCaptureFixture
) -> None:
    server = await start_server()
    with caplog.at_level("WARNING", logger="controller_stub.network.server"):
        for port in range(1000):
            server._log_refusal(("10.0.0.9", port), "too many failed authentications")
    refusals = [r for r in caplog.records if "refusing" in r.getMessage()]
    assert len(refusals) == 1  # a hammering peer cannot flood the log
