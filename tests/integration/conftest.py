"""Fixtures that run a real controller stub on 127.0.0.1 (port 0) in this event loop.

`start_stub(overrides)` builds a scenario from the small test defaults below merged with
`overrides`, starts `ControllerServer` on a free loopback port and closes it after the test.
The camera is small (320x256) so that building the simulation's renderer stays cheap.
"""

from __future__ import annotations

import copy
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from hostpc.transport import ControllerClient

TOKEN = "test-token"

BASE_SCENARIO: dict[str, Any] = {
    "seed": 7,
    "robot": "ur5e",
    "camera": {
        "image_width": 320,
        "image_height": 256,
        "fx": 350.0,
        "fy": 350.0,
        "cx": 160.3,
        "cy": 127.7,
    },
    "server": {"token": TOKEN},
}

StartStub = Callable[..., Awaitable[ControllerServer]]


def merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge `overrides` into a copy of `base`."""
    merged = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


@pytest.fixture
async def start_stub() -> AsyncIterator[StartStub]:
    """Factory: `server = await start_stub(overrides, truth_out=None)`; closed at teardown."""
    servers: list[ControllerServer] = []

    async def _start(
        overrides: dict[str, Any] | None = None, truth_out: Path | None = None
    ) -> ControllerServer:
        scenario = scenario_from_dict(merge(BASE_SCENARIO, overrides or {}))
        server = ControllerServer.from_scenario(scenario, truth_out=truth_out)
        await server.start("127.0.0.1", 0)
        servers.append(server)
        return server

    yield _start
    for server in servers:
        await server.close()


@pytest.fixture
async def stub(start_stub: StartStub) -> ControllerServer:
    """A stub with the base scenario."""
    return await start_stub()


@pytest.fixture
async def client(stub: ControllerServer) -> AsyncIterator[ControllerClient]:
    """An authenticated client of `stub`."""
    host, port = stub.address
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as connected:
        yield connected
