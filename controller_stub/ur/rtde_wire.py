"""The RTDE wire format (Universal Robots Real-Time Data Exchange, protocol version 2):
package framing, the named fields and their types, and the packing of recipe values.

Sans-IO: bytes in, values out; `rtde_server.RtdeServer` does the networking. As the
unmodified ur_rtde library (1.6) speaks it, all big-endian::

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
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from typing import Any

HEADER = struct.Struct(">HB")
PROTOCOL_VERSION = 2
MAX_PACKAGE_SIZE = 0xFFFF

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
