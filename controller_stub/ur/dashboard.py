"""The UR dashboard server (port 29999): one text command per line, one reply line each.

On connect the server greets with `Connected: Universal Robots Dashboard Server`. The
commands ur_rtde's `DashboardClient` sends are answered with the exact reply strings it
checks (`stop` -> `Stopped`, `play` -> `Starting program`, `unlock protective stop` ->
`Protective stop releasing`, ...); `PolyscopeVersion` answers e.g.
`URSoftware 5.11.1.108318 (Dec 06 2021)`. Commands the stub does not emulate get UR's
`could not understand: '<command>'`. The robot state comes from a `DashboardRobot` (the UR
personality); this module only parses and formats.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Protocol

from controller_stub.ur.tcp_service import TcpService

logger = logging.getLogger(__name__)

GREETING = "Connected: Universal Robots Dashboard Server"
MAX_LINE = 4096


class DashboardRobot(Protocol):
    """What the dashboard reports and controls."""

    controller_version: tuple[int, int, int, int]
    serial_number: str
    robot_model: str

    def program_running(self) -> bool:
        """True while a program runs (runtime state PLAYING)."""
        ...

    def program_name(self) -> str:
        """Name of the last program sent or loaded ('' if none)."""
        ...

    def stop_program(self) -> None:
        """Stop the running program (dashboard `stop`)."""
        ...

    def protective_stopped(self) -> bool:
        """True while a protective stop is active."""
        ...

    def unlock_protective_stop(self) -> None:
        """Clear the protective stop."""
        ...

    def emergency_stopped(self) -> bool:
        """True while the (simulated) e-stop is pressed."""
        ...


def answer(robot: DashboardRobot, line: str) -> str:
    """The reply line (without newline) to one dashboard command."""
    command = line.strip()
    lower = command.lower()
    major, minor, bugfix, build = robot.controller_version
    if lower == "polyscopeversion":
        return f"URSoftware {major}.{minor}.{bugfix}.{build} (Dec 06 2021)"
    if lower == "version":
        return f"Version information: {major}.{minor}.{bugfix}.{build}"
    if lower == "robotmode":
        return "Robotmode: RUNNING"
    if lower == "running":
        return f"Program running: {'true' if robot.program_running() else 'false'}"
    if lower == "programstate":
        name = robot.program_name() or "<unnamed>"
        return f"{'PLAYING' if robot.program_running() else 'STOPPED'} {name}"
    if lower == "get loaded program":
        name = robot.program_name()
        return f"Loaded program: {name}" if name else "No program loaded"
    if lower == "stop":
        robot.stop_program()
        return "Stopped"
    if lower == "play":
        return "Failed to execute: play"
    if lower == "pause":
        return "Failed to execute: pause"
    if lower.startswith("load "):
        return f"File not found: {command[5:]}"
    if lower == "is in remote control":
        return "true"
    if lower == "get serial number":
        return robot.serial_number
    if lower == "get robot model":
        return robot.robot_model
    if lower == "safetymode":
        if robot.emergency_stopped():
            return "Safetymode: ROBOT_EMERGENCY_STOP"
        return "Safetymode: PROTECTIVE_STOP" if robot.protective_stopped() else "Safetymode: NORMAL"
    if lower == "safetystatus":
        if robot.emergency_stopped():
            return "Safetystatus: ROBOT_EMERGENCY_STOP"
        if robot.protective_stopped():
            return "Safetystatus: PROTECTIVE_STOP"
        return "Safetystatus: NORMAL"
    if lower == "unlock protective stop":
        robot.unlock_protective_stop()
        return "Protective stop releasing"
    if lower == "power on":
        return "Powering on"
    if lower == "power off":
        return "Powering off"
    if lower == "brake release":
        return "Brake releasing"
    if lower == "close popup":
        return "closing popup"
    if lower.startswith("popup "):
        return "showing popup"
    if lower == "close safety popup":
        return "closing safety popup"
    if lower == "restart safety":
        return "Restarting safety"
    if lower.startswith("addtolog "):
        return "Added log message"
    if lower == "isprogramsaved":
        return f"true {robot.program_name() or '<unnamed>'}"
    if lower.startswith("setuserrole "):
        return f"Setting user role: {command[12:]}"
    if lower == "quit":
        return "Disconnected"
    if lower == "shutdown":
        return "Shutting down"
    return f"could not understand: '{command}'"


class DashboardServer(TcpService):
    """Serve the dashboard text protocol for one `DashboardRobot`."""

    service_name = "dashboard"
    default_port = 29999
    read_limit = MAX_LINE


    def __init__(self, robot: DashboardRobot) -> None:
        super().__init__()
        self.robot = robot

    async def _serve_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        try:
            writer.write(f"{GREETING}\n".encode())
            await writer.drain()
            while True:
                raw = await reader.readline()
                if not raw:
                    return
                line = raw.decode(errors="replace")
                reply = answer(self.robot, line)
                logger.debug("dashboard %r -> %r", line.strip(), reply)
                writer.write(f"{reply}\n".encode())
                await writer.drain()
                if line.strip().lower() == "quit":
                    return
        except (ConnectionError, asyncio.CancelledError, asyncio.LimitOverrunError, ValueError):
            pass
        finally:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()
