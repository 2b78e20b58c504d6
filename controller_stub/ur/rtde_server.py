"""The RTDE protocol (Universal Robots Real-Time Data Exchange, protocol version 2) on 30004.

Wire format, as the unmodified ur_rtde library (1.6) speaks it, all big-endian::

    package   = uint16 size (header included) | uint8 type | payload
    'V' (86)  request protocol version: uint16 version      -> 'V' uint8 accepted
    'v' (118) get controller version                        -> 'v' uint32 major, minor,
                                                                bugfix, build
    'O' (79)  output setup: double frequency, "name,name,.." -> 'O' uint8 recipe id,
                                                                "TYPE,TYPE,.." (NOT_FOUND)
    'I' (73)  input setup: "name,name,.."                  -> 'I' uint8 recipe id,
                                                                "TYPE,TYPE,.." (NOT_FOUND,
                                                                IN_USE)
    'S' (83)  start                                         -> 'S' uint8 success
    'P' (80)  pause                                         -> 'P' uint8 success
    'U' (85)  data package: uint8 recipe id, the recipe's fields back to back; the server
              streams the output recipe after 'S', the client writes input recipes
    'M' (77)  text message (server -> client: uint8 length, text, uint8 length, source,
              uint8 level); messages from the client are ignored

Field types and their widths (`TYPE_FORMATS`): DOUBLE 8, UINT64 8, UINT32 4, INT32 4,
UINT8 1, BOOL 1, VECTOR3D 24, VECTOR6D 48, VECTOR6INT32 24, VECTOR6UINT32 24. ur_rtde parses
a data package by ITS OWN name -> type table, so the types below follow UR's RTDE guide and
ur_rtde's `RobotState::state_types_` (e.g. `payload_cog` and `actual_tool_accelerometer` are
VECTOR3D, `joint_mode` VECTOR6INT32).

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
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from controller_stub.ur.tcp_service import TcpService

logger = logging.getLogger(__name__)

HEADER = struct.Struct(">HB")
PROTOCOL_VERSION = 2
MAX_PACKAGE_SIZE = 0xFFFF
MAX_WRITE_BUFFER = 1 << 20

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
CONTROL_PACKAGE_START = ord("S")
CONTROL_PACKAGE_PAUSE = ord("P")

TYPE_FORMATS: dict[str, str] = {
    "DOUBLE": "d",
    "UINT64": "Q",
    "UINT32": "I",
    "INT32": "i",
    "UINT8": "B",
    "BOOL": "?",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
"""RTDE type name -> struct format (big-endian, no padding)."""

_VECTOR_WIDTHS = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}
_VECTOR_TYPES = set(_VECTOR_WIDTHS)

OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "actual_current_window": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "euromap67_input_bits": "UINT32",
    "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE",
    "euromap67_24V_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "script_control_line": "UINT32",
    "ft_raw_wrench": "VECTOR6D",
    "joint_position_deviation_ratio": "DOUBLE",
    "collision_detection_ratio": "DOUBLE",
    "time_scale_source": "UINT32",
}
"""Named RTDE outputs (controller -> client) and their types."""

INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}
"""Named RTDE inputs (client -> controller) and their types."""

N_REGISTERS = 48
_REGISTER = re.compile(r"^(input|output)_(int|double|bit)_register_(\d+)$")


def register_field(name: str) -> tuple[str, str, int] | None:
    """`input_int_register_7` -> ("input", "int", 7); None if `name` is no register."""
    match = _REGISTER.match(name)
    if match is None:
        return None
    direction, kind, index_text = match.groups()
    index = int(index_text)
    if kind == "bit":
        return (direction, kind, index) if 64 <= index <= 127 else None
    return (direction, kind, index) if index < N_REGISTERS else None


def _register_type(kind: str) -> str:
    return {"int": "INT32", "double": "DOUBLE", "bit": "BOOL"}[kind]


def output_type(name: str) -> str | None:
    """RTDE type of output `name` (a register of either direction may be read), or None."""
    if name in OUTPUT_TYPES:
        return OUTPUT_TYPES[name]
    register = register_field(name)
    return _register_type(register[1]) if register else None


def input_type(name: str) -> str | None:
    """RTDE type of input `name` (only input registers may be written), or None."""
    if name in INPUT_TYPES:
        return INPUT_TYPES[name]
    register = register_field(name)
    if register is None or register[0] != "input":
        return None
    return _register_type(register[1])


def pack(kind: int, payload: bytes = b"") -> bytes:
    """One RTDE package: 3-byte header (uint16 size incl. header, uint8 type) + payload."""
    size = HEADER.size + len(payload)
    if size > MAX_PACKAGE_SIZE:
        raise ValueError(f"RTDE package of {size} bytes exceeds {MAX_PACKAGE_SIZE}")
    return HEADER.pack(size, kind) + payload


def pack_values(types: Sequence[str], values: Sequence[Any]) -> bytes:
    """Pack `values` (scalars or sequences for the vector types) in `types` order."""
    parts: list[bytes] = []
    for rtde_type, value in zip(types, values, strict=True):
        fmt = ">" + TYPE_FORMATS[rtde_type]
        if rtde_type in _VECTOR_TYPES:
            parts.append(struct.pack(fmt, *value))
        else:
            parts.append(struct.pack(fmt, value))
    return b"".join(parts)


def unpack_values(types: Sequence[str], data: bytes) -> list[Any]:
    """Unpack `data` laid out as `types` (vectors become tuples). ValueError on a size
    mismatch."""
    fmt = ">" + "".join(TYPE_FORMATS[t] for t in types)
    expected = struct.calcsize(fmt)
    if len(data) != expected:
        raise ValueError(f"data package of {len(data)} bytes, recipe needs {expected}")
    flat = struct.unpack(fmt, data)
    values: list[Any] = []
    position = 0
    for rtde_type in types:
        width = _VECTOR_WIDTHS.get(rtde_type, 1)
        chunk = flat[position : position + width]
        values.append(tuple(chunk) if rtde_type in _VECTOR_TYPES else chunk[0])
        position += width
    return values


def text_message(text: str, source: str = "controller-stub", level: int = 1) -> bytes:
    """A protocol-2 text message package ('M'): message, source, warning level."""
    message = text.encode()[:255]
    origin = source.encode()[:255]
    payload = bytes([len(message)]) + message + bytes([len(origin)]) + origin + bytes([level])
    return pack(TEXT_MESSAGE, payload)


class RtdeDataSource(Protocol):
    """What the RTDE server needs from the robot behind it."""

    controller_version: tuple[int, int, int, int]

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
