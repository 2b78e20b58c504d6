"""The RTDE server (Universal Robots Real-Time Data Exchange, protocol version 2) on 30004.

It answers the packages of the wire format in `rtde_wire.py` (package framing, the named
fields and their types, value packing) as the unmodified ur_rtde library (1.6) expects.

Input recipe fields are owned by the connection that set them up while it lives; another
connection asking for the same field gets `IN_USE` (as on a real controller). Only protocol
version 2 is accepted (ur_rtde always asks for 2). Data packages are streamed at the
requested frequency but at most `max_stream_hz` (default 125 Hz), on the source's controller
cycles (500 Hz: every cycle, 125 Hz: every 4th), so every package carries one whole cycle and
none is skipped when the host is slow; a client that does not read gets packages dropped,
never an unbounded buffer.

The server knows nothing of robots: a `RtdeDataSource` (the UR personality) supplies output
values by name and receives input values.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from controller_stub.ur.rtde_wire import (
    CONTROL_PACKAGE_PAUSE,
    CONTROL_PACKAGE_SETUP_INPUTS,
    CONTROL_PACKAGE_SETUP_OUTPUTS,
    CONTROL_PACKAGE_START,
    DATA_PACKAGE,
    GET_URCONTROL_VERSION,
    HEADER,
    PROTOCOL_VERSION,
    REQUEST_PROTOCOL_VERSION,
    TEXT_MESSAGE,
    input_type,
    output_type,
    pack,
    pack_values,
    unpack_values,
)
from controller_stub.ur.tcp_service import TcpService

logger = logging.getLogger(__name__)


MAX_WRITE_BUFFER = 1 << 20


class RtdeDataSource(Protocol):
    """What the RTDE server needs from the robot behind it."""

    @property
    def controller_version(self) -> tuple[int, int, int, int]:
        """(major, minor, bugfix, build) reported to GET_URCONTROL_VERSION."""
        ...

    def output_values(self, names: Sequence[str]) -> list[Any]:
        """Current values of the named outputs, in order (types as in `output_type`)."""
        ...

    def apply_inputs(self, values: dict[str, Any]) -> None:
        """Values written by a client's data package (one recipe, name -> value)."""
        ...

    async def next_cycle(self, after: int) -> int:
        """Wait for the controller cycle after cycle `after`; returns its number (a source
        without a cycle clock sleeps one 2 ms period and returns after + 1)."""
        ...


CONTROLLER_HZ = 500.0
"""The controller cycle rate the stream is divided from."""


@dataclass
class _Recipe:
    names: list[str]
    types: list[str]


@dataclass
class _Session:
    """One RTDE client connection's negotiated state."""

    peer: str
    version: int = 0
    output: _Recipe | None = None
    frequency: float = 125.0
    inputs: dict[int, _Recipe] = field(default_factory=dict)
    owned: set[str] = field(default_factory=set)
    streaming: asyncio.Task[None] | None = None


class RtdeServer(TcpService):
    """Serve RTDE to any number of clients from one `RtdeDataSource`.

    source: the robot; max_stream_hz: cap of the data package rate (Hz).
    """

    service_name = "rtde"
    default_port = 30004

    def __init__(self, source: RtdeDataSource, *, max_stream_hz: float = 125.0) -> None:
        super().__init__()
        self.source = source
        self.max_stream_hz = float(max_stream_hz)
        self._owners: dict[str, _Session] = {}

    async def _serve_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        session = _Session(peer=str(peer))
        try:
            await self._serve(session, reader, writer)
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        except asyncio.CancelledError:
            pass
        except Exception:  # a broken client must not take the server down
            logger.exception("rtde client %s failed", session.peer)
        finally:
            await self._stop_stream(session)
            for name in session.owned:
                if self._owners.get(name) is session:
                    del self._owners[name]
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()

    async def _serve(
        self, session: _Session, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        while True:
            header = await reader.readexactly(HEADER.size)
            size, kind = HEADER.unpack(header)
            if size < HEADER.size:
                logger.warning("rtde %s: package size %d < header, closing", session.peer, size)
                return
            payload = await reader.readexactly(size - HEADER.size)
            reply = await self._handle(session, kind, payload, writer)
            if reply:
                writer.write(reply)
                await writer.drain()

    async def _handle(
        self, session: _Session, kind: int, payload: bytes, writer: asyncio.StreamWriter
    ) -> bytes:
        if kind == REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 0
            accepted = version == PROTOCOL_VERSION
            if accepted:
                session.version = version
            return pack(REQUEST_PROTOCOL_VERSION, bytes([int(accepted)]))
        if kind == GET_URCONTROL_VERSION:
            return pack(GET_URCONTROL_VERSION, struct.pack(">4I", *self.source.controller_version))
        if kind == CONTROL_PACKAGE_SETUP_OUTPUTS:
            return self._setup_outputs(session, payload)
        if kind == CONTROL_PACKAGE_SETUP_INPUTS:
            return self._setup_inputs(session, payload)
        if kind == CONTROL_PACKAGE_START:
            await self._stop_stream(session)
            if session.output is not None:
                session.streaming = asyncio.create_task(self._stream(session, writer))
            return pack(CONTROL_PACKAGE_START, b"\x01")
        if kind == CONTROL_PACKAGE_PAUSE:
            await self._stop_stream(session)
            return pack(CONTROL_PACKAGE_PAUSE, b"\x01")
        if kind == DATA_PACKAGE:
            self._apply(session, payload)
            return b""
        if kind == TEXT_MESSAGE:
            return b""
        logger.warning("rtde %s: unknown package type %d ignored", session.peer, kind)
        return b""

    def _setup_outputs(self, session: _Session, payload: bytes) -> bytes:
        if len(payload) < 8:
            return pack(CONTROL_PACKAGE_SETUP_OUTPUTS, b"\x00NOT_FOUND")
        frequency = struct.unpack(">d", payload[:8])[0]
        names = [n for n in payload[8:].decode(errors="replace").split(",") if n]
        types = [output_type(n) or "NOT_FOUND" for n in names]
        if "NOT_FOUND" in types:
            missing = [n for n, t in zip(names, types, strict=True) if t == "NOT_FOUND"]
            logger.warning("rtde %s: outputs not found: %s", session.peer, ", ".join(missing))
            recipe_id = 0
        else:
            session.output = _Recipe(names, types)
            session.frequency = frequency if frequency > 0 else 125.0
            recipe_id = 1
        return pack(CONTROL_PACKAGE_SETUP_OUTPUTS, bytes([recipe_id]) + ",".join(types).encode())

    def _setup_inputs(self, session: _Session, payload: bytes) -> bytes:
        names = [n for n in payload.decode(errors="replace").split(",") if n]
        types: list[str] = []
        for name in names:
            rtde_type = input_type(name)
            owner = self._owners.get(name)
            if rtde_type is None:
                types.append("NOT_FOUND")
            elif owner is not None and owner is not session:
                types.append("IN_USE")
            else:
                types.append(rtde_type)
        if not names or any(t in ("NOT_FOUND", "IN_USE") for t in types):
            logger.warning("rtde %s: input setup refused: %s", session.peer, ",".join(types))
            return pack(CONTROL_PACKAGE_SETUP_INPUTS, b"\x00" + ",".join(types).encode())
        recipe_id = len(session.inputs) + 1
        if recipe_id > 255:
            return pack(CONTROL_PACKAGE_SETUP_INPUTS, b"\x00" + ",".join(types).encode())
        session.inputs[recipe_id] = _Recipe(names, types)
        for name in names:
            self._owners[name] = session
            session.owned.add(name)
        return pack(CONTROL_PACKAGE_SETUP_INPUTS, bytes([recipe_id]) + ",".join(types).encode())

    def _apply(self, session: _Session, payload: bytes) -> None:
        if not payload:
            return
        recipe = session.inputs.get(payload[0])
        if recipe is None:
            logger.warning("rtde %s: data package for unknown recipe %d", session.peer, payload[0])
            return
        try:
            values = unpack_values(recipe.types, payload[1:])
        except (ValueError, struct.error) as exc:
            logger.warning("rtde %s: recipe %d: %s", session.peer, payload[0], exc)
            return
        self.source.apply_inputs(dict(zip(recipe.names, values, strict=True)))

    async def _stream(self, session: _Session, writer: asyncio.StreamWriter) -> None:
        recipe = session.output
        assert recipe is not None
        # one package every `every` controller cycles: each package is one cycle's state
        rate = min(session.frequency, self.max_stream_hz)
        every = max(1, round(CONTROLLER_HZ / rate))
        cycle = await self.source.next_cycle(-1)
        while not writer.is_closing():
            if cycle % every == 0 and writer.transport.get_write_buffer_size() < MAX_WRITE_BUFFER:
                values = self.source.output_values(recipe.names)
                writer.write(pack(DATA_PACKAGE, b"\x01" + pack_values(recipe.types, values)))
            cycle = await self.source.next_cycle(cycle)

    async def _stop_stream(self, session: _Session) -> None:
        task, session.streaming = session.streaming, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
