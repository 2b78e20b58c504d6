"""hostpc's Modbus IO client (pymodbus AsyncModbusTcpClient) against the stub's Modbus
server (UR-style map: digital input i = discrete input i, output i = coil i)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import pytest

from controller_stub.network.modbus_io import ModbusIoServer
from controller_stub.network.server import ControllerServer
from hostpc.errors import ConnectionFailed, InputError, RequestTimeout
from hostpc.robots.modbus_io import ModbusIo
from tests.integration.conftest import StartStub


@pytest.fixture
async def served(start_stub: StartStub) -> AsyncIterator[tuple[ControllerServer, ModbusIo]]:
    server = await start_stub()
    modbus = ModbusIoServer(server.sim, host="127.0.0.1", port=0, writable=True)
    host, port = await modbus.start()
    io = await ModbusIo.connect(host, port, timeout=2.0)
    yield server, io
    await io.close()
    await modbus.close()


async def test_reads_inputs_including_the_probe_line(
    served: tuple[ControllerServer, ModbusIo], monkeypatch: pytest.MonkeyPatch
) -> None:
    server, io = served
    probe_line = server.sim.scenario.probe.io_line
    assert await io.read_inputs() == tuple(server.sim.digital_inputs())
    levels = [False] * 8
    levels[probe_line] = True
    monkeypatch.setattr(server.sim, "digital_inputs", lambda: list(levels))
    assert await io.read_input(probe_line)
    assert (await io.read_inputs())[probe_line]


async def test_station_bits_write_the_outputs(served: tuple[ControllerServer, ModbusIo]) -> None:
    server, io = served
    await io.set_station_bit(5, True)
    assert server.sim.digital_outputs()[5]
    assert (await io.read_outputs())[5]
    await io.write_output(5, False)
    assert not server.sim.digital_outputs()[5]
    with pytest.raises(InputError):
        await io.write_output(8, True)


async def test_wait_for_a_trigger(
    served: tuple[ControllerServer, ModbusIo], monkeypatch: pytest.MonkeyPatch
) -> None:
    server, io = served
    levels = [False] * 8
    monkeypatch.setattr(server.sim, "digital_inputs", lambda: list(levels))

    async def trigger() -> None:
        await asyncio.sleep(0.1)
        levels[2] = True

    task = asyncio.create_task(trigger())
    waited = await io.wait_for_edge(2, rising=True, timeout=2.0, poll_s=0.005)
    await task
    assert 0.05 < waited < 2.0
    with pytest.raises(RequestTimeout):
        await io.wait_for_input(3, True, timeout=0.1)


async def test_unreachable_server_is_connection_failed() -> None:
    with pytest.raises(ConnectionFailed):
        await ModbusIo.connect("127.0.0.1", 1, timeout=0.5)
