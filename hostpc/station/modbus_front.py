"""The Modbus TCP front of the station: whole frames, the right unit, register functions only.

Between the connection guard (`hostpc.serving.guard`) and pymodbus's request handler, one
`ModbusFront` per connection splits the byte stream into MBAP frames (`MbapSplitter`, sans
IO) and decides per frame, before pymodbus sees it:

- a frame for another unit id: answered with exception 0x0B (gateway target failed to
  respond), the answer a Modbus gateway gives; pymodbus 3.16 would raise a KeyError inside
  and log a 1.2 KB traceback per request;
- a coil or discrete write (FC 5, 15) or any function outside the register map's
  (FC 3, 4, 6, 16, 22, 23): exception 0x01 (illegal function), never acknowledged;
- a broken header (protocol id not 0, a length outside 2..254): the connection is closed;
- otherwise the frame goes to pymodbus, and the connection has completed a request (the
  guard counts it as serving, not silent).

Every refusal is logged at most once per `LOG_INTERVAL_S` per kind, with a count.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from dataclasses import dataclass

from pymodbus.transport import ModbusProtocol

from hostpc.serving.guard import GuardedConnection
from protocol.admission import LogBudget

MBAP_HEADER = 7  # transaction id, protocol id, length, unit id
MAX_PDU = 253
LOG_INTERVAL_S = 10.0
SERVED_FUNCTIONS = frozenset({3, 4, 6, 16, 22, 23})
"""Read holding/input registers, write single/multiple, mask write, read-write multiple."""
ILLEGAL_FUNCTION = 0x01
GATEWAY_TARGET_NO_RESPONSE = 0x0B


class MalformedFrameError(ValueError):
    """The peer broke MBAP framing: the connection cannot be resynchronised."""


@dataclass(frozen=True)
class MbapFrame:
    transaction: int
    unit: int
    function: int
    raw: bytes  # the whole frame, header included

    def exception(self, code: int) -> bytes:
        """The exception response to this request (MBAP header, function | 0x80, code)."""
        return struct.pack(">HHHBBB", self.transaction, 0, 3, self.unit,
                           (self.function | 0x80) & 0xFF, code)


class MbapSplitter:
    """Bytes in, whole MBAP frames out; holds at most one frame's bytes."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[MbapFrame]:
        """The frames completed by `data`; MalformedFrameError on a broken header."""
        self._buffer += data
        frames = []
        while len(self._buffer) >= MBAP_HEADER:
            transaction, protocol_id, length, unit = struct.unpack_from(">HHHB", self._buffer)
            if protocol_id != 0 or not 2 <= length <= MAX_PDU + 1:
                raise MalformedFrameError(f"protocol id {protocol_id}, length {length}")
            size = MBAP_HEADER - 1 + length
            if len(self._buffer) < size:
                break
            raw = bytes(self._buffer[:size])
            del self._buffer[:size]
            frames.append(MbapFrame(transaction, unit, raw[MBAP_HEADER], raw))
        return frames


class ModbusFront(asyncio.Protocol):
    """Filter one connection's frames for pymodbus's `handler` (see module docstring)."""

    def __init__(self, handler: ModbusProtocol, connection: GuardedConnection, unit: int,
                 logger: logging.Logger, log_budget: LogBudget) -> None:
        self.handler = handler
        self.connection = connection
        self.unit = unit
        self.logger = logger
        self.log_budget = log_budget
        self.splitter = MbapSplitter()
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.handler.connection_made(transport)

    def data_received(self, data: bytes) -> None:
        assert self.transport is not None
        try:
            frames = self.splitter.feed(data)
        except MalformedFrameError as exc:
            self._report("malformed", "Modbus peer %s sent a broken MBAP header (%s); closing",
                         self.connection.peer, exc)
            self.transport.abort()
            return
        for frame in frames:
            self.connection.request_done()
            if frame.unit != self.unit:
                self._report("unit", "Modbus request for unit %d from %s answered 'gateway "
                             "target failed to respond' (this station is unit %d)",
                             frame.unit, self.connection.peer, self.unit)
                self.transport.write(frame.exception(GATEWAY_TARGET_NO_RESPONSE))
            elif frame.function not in SERVED_FUNCTIONS:
                self._report("function", "Modbus function %d from %s refused (illegal "
                             "function: the station serves holding registers only)",
                             frame.function, self.connection.peer)
                self.transport.write(frame.exception(ILLEGAL_FUNCTION))
            else:
                self.handler.data_received(frame.raw)

    def eof_received(self) -> bool | None:
        self.handler.eof_received()
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        self.handler.connection_lost(exc)

    def pause_writing(self) -> None:
        self.handler.pause_writing()

    def resume_writing(self) -> None:
        self.handler.resume_writing()

    def _report(self, kind: str, message: str, *args: object) -> None:
        held = self.log_budget.admit(kind, asyncio.get_running_loop().time())
        if held is not None:
            self.logger.warning(message + (f" ({held} more since the last report)"
                                           if held else ""), *args)
