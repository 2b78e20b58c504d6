"""The station process under a flood (the users' measurement, on 127.0.0.1): at the common
1024 open-file limit, 1,100 idle connections on each of its Modbus and HTTP ports must not
lock the PLC or the page out, and must not flood its log."""

from __future__ import annotations

import asyncio
import json
import resource
import signal
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from pymodbus.client import AsyncModbusTcpClient

from hostpc.station import registers as reg
from tests.integration.test_server_floods import open_flood, raise_open_file_limit
from tests.station.conftest import REPO, hostpc_command
from tests.station.test_station import _free_port

FLOOD = 1100
STATION_OPEN_FILES = 1024


def _limit_open_files() -> None:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (STATION_OPEN_FILES, hard))


@pytest.fixture
def station(tmp_path: Path) -> Iterator[tuple[int, int, Path]]:
    """A station process with the 1024 open-file limit: (Modbus port, HTTP port, log)."""
    modbus, http = _free_port(), _free_port()
    config = {"station": "eol-flood", "robot": "sim", "db": f"sqlite:///{tmp_path / 'a.db'}",
              "runs_dir": str(tmp_path / "runs"), "http": f"127.0.0.1:{http}",
              "modbus": {"host": "127.0.0.1", "port": modbus}}
    (tmp_path / "station.yaml").write_text(yaml.safe_dump(config))
    log = tmp_path / "station.log"
    with log.open("wb") as out:
        process = subprocess.Popen(hostpc_command("station", "--config",
                                                  str(tmp_path / "station.yaml")),
                                   cwd=REPO, stdout=out, stderr=subprocess.STDOUT,
                                   preexec_fn=_limit_open_files)
    try:
        deadline = time.monotonic() + 60
        while b"page on http" not in log.read_bytes():
            assert process.poll() is None, log.read_text()[-3000:]
            assert time.monotonic() < deadline, "station did not start"
            time.sleep(0.1)
        yield modbus, http, log
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


async def _plc_session(port: int, floods: list[list[object]]) -> tuple[float, float]:
    """The PLC (pymodbus's asyncio client: the flood's sockets are numbered beyond what
    select() takes) connects through the flood, STARTs (no serial in the registers: the
    station answers ERROR at once) and reads the state; then a second flood arrives and the
    connected PLC acknowledges. Returns the seconds both took."""
    started = time.monotonic()
    plc = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1, retries=0)
    try:
        assert await plc.connect()
        assert not (await plc.write_register(reg.COMMAND, reg.Command.START)).isError()
        while True:
            reply = await plc.read_holding_registers(0, count=reg.N_REGISTERS)
            assert not reply.isError(), reply
            if reply.registers[reg.STATE] == reg.State.ERROR or time.monotonic() > started + 2:
                break
            await asyncio.sleep(0.02)
        took_start = time.monotonic() - started
        assert reply.registers[reg.STATE] == reg.State.ERROR  # the START was served
        assert reply.registers[reg.RESULT_CODE] == reg.RESULT_NO_SERIAL
        # a second flood evicts the flood's silent sockets, not the PLC that polls
        floods.append(await asyncio.to_thread(open_flood, port, FLOOD))
        started = time.monotonic()
        assert not (await plc.write_register(reg.COMMAND, reg.Command.ACKNOWLEDGE)).isError()
        assert not (await plc.read_holding_registers(0, count=reg.N_REGISTERS)).isError()
        return took_start, time.monotonic() - started
    finally:
        plc.close()


@pytest.mark.slow  # ~30 s: opening 3,300 sockets on a shared machine
def test_1100_idle_connections_per_port_do_not_lock_out_the_plc_or_the_page(
    station: tuple[int, int, Path],
) -> None:
    modbus, http, log = station
    raise_open_file_limit(2 * (2 * FLOOD) + 256)
    logged_before = log.stat().st_size
    t0 = time.monotonic()
    floods: list[list[object]] = [open_flood(modbus, FLOOD), open_flood(http, FLOOD)]
    print(f"floods opened in {time.monotonic() - t0:.1f} s")
    try:
        took_start, took_again = asyncio.run(_plc_session(modbus, floods))
        started = time.monotonic()
        with urllib.request.urlopen(f"http://127.0.0.1:{http}/api/state", timeout=1) as page:
            assert json.loads(page.read())["state"] in ("ERROR", "IDLE")  # ack: soon IDLE
        took_page = time.monotonic() - started
        print(f"START {took_start:.3f} s, again {took_again:.3f} s, page {took_page:.3f} s")
        assert max(took_start, took_again, took_page) < 1.0, (took_start, took_again, took_page)
    finally:
        for flood in floods:
            for sock in flood:
                sock.close()  # type: ignore[attr-defined]
    grown = log.stat().st_size - logged_before
    print(f"station log grew {grown} bytes")
    text = log.read_bytes()[logged_before:]
    assert grown < 1_000_000 and b"Traceback" not in text, (grown, text[-2000:])
