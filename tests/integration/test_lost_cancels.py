"""A cancellation (SIGTERM, Ctrl-C, a service shutting down) that comes in the loop step a
wait's result does is not lost outside the transport either: Python 3.11's
asyncio.wait_for returned the result and lost the cancellation (CPython gh-86296;
hostpc.transport.waiting, whose own tests are in test_transport.py). Each test cancels a
real task in the step after the wait it is in completed and before the task resumes."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from controller_stub.network.modbus_io import ModbusIoServer
from hostpc.robots.modbus_io import ModbusIo
from hostpc.robots.ur_precheck import probe_rtde
from hostpc.sensors.camera_service import CameraService
from hostpc.sensors.stereo_camera import StereoCamera
from protocol.connection import Connection
from protocol.session_states import Role
from tests.hostpc.test_sensors import noise_images, write_sequence
from tests.integration.conftest import StartStub

TOKEN = "lost-cancel-token"


async def running(qualname: str) -> asyncio.Task[Any]:
    """The task running the coroutine function `qualname` (e.g. the one asyncio.wait_for
    wraps around the awaitable it waits on), once it exists."""
    for _ in range(100_000):
        for task in asyncio.all_tasks():
            if task.get_coro().__qualname__ == qualname:
                return task
        await asyncio.sleep(0)
    raise AssertionError(f"no task runs {qualname}")


async def cancel_when_done(outer: asyncio.Task[Any], inner: asyncio.Task[Any]) -> None:
    """Cancel `outer` in the first loop step after `inner`, the wait it is in, completed:
    before `outer` resumes (the result reaches it two steps later)."""
    while not inner.done():
        assert not outer.done()
        await asyncio.sleep(0)
    outer.cancel()


async def test_a_modbus_connection_opened_as_a_cancel_comes_is_cancelled_and_closed(
        start_stub: StartStub) -> None:
    server = await start_stub()
    modbus = ModbusIoServer(server.sim, host="127.0.0.1", port=0)
    host, port = await modbus.start()
    try:
        connecting = asyncio.create_task(ModbusIo.connect(host, port, timeout=2.0))
        await cancel_when_done(connecting, await running("ModbusBaseClient.connect"))
        with pytest.raises(asyncio.CancelledError):  # 3.11's wait_for: a ModbusIo
            await connecting
        for _ in range(200):  # the connection is not kept
            if not modbus._server.active_connections:
                break
            await asyncio.sleep(0.01)
        assert not modbus._server.active_connections
    finally:
        await modbus.close()


async def test_a_ur_precheck_connection_opened_as_a_cancel_comes_is_cancelled() -> None:
    """connect_ur's pre-check: a cancel lost with the opened connection ran the check on
    (here to its 2 s timeout against a silent peer, a ConnectionFailed), then created the
    ur_rtde interfaces."""
    peers: list[asyncio.StreamWriter] = []
    silent = await asyncio.start_server(lambda _r, w: peers.append(w), "127.0.0.1", 0)
    port = silent.sockets[0].getsockname()[1]
    try:
        probing = asyncio.create_task(probe_rtde("127.0.0.1", port, timeout=2.0))
        await cancel_when_done(probing, await running("open_connection"))
        with pytest.raises(asyncio.CancelledError):
            await probing
    finally:
        silent.close()
        for peer in peers:
            peer.close()
        await silent.wait_closed()


async def test_a_camera_session_whose_read_comes_with_a_cancel_ends(tmp_path: Path) -> None:
    """`hostpc camera serve` shutting down (asyncio.run cancels every task): a session whose
    read came in the same step served on, and the shutdown waited out its handshake or
    idle timeout (5 s, 300 s)."""
    camera = StereoCamera(write_sequence(tmp_path, "left", noise_images(1, 31)),
                          write_sequence(tmp_path, "right", noise_images(1, 32)))
    server = await CameraService(camera, TOKEN).start("127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    session: asyncio.Task[Any] | None = None
    try:
        read = await running("StreamReader.read")  # the session waits for its hello
        session = await running("CameraService._session")
        cancelling = asyncio.create_task(cancel_when_done(session, read))
        writer.write(Connection(Role.CLIENT, token=TOKEN).initiate())
        await cancelling
        done, _ = await asyncio.wait({session}, timeout=3.0)
        assert session in done and session.cancelled()
    finally:
        if session is not None and not session.done():
            session.cancel()
        writer.close()
        server.close()
        await server.wait_closed()
        camera.close()
