"""The UR controller's register banks and the settings a client writes through RTDE.

One `UrRegisters` per UR personality, shared by its RTDE face (`rtde_values.py`: clients
read and write them), the emulated control script (`control_script.py`: its command and
result registers) and generic programs (`personality.py`: write_output_integer_register).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from controller_stub.ur.rtde_wire import N_REGISTERS


@dataclass
class UrRegisters:
    """Registers (int and double, input and output, N_REGISTERS each), the 64 input and
    output bit registers as integers, the speed slider (fraction 0..1), the two standard
    analog outputs and the tool digital outputs (bit mask)."""

    input_int: list[int] = field(default_factory=lambda: [0] * N_REGISTERS)
    input_double: list[float] = field(default_factory=lambda: [0.0] * N_REGISTERS)
    output_int: list[int] = field(default_factory=lambda: [0] * N_REGISTERS)
    output_double: list[float] = field(default_factory=lambda: [0.0] * N_REGISTERS)
    input_bits: int = 0
    output_bits: int = 0
    speed_slider: float = 1.0
    standard_analog_output: list[float] = field(default_factory=lambda: [0.0, 0.0])
    tool_outputs: int = 0
