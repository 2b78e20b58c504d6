"""The station's register map served over Modbus TCP (pymodbus 3.16 SimDevice API).

The station owns the register values (`self.values`); every request is answered from them
through the device's action hook, and a PLC write is accepted only on the PLC-writable
registers (COMMAND, SERIAL, MODEL), else answered ILLEGAL_ADDRESS. Modbus TCP has no
authentication: bind it to the cell network's interface only (default 127.0.0.1).
"""

from __future__ import annotations

import logging

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hostpc.station.registers import N_REGISTERS, PLC_WRITABLE

logger = logging.getLogger("hostpc.station.plc")
_WRITE_CODES = {6, 16, 22, 23}


class PlcServer:
    """Holding registers 0..N_REGISTERS-1; `values` is the live register image."""

    def __init__(self, host: str = "127.0.0.1", port: int = 5020, device_id: int = 1):
        self.values = [0] * N_REGISTERS
        device = SimDevice(
            id=device_id,
            simdata=(
                [SimData(0, values=False, datatype=DataType.BITS)],
                [SimData(0, values=False, datatype=DataType.BITS, readonly=True)],
                [SimData(0, count=N_REGISTERS, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, values=0, datatype=DataType.REGISTERS, readonly=True)],
            ),
            action=self._action,
        )
        self._server = ModbusTcpServer(device, address=(host, port))

    async def start(self) -> tuple[str, int]:
        await self._server.serve_forever(background=True)
        host, port = self._server.transport.sockets[0].getsockname()[:2]  # type: ignore[attr-defined]
        logger.info("PLC registers on %s:%d", host, port)
        return str(host), int(port)

    async def close(self) -> None:
        await self._server.shutdown()

    def set(self, address: int, value: int) -> None:
        self.values[address] = int(value) & 0xFFFF

    def set_many(self, values: dict[int, int]) -> None:
        for address, value in values.items():
            self.set(address, value)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None
                      ) -> ExcCodes | None:
        if function_code in _WRITE_CODES and set_values:
            targets = range(address, address + len(set_values))
            if any(t not in PLC_WRITABLE for t in targets):
                logger.warning("PLC write to read-only register %d..%d refused",
                               address, address + len(set_values) - 1)
                return ExcCodes.ILLEGAL_ADDRESS
            for target, value in zip(targets, set_values, strict=True):
                self.values[target] = int(value) & 0xFFFF
        registers[:N_REGISTERS] = self.values
        return None
