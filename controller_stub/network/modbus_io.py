"""The simulation's digital IO as a Modbus TCP server (pymodbus 3.16, SimDevice API).

Register map (UR-style: digital inputs start at address 0; device id: any)::

    discrete inputs (FC 2)    bit i   = digital input i              read only
    coils (FC 1, 5, 15)       bit i   = digital output i             read (/ write)
    input registers (FC 4)    0       = digital inputs as a bitmask (bit i = input i)
                              1       = digital outputs as a bitmask
    holding register (FC 3/6) 0       = digital outputs as a bitmask  read (/ write)

Modbus TCP has no authentication, so the server is read-only unless built with
`writable=True` (`controller-stub serve --modbus-writable`, or `server.modbus_writable` in
the scenario): a coil or holding-register write is otherwise answered with the Modbus
exception ILLEGAL_FUNCTION and changes nothing.

Values are read from the simulation on every request (a device `action` refreshes the
registers before pymodbus answers), and coil / holding-register writes go straight to
`sim.set_digital_output`. Uses pymodbus's current server API (`SimDevice` / `SimData`
with `ModbusTcpServer`), not the deprecated `ModbusServerContext` datastores.
"""

from __future__ import annotations

import logging

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from controller_stub.world.controller_state import SimulatedController

logger = logging.getLogger(__name__)

_READ_BITS = {1: "outputs", 2: "inputs"}
_WRITE_COILS = {5, 15}
_HOLDING = {3, 6, 16, 22, 23}


def _bits_to_registers(bits: list[bool], n_registers: int) -> list[int]:
    registers = [0] * n_registers
    for index, bit in enumerate(bits[: 16 * n_registers]):
        if bit:
            registers[index // 16] |= 1 << (index % 16)
    return registers


def _mask(bits: list[bool]) -> int:
    return sum(1 << i for i, bit in enumerate(bits[:16]) if bit)


class ModbusIoServer:
    """Serve `sim.digital_inputs()` / `sim.digital_outputs()` over Modbus TCP.

    sim: the Simulation (digital_inputs, digital_outputs, set_digital_output).
    n_io: number of digital lines mapped (default: len(sim.digital_inputs())).
    writable: accept coil / holding-register writes (default False: read-only).
    """

    def __init__(
        self,
        sim: SimulatedController,
        host: str = "127.0.0.1",
        port: int = 0,
        n_io: int | None = None,
        *,
        writable: bool = False,
    ):
        self.sim = sim
        self.writable = writable
        self.n_io = n_io if n_io is not None else len(sim.digital_inputs())
        self._n_bit_registers = (self.n_io + 15) // 16
        bits = [False] * (16 * self._n_bit_registers)
        device = SimDevice(
            id=0,
            simdata=(
                [SimData(0, values=bits, datatype=DataType.BITS)],  # coils
                [SimData(0, values=bits, datatype=DataType.BITS, readonly=True)],  # inputs
                [SimData(0, values=0, datatype=DataType.REGISTERS)],  # holding
                [SimData(0, count=2, values=0, datatype=DataType.REGISTERS, readonly=True)],
            ),
            action=self._action,
        )
        self._server = ModbusTcpServer(device, address=(host, port))

    async def start(self) -> tuple[str, int]:
        """Start listening; returns the bound (host, port)."""
        await self._server.serve_forever(background=True)
        host, port = self._server.transport.sockets[0].getsockname()[:2]  # type: ignore[attr-defined]
        logger.info("modbus listening on %s:%d", host, port)
        return host, port

    async def close(self) -> None:
        """Stop the server."""
        await self._server.shutdown()

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Refresh `registers` from the simulation, or apply a write to it."""
        is_write = function_code in _WRITE_COILS or (function_code in _HOLDING and set_values)
        if is_write and not self.writable:
            logger.warning("modbus write fc=%d refused: read-only server", function_code)
            return ExcCodes.ILLEGAL_FUNCTION
        try:
            inputs = [bool(v) for v in self.sim.digital_inputs()]
            outputs = [bool(v) for v in self.sim.digital_outputs()]
            if function_code in _READ_BITS:
                bits = outputs if _READ_BITS[function_code] == "outputs" else inputs
                registers[: self._n_bit_registers] = _bits_to_registers(bits, self._n_bit_registers)
            elif function_code == 4:
                registers[:2] = [_mask(inputs), _mask(outputs)]
            elif function_code in _WRITE_COILS and set_values is not None:
                if address + len(set_values) > self.n_io:
                    return ExcCodes.ILLEGAL_ADDRESS
                for offset, value in enumerate(set_values):
                    self.sim.set_digital_output(address + offset, bool(value))
            elif function_code in _HOLDING:
                if set_values:
                    mask = int(set_values[0])
                    for line in range(min(self.n_io, 16)):
                        self.sim.set_digital_output(line, bool(mask >> line & 1))
                else:
                    registers[:1] = [_mask(outputs)]
        except Exception:  # a failing simulation must not take the Modbus server down
            logger.exception("modbus request fc=%d address=%d failed", function_code, address)
            return ExcCodes.DEVICE_FAILURE
        return None
