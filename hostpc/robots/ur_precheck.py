"""The asyncio pre-checks of a Universal Robots controller, run by `ur.connect_ur` before
any ur_rtde interface is created.

ur_rtde's constructors hold the Python GIL while they wait for the controller, so a peer that
accepts a TCP connection and never answers would freeze the whole interpreter. These checks
talk to the controller with plain asyncio under a timeout instead: an RTDE protocol-version
request and controller-version request on 30004, the dashboard greeting and queries on 29999,
a TCP connect to 30003. What they learn is a `UrControllerInfo`; any failure is a
ConnectionFailed with the reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from dataclasses import dataclass

from hostpc.errors import ConnectionFailed
from hostpc.transport.waiting import wait_for_reply

RTDE_PORT = 30004
DASHBOARD_PORT = 29999
SCRIPT_PORT = 30003
RTDE_PROTOCOL_VERSION = 2


@dataclass(frozen=True)
class UrControllerInfo:
    """What the asyncio pre-check learned: versions, model, serial, remote control."""

    controller_version: tuple[int, int, int, int]
    polyscope: str
    robot_model: str
    serial_number: str
    remote_control: bool | None

    @property
    def robot_name(self) -> str:
        """zerocal robot name (`ur5e`, `ur10e`, ... for e-Series, `ur5`, ... for CB3)."""
        model = self.robot_model.strip().lower()
        if not model.startswith("ur"):
            return model or "ur"
        if self.controller_version[0] >= 5 and model[-1].isdigit() and model not in (
            "ur20", "ur30", "ur8long", "ur15", "ur18"
        ):
            return model + "e"
        return model


def _package(kind: str, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload


async def _read_package(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    size, kind = struct.unpack(">HB", await reader.readexactly(3))
    if size < 3:
        raise ValueError(f"RTDE package size {size} < 3")
    return kind, await reader.readexactly(size - 3)


async def _open(host: str, port: int, timeout: float, what: str) -> tuple[
    asyncio.StreamReader, asyncio.StreamWriter
]:
    try:
        return await wait_for_reply(asyncio.open_connection(host, port), timeout,
                                    lambda opened: opened[1].close())
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR {what} {host}:{port}: no connection within {timeout:.1f} s"
        ) from exc
    except OSError as exc:
        raise ConnectionFailed(f"UR {what} {host}:{port}: cannot connect: {exc}") from exc


async def _close(writer: asyncio.StreamWriter) -> None:
    writer.close()
    with contextlib.suppress(Exception):
        await writer.wait_closed()


async def probe_rtde(
    host: str, port: int = RTDE_PORT, timeout: float = 3.0
) -> tuple[int, int, int, int]:
    """Check that `host:port` speaks RTDE: protocol version 2, then the controller version.

    Pure asyncio with a timeout, so a peer that accepts and stays silent cannot freeze the
    interpreter (ur_rtde's constructors would). Returns (major, minor, bugfix, build).
    Raises ConnectionFailed with the reason.
    """
    reader, writer = await _open(host, port, timeout, "RTDE")
    try:
        async with asyncio.timeout(timeout):
            writer.write(_package("V", struct.pack(">H", RTDE_PROTOCOL_VERSION)))
            await writer.drain()
            kind, body = await _read_package(reader)
            if kind != ord("V") or not body or not body[0]:
                raise ConnectionFailed(
                    f"UR RTDE {host}:{port}: the controller refused RTDE protocol version "
                    f"{RTDE_PROTOCOL_VERSION} (reply type {kind}, {body[:4]!r})"
                )
            writer.write(_package("v"))
            await writer.drain()
            kind, body = await _read_package(reader)
            if kind != ord("v") or len(body) < 16:
                raise ConnectionFailed(
                    f"UR RTDE {host}:{port}: bad controller-version reply (type {kind})"
                )
            major, minor, bugfix, build = struct.unpack(">4I", body[:16])
            return major, minor, bugfix, build
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR RTDE {host}:{port}: the peer accepted the connection but did not answer the "
            f"RTDE protocol-version request within {timeout:.1f} s (is it a UR controller with "
            "RTDE enabled?); no ur_rtde interface was created"
        ) from exc
    except (asyncio.IncompleteReadError, ConnectionError, ValueError) as exc:
        raise ConnectionFailed(f"UR RTDE {host}:{port}: connection broken: {exc}") from exc
    finally:
        await _close(writer)


async def probe_dashboard(
    host: str, port: int = DASHBOARD_PORT, timeout: float = 3.0
) -> tuple[str, str, str, bool | None]:
    """Greeting and (PolyScope version, robot model, serial number, in remote control) from
    the dashboard server, in asyncio under `timeout`. ConnectionFailed if it does not answer.
    """
    reader, writer = await _open(host, port, timeout, "dashboard")

    async def ask(command: str) -> str:
        writer.write(f"{command}\n".encode())
        await writer.drain()
        return (await reader.readline()).decode(errors="replace").strip()

    try:
        async with asyncio.timeout(timeout):
            greeting = (await reader.readline()).decode(errors="replace").strip()
            if "dashboard" not in greeting.lower():
                raise ConnectionFailed(
                    f"UR dashboard {host}:{port}: unexpected greeting {greeting!r}"
                )
            polyscope = await ask("PolyscopeVersion")
            model = await ask("get robot model")
            serial = await ask("get serial number")
            remote_text = (await ask("is in remote control")).lower()
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR dashboard {host}:{port}: no answer within {timeout:.1f} s"
        ) from exc
    except (asyncio.IncompleteReadError, ConnectionError) as exc:
        raise ConnectionFailed(f"UR dashboard {host}:{port}: connection broken: {exc}") from exc
    finally:
        await _close(writer)
    remote = True if "true" in remote_text else False if "false" in remote_text else None
    if model.lower().startswith("could not understand"):
        model = ""
    if not serial.isdigit():
        serial = ""
    return polyscope, model, serial, remote


async def probe_port(host: str, port: int, timeout: float, what: str) -> None:
    """TCP connect to `host:port` under `timeout`; ConnectionFailed otherwise."""
    _, writer = await _open(host, port, timeout, what)
    await _close(writer)


async def check_controller(host: str, timeout: float = 3.0) -> UrControllerInfo:
    """All asyncio pre-checks of a UR controller (RTDE, dashboard, script port)."""
    version = await probe_rtde(host, RTDE_PORT, timeout)
    polyscope, model, serial, remote = await probe_dashboard(host, DASHBOARD_PORT, timeout)
    await probe_port(host, SCRIPT_PORT, timeout, "script port")
    if remote is False:
        raise ConnectionFailed(
            f"UR {host}: the robot is in local control; switch it to remote control on the "
            "teach pendant (docs/robots.md)"
        )
    return UrControllerInfo(version, polyscope, model, serial, remote)
