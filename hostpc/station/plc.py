"""The station's register map served over Modbus TCP (pymodbus 3.16 SimDevice API).

The station owns the register values (`self.values`); every request is answered from them
through the device's action hook, and a PLC write is accepted only on the PLC-writable
registers (COMMAND, SERIAL, MODEL), else answered ILLEGAL_ADDRESS. Modbus TCP has no
authentication: bind it to the cell network's interface only (default 127.0.0.1).

Against hostile peers (docs/security.md): the station, not pymodbus, listens. A
`ConnectionGuard` caps the connections (`max_connections` in all, `max_per_address` per
peer address; a newcomer evicts a silent connection first, then the longest idle, so a PLC
that polls always gets in) and closes a connection that completes no request within
`first_request_timeout_s` or none for `idle_timeout_s`; a `ModbusFront` per connection
hands pymodbus whole frames for this unit and register functions only (wrong unit:
exception 0x0B; coils and anything else: illegal function). pymodbus's request handler is
created through its own protocol factory (`handle_new_connection`) and driven through the
asyncio protocol contract; nothing of it is patched. Why not pymodbus's listener: it has no
connection cap or hook before accepting, and a per-connection protocol in front of its
handler is the one seam that keeps the cap, the deadlines and the frame filter out of its
code. pymodbus's own log is rate-limited and cut to one line per record.
"""

from __future__ import annotations

import asyncio
import logging

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hostpc.serving.guard import ConnectionGuard, GuardedConnection
from hostpc.serving.log_limits import limit_logging
from hostpc.station.modbus_front import LOG_INTERVAL_S, ModbusFront
from hostpc.station.registers import N_REGISTERS, PLC_WRITABLE
from protocol.admission import LogBudget
from protocol.connection_table import ConnectionTable

logger = logging.getLogger("hostpc.station.plc")
_WRITE_CODES = {6, 16, 22, 23}
_COIL_WRITE_CODES = {5, 15}

MAX_CONNECTIONS = 32
"""Modbus connections held at most (a cell has a PLC, perhaps an HMI and a SCADA poller)."""
MAX_PER_ADDRESS = 16
FIRST_REQUEST_TIMEOUT_S = 10.0
"""A connection that completes no request this long after connecting is closed (s)."""
IDLE_TIMEOUT_S = 120.0
"""A connection without a request for this long is closed (s); a PLC that polls less
often reconnects (pymodbus and PLC Modbus clients do so by themselves)."""


class PlcServer:
    """Holding registers 0..N_REGISTERS-1; `values` is the live register image."""

    def __init__(self, host: str = "127.0.0.1", port: int = 5020, device_id: int = 1, *,
                 max_connections: int = MAX_CONNECTIONS,
                 max_per_address: int = MAX_PER_ADDRESS,
                 first_request_timeout_s: float = FIRST_REQUEST_TIMEOUT_S,
                 idle_timeout_s: float = IDLE_TIMEOUT_S):
        self.values = [0] * N_REGISTERS
        self.host, self.port, self.device_id = host, port, device_id
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
        # never listens itself: it only builds the request handler of each connection
        self._server = ModbusTcpServer(device, address=(host, port))
        self._front_log = LogBudget(interval_s=LOG_INTERVAL_S)
        self.guard = ConnectionGuard(
            "Modbus",
            ConnectionTable(max_connections, max_per_address, first_request_timeout_s,
                            idle_timeout_s),
            self._front, logger)
        limit_logging("pymodbus.logging", "hostpc.station.plc")

    async def start(self) -> tuple[str, int]:
        return await self.guard.listen(self.host, self.port)

    async def close(self) -> None:
        await self.guard.close()
        await self._server.shutdown()

    def _front(self, connection: GuardedConnection) -> asyncio.Protocol:
        handler = self._server.handle_new_connection()
        return ModbusFront(handler, connection, self.device_id, logger, self._front_log)

    def set(self, address: int, value: int) -> None:
        self.values[address] = int(value) & 0xFFFF

    def set_many(self, values: dict[int, int]) -> None:
        for address, value in values.items():
            self.set(address, value)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None
                      ) -> ExcCodes | None:
        if function_code in _COIL_WRITE_CODES:  # the front refuses them first; never ack
            return ExcCodes.ILLEGAL_FUNCTION
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
