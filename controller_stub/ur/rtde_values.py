"""The RTDE face of the UR personality: the values its outputs show and what its inputs do.

Part of `personality.UrPersonality` (a mixin; the personality provides the simulation, the
controller cycle, the register banks and the displayed state). Outputs are read by name for
one controller cycle (`output_values`); a client's input data package is applied by
`apply_inputs`: registers, bit registers, standard / configurable / tool digital outputs,
the speed slider and the standard analog outputs (docs/robots.md has the table).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from controller_stub.ur.paced_motion import CYCLE_S
from controller_stub.ur.rtde_wire import output_type, register_field
from controller_stub.world.simulation import Simulation

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


class UrRtdeValuesMixin:
    """output_values / apply_inputs of `UrPersonality` (the RTDE data source)."""

    sim: Simulation
    cycle: int
    input_int: list[int]
    input_double: list[float]
    output_int: list[int]
    output_double: list[float]
    input_bits: int
    output_bits: int
    speed_slider: float
    standard_analog_output: list[float]
    tool_outputs: int
    _protective_stop: bool

    if TYPE_CHECKING:  # provided by UrPersonality

        def displayed_q(self) -> np.ndarray: ...
        def displayed_qd(self) -> np.ndarray: ...
        def displayed_inputs(self) -> list[bool]: ...
        def program_running(self) -> bool: ...
        def emergency_stopped(self) -> bool: ...
        def tcp_pose(self, q: np.ndarray | None = None) -> list[float]: ...

    def output_values(self, names: Sequence[str]) -> list[Any]:
        """Current values of the named RTDE outputs (see rtde_server.OUTPUT_TYPES)."""
        q = self.displayed_q()  # one controller cycle for the whole package
        return [self._output(name, q) for name in names]

    def _output(self, name: str, q: np.ndarray) -> Any:
        if name in ("actual_q", "target_q"):
            return tuple(q.tolist())
        if name in ("actual_qd", "target_qd"):
            return tuple(self.displayed_qd().tolist())
        if name == "timestamp":
            return self.cycle * CYCLE_S
        if name == "actual_digital_input_bits":
            return _mask(self.displayed_inputs())
        if name == "actual_digital_output_bits":
            return _mask(self.sim.digital_outputs()) | (self.tool_outputs & 0x3) << 16
        if name == "runtime_state":
            return RUNTIME_PLAYING if self.program_running() else RUNTIME_STOPPED
        if name == "robot_status_bits":
            running = self.program_running()
            return 1 << STATUS_BIT_POWER_ON | (1 << STATUS_BIT_PROGRAM_RUNNING if running else 0)
        if name == "safety_status_bits":
            if self.emergency_stopped():
                return 1 << SAFETY_BIT_EMERGENCY_STOPPED
            if self._protective_stop:
                return 1 << SAFETY_BIT_PROTECTIVE_STOPPED
            return 1 << SAFETY_BIT_NORMAL
        if name in ("safety_mode", "safety_status"):
            if self.emergency_stopped():
                return SAFETY_MODE_ROBOT_EMERGENCY_STOP
            return SAFETY_MODE_PROTECTIVE_STOP if self._protective_stop else SAFETY_MODE_NORMAL
        if name == "robot_mode":
            return ROBOT_MODE_RUNNING
        if name == "joint_mode":
            return (JOINT_MODE_RUNNING,) * 6
        if name in ("actual_TCP_pose", "target_TCP_pose"):
            return tuple(self.tcp_pose(q))
        if name in ("speed_scaling", "target_speed_fraction"):
            return self.speed_slider
        if name == "joint_temperatures":
            return (30.0,) * 6
        if name in ("actual_main_voltage", "actual_robot_voltage"):
            return 48.0
        if name == "actual_joint_voltage":
            return (48.0,) * 6
        if name == "actual_tool_accelerometer":
            return (0.0, 0.0, 9.81)
        if name in ("standard_analog_output0", "standard_analog_output1"):
            return self.standard_analog_output[int(name[-1])]
        if name == "actual_execution_time":
            return 0.2
        if name == "output_bit_registers0_to_31":
            return self.output_bits & 0xFFFFFFFF
        if name == "output_bit_registers32_to_63":
            return self.output_bits >> 32 & 0xFFFFFFFF
        if name == "input_bit_registers0_to_31":
            return self.input_bits & 0xFFFFFFFF
        if name == "input_bit_registers32_to_63":
            return self.input_bits >> 32 & 0xFFFFFFFF
        register = register_field(name)
        if register is not None:
            direction, kind, index = register
            if kind == "int":
                return (self.input_int if direction == "input" else self.output_int)[index]
            if kind == "double":
                return (self.input_double if direction == "input" else self.output_double)[index]
            bits = self.input_bits if direction == "input" else self.output_bits
            return bool(bits >> index & 1)
        rtde_type = output_type(name)
        return _zero(rtde_type) if rtde_type else 0

    def apply_inputs(self, values: dict[str, Any]) -> None:
        """Apply one RTDE input data package (name -> value)."""
        for name, value in values.items():
            register = register_field(name)
            if register is not None:
                _, kind, index = register
                if kind == "int":
                    self.input_int[index] = int(value)
                elif kind == "double":
                    self.input_double[index] = float(value)
                else:
                    bit = 1 << index
                    self.input_bits = self.input_bits | bit if value else self.input_bits & ~bit
            elif name == "input_bit_registers0_to_31":
                self.input_bits = (self.input_bits & ~0xFFFFFFFF) | int(value)
            elif name == "input_bit_registers32_to_63":
                self.input_bits = (self.input_bits & 0xFFFFFFFF) | int(value) << 32
        self._apply_io(values)

    def _apply_io(self, values: dict[str, Any]) -> None:
        n_io = len(self.sim.digital_outputs())
        for prefix, first_line in (("standard", 0), ("configurable", 8)):
            mask = int(values.get(f"{prefix}_digital_output_mask", 0))
            if not mask:
                continue
            levels = int(values.get(f"{prefix}_digital_output", 0))
            for bit in range(8):
                if mask >> bit & 1 and first_line + bit < n_io:
                    self.sim.set_digital_output(first_line + bit, bool(levels >> bit & 1))
        tool_mask = int(values.get("tool_digital_output_mask", 0))
        if tool_mask:
            levels = int(values.get("tool_digital_output", 0))
            self.tool_outputs = (self.tool_outputs & ~tool_mask) | (levels & tool_mask)
        if int(values.get("speed_slider_mask", 0)) & 1:
            self.speed_slider = float(np.clip(values.get("speed_slider_fraction", 1.0), 0.0, 1.0))
        analog_mask = int(values.get("standard_analog_output_mask", 0))
        for k in range(2):
            if analog_mask >> k & 1:
                self.standard_analog_output[k] = float(values.get(f"standard_analog_output_{k}",
                                                                  0.0))
