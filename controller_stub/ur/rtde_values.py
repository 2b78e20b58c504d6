"""The RTDE face of the UR personality: the values its outputs show and what its inputs do.

`RtdeValues` is the RTDE data source of `personality.UrPersonality`: it holds the
personality's register banks (`registers.UrRegisters`) and asks the personality, through the
`RtdeRobot` interface, for the displayed state (angles, inputs, program, stops, the
controller cycle). Outputs are read by name for one controller cycle (`output_values`); a
client's input data package is applied by
`apply_inputs`: registers, bit registers, standard / configurable / tool digital outputs,
the speed slider and the standard analog outputs (docs/robots.md has the table).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from controller_stub.ur.registers import UrRegisters
from controller_stub.ur.rtde_wire import output_type, register_field
from controller_stub.world.controller_state import SimulatedController

RUNTIME_STOPPED, RUNTIME_PLAYING = 1, 2
ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL, SAFETY_MODE_PROTECTIVE_STOP, SAFETY_MODE_ROBOT_EMERGENCY_STOP = 1, 3, 7
JOINT_MODE_RUNNING = 253
SAFETY_BIT_NORMAL, SAFETY_BIT_PROTECTIVE_STOPPED, SAFETY_BIT_EMERGENCY_STOPPED = 0, 2, 7
STATUS_BIT_POWER_ON, STATUS_BIT_PROGRAM_RUNNING = 0, 1

_ZEROS = {"DOUBLE": 0.0, "UINT64": 0, "UINT32": 0, "INT32": 0, "UINT8": 0, "BOOL": False}


def _zero(rtde_type: str) -> Any:
    if rtde_type in _ZEROS:
        return _ZEROS[rtde_type]
    width = 3 if rtde_type == "VECTOR3D" else 6
    return (0.0 if rtde_type.endswith("D") else 0,) * width


def _mask(bits: list[bool]) -> int:
    return sum(1 << i for i, bit in enumerate(bits) if bit)


class RtdeRobot(Protocol):
    """What the RTDE face reads of the UR personality: its simulation, its controller cycle
    and the state it displays for that cycle."""

    @property
    def sim(self) -> SimulatedController: ...
    @property
    def cycle(self) -> int: ...
    @property
    def uptime(self) -> float: ...
    @property
    def controller_version(self) -> tuple[int, int, int, int]: ...
    async def next_cycle(self, after: int) -> int: ...
    def displayed_q(self) -> np.ndarray: ...
    def displayed_qd(self) -> np.ndarray: ...
    def displayed_inputs(self) -> list[bool]: ...
    def program_running(self) -> bool: ...
    def emergency_stopped(self) -> bool: ...
    def protective_stopped(self) -> bool: ...
    def tcp_pose(self, q: np.ndarray | None = None) -> list[float]: ...


class RtdeValues:
    """output_values / apply_inputs for the RTDE server (its `RtdeDataSource`).

    robot: the UR personality (`RtdeRobot`); registers: its register banks, which the
    inputs write and the outputs show.
    """

    def __init__(self, robot: RtdeRobot, registers: UrRegisters) -> None:
        self.robot = robot
        self.registers = registers

    @property
    def controller_version(self) -> tuple[int, int, int, int]:
        """The controller version the personality reports."""
        return self.robot.controller_version

    async def next_cycle(self, after: int) -> int:
        """Wait until the personality's controller cycle is past `after`; returns it."""
        return await self.robot.next_cycle(after)

    def output_values(self, names: Sequence[str]) -> list[Any]:
        """Current values of the named RTDE outputs (see rtde_server.OUTPUT_TYPES)."""
        q = self.robot.displayed_q()  # one controller cycle for the whole package
        return [self._output(name, q) for name in names]

    def _output(self, name: str, q: np.ndarray) -> Any:
        reg = self.registers
        robot = self.robot
        if name in ("actual_q", "target_q"):
            return tuple(q.tolist())
        if name in ("actual_qd", "target_qd"):
            return tuple(robot.displayed_qd().tolist())
        if name == "timestamp":
            return robot.uptime
        if name == "actual_digital_input_bits":
            return _mask(robot.displayed_inputs())
        if name == "actual_digital_output_bits":
            return _mask(robot.sim.digital_outputs()) | (reg.tool_outputs & 0x3) << 16
        if name == "runtime_state":
            return RUNTIME_PLAYING if robot.program_running() else RUNTIME_STOPPED
        if name == "robot_status_bits":
            running = robot.program_running()
            return 1 << STATUS_BIT_POWER_ON | (1 << STATUS_BIT_PROGRAM_RUNNING if running else 0)
        if name == "safety_status_bits":
            if robot.emergency_stopped():
                return 1 << SAFETY_BIT_EMERGENCY_STOPPED
            if robot.protective_stopped():
                return 1 << SAFETY_BIT_PROTECTIVE_STOPPED
            return 1 << SAFETY_BIT_NORMAL
        if name in ("safety_mode", "safety_status"):
            if robot.emergency_stopped():
                return SAFETY_MODE_ROBOT_EMERGENCY_STOP
            return SAFETY_MODE_PROTECTIVE_STOP if robot.protective_stopped() else SAFETY_MODE_NORMAL
        if name == "robot_mode":
            return ROBOT_MODE_RUNNING
        if name == "joint_mode":
            return (JOINT_MODE_RUNNING,) * 6
        if name in ("actual_TCP_pose", "target_TCP_pose"):
            return tuple(robot.tcp_pose(q))
        if name in ("speed_scaling", "target_speed_fraction"):
            return reg.speed_slider
        if name == "joint_temperatures":
            return (30.0,) * 6
        if name in ("actual_main_voltage", "actual_robot_voltage"):
            return 48.0
        if name == "actual_joint_voltage":
            return (48.0,) * 6
        if name == "actual_tool_accelerometer":
            return (0.0, 0.0, 9.81)
        if name in ("standard_analog_output0", "standard_analog_output1"):
            return reg.standard_analog_output[int(name[-1])]
        if name == "actual_execution_time":
            return 0.2
        if name == "output_bit_registers0_to_31":
            return reg.output_bits & 0xFFFFFFFF
        if name == "output_bit_registers32_to_63":
            return reg.output_bits >> 32 & 0xFFFFFFFF
        if name == "input_bit_registers0_to_31":
            return reg.input_bits & 0xFFFFFFFF
        if name == "input_bit_registers32_to_63":
            return reg.input_bits >> 32 & 0xFFFFFFFF
        register = register_field(name)
        if register is not None:
            direction, kind, index = register
            if kind == "int":
                return (reg.input_int if direction == "input" else reg.output_int)[index]
            if kind == "double":
                return (reg.input_double if direction == "input" else reg.output_double)[index]
            bits = reg.input_bits if direction == "input" else reg.output_bits
            return bool(bits >> index & 1)
        rtde_type = output_type(name)
        return _zero(rtde_type) if rtde_type else 0

    def apply_inputs(self, values: dict[str, Any]) -> None:
        """Apply one RTDE input data package (name -> value)."""
        reg = self.registers
        for name, value in values.items():
            register = register_field(name)
            if register is not None:
                _, kind, index = register
                if kind == "int":
                    reg.input_int[index] = int(value)
                elif kind == "double":
                    reg.input_double[index] = float(value)
                else:
                    bit = 1 << index
                    reg.input_bits = reg.input_bits | bit if value else reg.input_bits & ~bit
            elif name == "input_bit_registers0_to_31":
                reg.input_bits = (reg.input_bits & ~0xFFFFFFFF) | int(value)
            elif name == "input_bit_registers32_to_63":
                reg.input_bits = (reg.input_bits & 0xFFFFFFFF) | int(value) << 32
        self._apply_io(values)

    def _apply_io(self, values: dict[str, Any]) -> None:
        reg = self.registers
        robot = self.robot
        n_io = len(robot.sim.digital_outputs())
        for prefix, first_line in (("standard", 0), ("configurable", 8)):
            mask = int(values.get(f"{prefix}_digital_output_mask", 0))
            if not mask:
                continue
            levels = int(values.get(f"{prefix}_digital_output", 0))
            for bit in range(8):
                if mask >> bit & 1 and first_line + bit < n_io:
                    robot.sim.set_digital_output(first_line + bit, bool(levels >> bit & 1))
        tool_mask = int(values.get("tool_digital_output_mask", 0))
        if tool_mask:
            levels = int(values.get("tool_digital_output", 0))
            reg.tool_outputs = (reg.tool_outputs & ~tool_mask) | (levels & tool_mask)
        if int(values.get("speed_slider_mask", 0)) & 1:
            reg.speed_slider = float(np.clip(values.get("speed_slider_fraction", 1.0), 0.0, 1.0))
        analog_mask = int(values.get("standard_analog_output_mask", 0))
        for k in range(2):
            if analog_mask >> k & 1:
                reg.standard_analog_output[k] = float(values.get(f"standard_analog_output_{k}",
                                                                  0.0))
