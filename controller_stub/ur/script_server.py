"""The UR script port (30003, the "real-time" client interface) as far as ur_rtde needs it.

ur_rtde's `ScriptClient` connects here and writes URScript text: its control program
`def rtde_control(): ... end` (with the register offset injected), later re-uploads, and
custom scripts. A real controller compiles and runs such a program, replacing the one that
runs. The stub does not interpret URScript: it cuts the byte stream into programs (a
`def NAME():` or `sec NAME():` line at column 0 up to the next `end` line at column 0) and
hands each complete one to a `ScriptRobot` (the UR personality), which emulates the
programs it knows. Lines outside a program (single script commands) are logged and ignored.

Not emulated: the 1.1 kB robot state packets a real controller streams on this port at
125/500 Hz (ur_rtde never reads them; it only writes here).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
from typing import Protocol

from controller_stub.ur.tcp_service import TcpService

logger = logging.getLogger(__name__)

_PROGRAM_START = re.compile(r"^(def|sec)\s+([A-Za-z_][A-Za-z0-9_]*)\s*\(\s*\)\s*:")
MAX_PROGRAM_BYTES = 4 << 20


class ScriptRobot(Protocol):
    """Where complete programs go."""

    def run_program(self, name: str, text: str) -> None:
        """Start program `name` (full text), replacing a running one."""
        ...


class ProgramSplitter:
    """Sans-IO: feed text chunks, get complete (name, program text) pairs."""

    def __init__(self) -> None:
        self._pending = ""
        self._lines: list[str] = []
        self._name: str | None = None

    def feed(self, chunk: str) -> list[tuple[str, str]]:
        """Add `chunk`; returns the programs completed by it, in order."""
        self._pending += chunk
        programs: list[tuple[str, str]] = []
        while "\n" in self._pending:
            line, self._pending = self._pending.split("\n", 1)
            line = line.rstrip("\r")
            if self._name is None:
                match = _PROGRAM_START.match(line)
                if match:
                    self._name = match.group(2)
                    self._lines = [line]
                elif line.strip():
                    logger.info("script port: single command ignored: %s", line.strip()[:120])
                continue
            self._lines.append(line)
            if line.rstrip() == "end":
                programs.append((self._name, "\n".join(self._lines) + "\n"))
                self._name, self._lines = None, []
        if sum(len(x) for x in self._lines) + len(self._pending) > MAX_PROGRAM_BYTES:
            logger.warning("script port: program larger than %d bytes dropped", MAX_PROGRAM_BYTES)
            self._name, self._lines, self._pending = None, [], ""
        return programs


class ScriptServer(TcpService):
    """Accept URScript on the script port and hand programs to a `ScriptRobot`."""

    service_name = "script port"
    default_port = 30003


    def __init__(self, robot: ScriptRobot) -> None:
        super().__init__()
        self.robot = robot

    async def _serve_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        splitter = ProgramSplitter()
        try:
            while True:
                chunk = await reader.read(1 << 16)
                if not chunk:
                    return
                for name, text in splitter.feed(chunk.decode(errors="replace")):
                    logger.info("script port: program %r (%d bytes)", name, len(text))
                    self.robot.run_program(name, text)
        except (ConnectionError, asyncio.CancelledError):
            pass
        except Exception:
            logger.exception("script port client failed")
        finally:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()
