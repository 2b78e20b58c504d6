"""The station's Modbus port and live page against misbehaving peers (in-process, real
sockets on 127.0.0.1, the real pymodbus client): coil writes and wrong units refused
without a traceback, broken headers closed, silent and slowloris connections closed at
their deadline, drift plots rendered once for a burst of requests."""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient

from hostpc.station import registers as reg
from hostpc.station.config import StationConfig
from hostpc.station.plc import PlcServer
from hostpc.station.service import Station
from hostpc.station.web import DriftPlots, serve_page
from tests.station.test_history import _run


async def test_coil_writes_and_wrong_units_are_refused_in_one_line_each(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    plc = PlcServer("127.0.0.1", 0)
    _, port = await plc.start()
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    try:
        assert await client.connect()
        for _ in range(50):
            coil = await client.write_coil(0, True)
            assert coil.isError() and coil.exception_code == 0x01  # illegal function
            coils = await client.write_coils(0, [True, False])
            assert coils.isError() and coils.exception_code == 0x01
            other = await client.read_holding_registers(0, count=2, device_id=7)
            assert other.isError() and other.exception_code == 0x0B  # gateway: no target
        reply = await client.read_holding_registers(0, count=reg.N_REGISTERS)
        assert not reply.isError()  # the same connection still serves
    finally:
        client.close()
        await plc.close()
    records = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not [r for r in caplog.records if r.exc_info or "Traceback" in r.getMessage()]
    assert 2 <= len(records) <= 4, [r.getMessage() for r in records]  # per kind, not per request


async def test_silent_and_broken_modbus_connections_are_closed() -> None:
    plc = PlcServer("127.0.0.1", 0, first_request_timeout_s=0.5)
    _, port = await plc.start()
    try:
        silent = await asyncio.open_connection("127.0.0.1", port)
        broken = await asyncio.open_connection("127.0.0.1", port)
        broken[1].write(b"\x00\x01\x12\x34\x00\x06\x01\x03\x00\x00\x00\x01")  # protocol 0x1234
        assert await asyncio.wait_for(broken[0].read(), 1.0) == b""
        started = time.monotonic()
        assert await asyncio.wait_for(silent[0].read(), 3.0) == b""
        assert 0.4 < time.monotonic() - started < 2.0
        assert plc.guard.overdue == 1
    finally:
        await plc.close()


async def test_a_slowloris_on_the_page_is_closed_at_its_deadline(tmp_path: Path) -> None:
    station = Station(StationConfig(robot="sim", runs_dir=str(tmp_path / "runs"),
                                    db=f"sqlite:///{tmp_path / 'archive.db'}"))
    page = await serve_page(station, "127.0.0.1", 0, first_request_timeout_s=1.0)
    try:
        reader, writer = await asyncio.open_connection(*page.address)
        started = time.monotonic()
        closed = False
        for byte in b"GET /api/state HTTP/1.1\r\nHost: x\r\nX-Slow: " + b"a" * 100:
            writer.write(bytes([byte]))  # one byte every 0.1 s never completes a request
            try:
                if await asyncio.wait_for(reader.read(1), 0.1) == b"":
                    closed = True
                    break
            except TimeoutError:
                continue
            except ConnectionError:
                closed = True
                break
        assert closed and time.monotonic() - started < 3.0
    finally:
        await page.cleanup()


async def test_a_burst_of_drift_plot_requests_renders_once() -> None:
    runs = [_run(k, "A", [0.1, 0.2, 0.3 + 0.01 * k]) for k in range(1, 6)]
    plots = DriftPlots()
    try:
        pngs = await asyncio.gather(*(plots.png("A", runs) for _ in range(200)))
        assert plots.rendered == 1 and len(set(pngs)) == 1 and pngs[0][:4] == b"\x89PNG"
        await plots.png("A", [*runs, _run(6, "A", [0.1, 0.2, 0.4])])
        assert plots.rendered == 2  # a new run: a new plot
    finally:
        plots.close()
