"""Every server zerocal ships against a flood of idle connections (real sockets on
127.0.0.1, in-process): the controller stub, the camera service, the station's Modbus port
(real pymodbus client) and the station's live page (real aiohttp client). Each must serve a
legitimate request within 1 s with the flood held open, and log no traceback."""

from __future__ import annotations

import asyncio
import logging
import resource
import socket
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path

import aiohttp
import pytest
from pymodbus.client import AsyncModbusTcpClient

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from hostpc.sensors.camera_service import CameraService
from hostpc.sensors.stereo_camera import StereoCamera
from hostpc.station import registers as reg
from hostpc.station.config import StationConfig
from hostpc.station.plc import PlcServer
from hostpc.station.service import Station
from hostpc.station.web import serve_page
from hostpc.transport import ControllerClient
from protocol import messages as m
from protocol.connection import Connection
from protocol.session_states import Role
from tests.controller_stub.test_server import SCENARIO, TOKEN, RawClient
from tests.hostpc.test_sensors import noise_images, write_sequence

FLOOD = 500
LEGITIMATE = 10


def raise_open_file_limit(needed: int) -> None:
    """The flood's client sockets live in this process too: raise the soft limit (never
    above the hard one); skip if the hard limit is too low."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < needed:
        if hard != resource.RLIM_INFINITY and hard < needed:
            pytest.skip(f"needs {needed} open files, the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (needed, hard))


def open_flood(port: int, count: int, within_s: float = 60.0) -> list[socket.socket]:
    """Up to `count` connections that never send a byte, opened within `within_s` (a server
    that stops accepting must not stall the test); blocking connects: run in a thread."""
    flood = []
    deadline = time.monotonic() + within_s
    for _ in range(count):
        if time.monotonic() > deadline:
            break
        try:
            flood.append(socket.create_connection(("127.0.0.1", port), timeout=1))
        except OSError:
            pass  # the server is shedding: what is open is the flood
    return flood


@dataclass
class Served:
    """A running server: its port, and one legitimate request (raises if not served)."""

    port: int
    legitimate: Callable[[], Awaitable[None]]


ServerFactory = Callable[[Path], AsyncIterator[Served]]


async def controller_stub(_tmp: Path) -> AsyncIterator[Served]:
    server = ControllerServer.from_scenario(
        scenario_from_dict({**SCENARIO, "server": {"token": TOKEN}}))
    await server.start("127.0.0.1", 0)

    async def heartbeat() -> None:
        client = await RawClient.open(server)
        try:
            assert (await client.request(m.Heartbeat(id=client.conn.next_id()))).kind == (
                "heartbeat_reply")
        finally:
            await client.close()

    try:
        yield Served(server.address[1], heartbeat)
    finally:
        await server.close()


async def camera_service(tmp: Path) -> AsyncIterator[Served]:
    camera = StereoCamera(write_sequence(tmp, "left", noise_images(LEGITIMATE + 2, 31)),
                          write_sequence(tmp, "right", noise_images(LEGITIMATE + 2, 32)))
    server = await CameraService(camera, "camera-token").start("127.0.0.1", 0)

    async def capture() -> None:
        client = await ControllerClient.connect("127.0.0.1", port, token="camera-token")
        try:
            left, _, _, _ = await client.capture("target", encoding="raw")
            assert left.shape == (48, 64)
        finally:
            await client.close()

    port = server.sockets[0].getsockname()[1]
    try:
        yield Served(port, capture)
    finally:
        server.close()
        camera.close()


async def station_modbus(_tmp: Path) -> AsyncIterator[Served]:
    plc = PlcServer("127.0.0.1", 0)
    _, port = await plc.start()

    async def write_and_read() -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1, retries=0)
        try:
            assert await client.connect()
            assert not (await client.write_registers(
                reg.SERIAL, reg.encode_text("SN-1", reg.SERIAL_LENGTH))).isError()
            reply = await client.read_holding_registers(0, count=reg.N_REGISTERS)
            assert not reply.isError() and reg.decode_text(
                reply.registers[reg.SERIAL:reg.SERIAL + reg.SERIAL_LENGTH]) == "SN-1"
        finally:
            client.close()

    try:
        yield Served(port, write_and_read)
    finally:
        await plc.close()


async def station_page(tmp: Path) -> AsyncIterator[Served]:
    station = Station(StationConfig(robot="sim", runs_dir=str(tmp / "runs"),
                                    db=f"sqlite:///{tmp / 'archive.db'}"))
    page = await serve_page(station, "127.0.0.1", 0)
    port = page.address[1]

    async def get_state() -> None:
        async with aiohttp.ClientSession() as session, session.get(
                f"http://127.0.0.1:{port}/api/state") as reply:
            assert reply.status == 200 and (await reply.json())["state"] == "IDLE"

    try:
        yield Served(port, get_state)
    finally:
        await page.cleanup()


SERVERS = {"controller_stub": controller_stub, "camera_service": camera_service,
           "station_modbus": station_modbus, "station_page": station_page}


@pytest.fixture(params=sorted(SERVERS))
async def served(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[Served]:
    factory: ServerFactory = SERVERS[request.param]
    async for server in factory(tmp_path):
        yield server


async def test_an_idle_flood_does_not_lock_out_a_legitimate_client(
    served: Served, caplog: pytest.LogCaptureFixture
) -> None:
    raise_open_file_limit(4 * FLOOD + 256)
    caplog.set_level(logging.INFO)
    flood = await asyncio.to_thread(open_flood, served.port, FLOOD)
    try:
        slowest = 0.0
        for _ in range(LEGITIMATE):
            started = time.monotonic()
            await asyncio.wait_for(served.legitimate(), 5.0)
            slowest = max(slowest, time.monotonic() - started)
        assert slowest < 1.0, f"a legitimate request took {slowest:.2f} s"
    finally:
        for sock in flood:
            sock.close()
    assert not [r for r in caplog.records if r.exc_info or "Traceback" in r.getMessage()]
    logged = sum(len(r.getMessage()) for r in caplog.records)
    assert logged < 200 * FLOOD, f"{logged} bytes logged for a flood of {FLOOD}"


async def guesses_within(port: int, attempts: int, seconds: float) -> int:
    """Wrong-token attempts one after the other for at most `seconds`: how many got their
    `auth_failed` answer (= tokens guessed)."""
    guessed = 0
    deadline = time.monotonic() + seconds
    for _ in range(attempts):
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        conn = Connection(Role.CLIENT, token="wrong")
        writer.write(conn.initiate())
        try:
            async with asyncio.timeout(max(deadline - time.monotonic(), 0.01)):
                while data := await reader.read(1 << 16):
                    events = conn.receive_data(data)
                    guessed += sum(isinstance(e, m.ErrorReply) and e.code == "auth_failed"
                                   for e in events)
                    writer.write(conn.data_to_send())
        except TimeoutError:
            break
        finally:
            writer.close()
    return guessed


@pytest.mark.parametrize("server", ["controller_stub", "camera_service"])
async def test_a_wrong_token_storm_is_delayed_per_address(server: str, tmp_path: Path) -> None:
    async for served in SERVERS[server](tmp_path):
        guessed = await guesses_within(served.port, 40, 6.0)
        # 0.1, 0.2, 0.4, 0.8, 1.6, 2 s apart: at most 7 guesses in 6 s (40 without it)
        assert 3 <= guessed <= 8, guessed
