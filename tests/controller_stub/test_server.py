"""ControllerServer in this event loop, driven by a raw protocol client (no hostpc)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.simulation import Simulation
from protocol import messages as m
from protocol.connection import Connection
from protocol.framing import encode_frame
from protocol.measurement_messages import Capture
from protocol.message_base import Request
from protocol.session_states import ConnectionState, Role

TOKEN = "server-test"
SCENARIO = {
    "camera": {"image_width": 64, "image_height": 48, "fx": 70.0, "fy": 70.0, "cx": 32, "cy": 24},
    "server": {"token": TOKEN},
}


class RawClient:
    """asyncio streams + sans-IO Connection: the smallest possible driver."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.conn = Connection(Role.CLIENT, token=TOKEN)
        self.events: list[object] = []

    @classmethod
    async def open(cls, server: ControllerServer, handshake: bool = True) -> RawClient:
        reader, writer = await asyncio.open_connection(*server.address)
        client = cls(reader, writer)
        if handshake:
            writer.write(client.conn.initiate())
            while client.conn.state is not ConnectionState.READY:
                await client.pump()
        return client

    async def pump(self) -> list[object]:
        data = await asyncio.wait_for(self.reader.read(1 << 20), 5)
        events = self.conn.receive_data(data)
        self.writer.write(self.conn.data_to_send())
        self.events += events
        return events

    async def request(self, request: Request) -> Any:
        self.writer.write(self.conn.send(request))
        while True:
            for event in await self.pump():
                if getattr(event, "reply_to", None) == request.id:
                    return event

    async def close(self) -> None:
        self.writer.close()
        await self.writer.wait_closed()


class FailingSim:
    """The real simulation, except that capture_stereo raises."""

    def __init__(self, sim: Simulation) -> None:
        self._sim = sim

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sim, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "_sim":
            object.__setattr__(self, name, value)
        else:
            setattr(self._sim, name, value)

    def capture_stereo(self, pattern: str = "target", view: int = 0) -> Any:
        raise RuntimeError("camera exploded")


@pytest.fixture
async def server(tmp_path: Path) -> AsyncIterator[ControllerServer]:
    sim = FailingSim(Simulation(scenario_from_dict(SCENARIO)))
    instance = ControllerServer(sim, token=TOKEN, truth_out=tmp_path / "truth.json")
    await instance.start("127.0.0.1", 0)
    yield instance
    await instance.close()


async def test_binds_loopback_and_writes_truth(server: ControllerServer, tmp_path: Path) -> None:
    host, port = server.address
    assert host == "127.0.0.1" and port > 0
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["robot"] == "ur5e" and len(truth["zero_errors"]) == 6


async def test_handler_failure_becomes_an_error_reply_and_serving_goes_on(
    server: ControllerServer,
) -> None:
    client = await RawClient.open(server)
    try:
        reply = await client.request(Capture(id=client.conn.next_id()))
        assert reply.kind == "error" and reply.code == "internal"
        assert "camera exploded" in reply.message
        state = await client.request(m.GetState(id=client.conn.next_id()))
        assert state.kind == "state" and state.n_joints == 6
    finally:
        await client.close()


async def test_wrong_joint_count_is_a_bad_message(server: ControllerServer) -> None:
    client = await RawClient.open(server)
    try:
        reply = await client.request(m.MoveJoints(id=client.conn.next_id(), q=[0.0], speed=0.5))
        assert reply.kind == "error" and reply.code == "bad_message"
        reply = await client.request(m.SetOffsets(id=client.conn.next_id(), offsets=[0.0] * 3))
        assert reply.kind == "error" and reply.code == "bad_message"
    finally:
        await client.close()


async def test_bad_client_does_not_disturb_a_good_one(server: ControllerServer) -> None:
    good = await RawClient.open(server)
    bad_reader, bad_writer = await asyncio.open_connection(*server.address)
    try:
        bad_writer.write(b"\x00garbage that is not a frame")
        assert await asyncio.wait_for(bad_reader.read(), 5)  # an error frame, then EOF
        assert bad_reader.at_eof()
        for _ in range(5):
            reply = await good.request(m.Heartbeat(id=good.conn.next_id()))
            assert reply.kind == "heartbeat_reply"
    finally:
        bad_writer.close()
        await good.close()


async def test_io_edges_reach_authenticated_sessions_only(server: ControllerServer) -> None:
    authenticated = await RawClient.open(server)
    reader, writer = await asyncio.open_connection(*server.address)
    anonymous = RawClient(reader, writer)
    anonymous.conn = Connection(Role.CLIENT, token=None)
    writer.write(anonymous.conn.initiate())
    while anonymous.conn.state is not ConnectionState.AUTHENTICATING:
        await anonymous.pump()
    try:
        q = [0.1] * 6
        server.sim.on_io_edge(2, True, 1.25, np.array(q))  # as the simulation would call it
        events = await authenticated.pump()
        assert [e for e in events if isinstance(e, m.IoEdge)] == [
            m.IoEdge(line=2, value=True, time=1.25, q_latched=q)
        ]
        reply = await anonymous.request(m.Heartbeat(id=anonymous.conn.next_id()))
        assert reply.kind == "heartbeat_reply"
        assert not [e for e in anonymous.events if isinstance(e, m.IoEdge)]
    finally:
        await authenticated.close()
        await anonymous.close()


async def test_pipelined_requests_are_all_answered(server: ControllerServer) -> None:
    client = await RawClient.open(server)
    try:
        requests = [m.Heartbeat(id=client.conn.next_id()) for _ in range(50)]
        client.writer.write(b"".join(client.conn.send(r) for r in requests))
        answered: set[int] = set()
        while len(answered) < len(requests):
            for event in await client.pump():
                if isinstance(event, m.HeartbeatReply):
                    answered.add(event.reply_to)
        assert answered == {r.id for r in requests}
    finally:
        await client.close()


async def test_request_before_hello_is_refused_over_the_socket(server: ControllerServer) -> None:
    reader, writer = await asyncio.open_connection(*server.address)
    try:
        writer.write(encode_frame(m.GetState(id=1).model_dump_json().encode()))
        data = await asyncio.wait_for(reader.read(1 << 16), 5)
        assert b'"unexpected_message"' in data
    finally:
        writer.close()
