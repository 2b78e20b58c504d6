"""Digital IO over Modbus TCP (pymodbus `AsyncModbusTcpClient`): triggers and station bits.

For cells whose triggers (a probe, a light barrier) and station bits (clamp closed, part
present, "calibration running") are wired to a controller or a PLC that serves Modbus TCP.
The register map is UR's (and the simulated controller's, `controller-stub serve
--modbus-port PORT`)::

    discrete inputs (FC 2)  address i = digital input i      (read)
    coils (FC 1 / 5)        address i = digital output i     (read / write)

A UR controller serves this on port 502 (its built-in Modbus TCP server: digital inputs at
address 0, outputs at address 16 on some PolyScope versions; pass `output_address`).
Polling is the only way to see an edge over Modbus: `wait_for_input` polls every `poll_s`
(default 5 ms), so an edge's time is known to that resolution; it is a trigger for a
station, not a position latch (the zerocal protocol's guarded move latches on the controller).

Errors: ConnectionFailed (cannot connect), RequestTimeout (no answer), ControllerError (a
Modbus exception reply, e.g. an illegal address).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException

from hostpc.errors import ConnectionFailed, ControllerError, InputError, RequestTimeout
from hostpc.transport.waiting import wait_for_reply

logger = logging.getLogger(__name__)

MODBUS_PORT = 502


class ModbusIo:
    """An open Modbus TCP connection to a controller's digital IO.

    n_inputs / n_outputs: lines mapped; input_address / output_address: first address of
    the discrete inputs / coils; device_id: Modbus unit id.
    """

    def __init__(
        self,
        client: AsyncModbusTcpClient,
        *,
        n_inputs: int = 8,
        n_outputs: int = 8,
        input_address: int = 0,
        output_address: int = 0,
        device_id: int = 1,
    ) -> None:
        self.client = client
        self.n_inputs = int(n_inputs)
        self.n_outputs = int(n_outputs)
        self.input_address = int(input_address)
        self.output_address = int(output_address)
        self.device_id = int(device_id)

    @classmethod
    async def connect(
        cls, host: str, port: int = MODBUS_PORT, *, timeout: float = 3.0, **options: Any
    ) -> ModbusIo:
        """Connect to `host:port`; ConnectionFailed if it cannot. options: see the class."""
        client = AsyncModbusTcpClient(host, port=port, timeout=timeout, retries=1)
        try:  # a cancel in the step the connection opens is not lost (transport.waiting)
            connected = await wait_for_reply(client.connect(), timeout + 1.0)
        except (TimeoutError, OSError, ConnectionException) as exc:
            client.close()
            raise ConnectionFailed(f"Modbus {host}:{port}: cannot connect: {exc}") from exc
        except asyncio.CancelledError:  # SIGTERM, Ctrl-C: the connection is not kept
            client.close()
            raise
        if not connected:
            client.close()
            raise ConnectionFailed(f"Modbus {host}:{port}: cannot connect")
        return cls(client, **options)

    async def close(self) -> None:
        """Close the connection."""
        self.client.close()

    async def __aenter__(self) -> ModbusIo:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def _request(self, what: str, call: Any) -> Any:
        try:
            response = await call
        except ConnectionException as exc:
            raise ConnectionFailed(f"Modbus {what}: connection lost: {exc}") from exc
        except TimeoutError as exc:
            raise RequestTimeout(f"Modbus {what}: no answer") from exc
        except ModbusException as exc:
            if "timeout" in str(exc).lower() or "no response" in str(exc).lower():
                raise RequestTimeout(f"Modbus {what}: {exc}") from exc
            raise ControllerError(f"Modbus {what}: {exc}") from exc
        if response.isError():
            raise ControllerError(f"Modbus {what}: exception reply {response}")
        return response

    async def read_inputs(self) -> tuple[bool, ...]:
        """Digital inputs 0..n_inputs-1 (discrete inputs)."""
        response = await self._request(
            f"read inputs @{self.input_address}",
            self.client.read_discrete_inputs(
                self.input_address, count=self.n_inputs, device_id=self.device_id
            ),
        )
        return tuple(bool(b) for b in response.bits[: self.n_inputs])

    async def read_outputs(self) -> tuple[bool, ...]:
        """Digital outputs 0..n_outputs-1 (coils)."""
        response = await self._request(
            f"read outputs @{self.output_address}",
            self.client.read_coils(
                self.output_address, count=self.n_outputs, device_id=self.device_id
            ),
        )
        return tuple(bool(b) for b in response.bits[: self.n_outputs])

    async def read_input(self, line: int) -> bool:
        """One digital input."""
        self._check(line, self.n_inputs, "input")
        return (await self.read_inputs())[line]

    async def write_output(self, line: int, value: bool) -> None:
        """Set digital output `line` (a station bit) to `value`."""
        self._check(line, self.n_outputs, "output")
        await self._request(
            f"write output {line}",
            self.client.write_coil(self.output_address + line, bool(value),
                                   device_id=self.device_id),
        )

    set_station_bit = write_output

    async def wait_for_input(
        self, line: int, value: bool = True, *, timeout: float = 10.0, poll_s: float = 0.005
    ) -> float:
        """Wait until input `line` reads `value` (a trigger); returns the seconds waited.

        An edge is seen only if the level lasts longer than `poll_s`. RequestTimeout if it
        does not come within `timeout`.
        """
        self._check(line, self.n_inputs, "input")
        loop = asyncio.get_running_loop()
        start = loop.time()
        while True:
            if (await self.read_inputs())[line] == bool(value):
                return loop.time() - start
            if loop.time() - start > timeout:
                raise RequestTimeout(
                    f"Modbus input {line} did not become {bool(value)} within {timeout:.1f} s"
                )
            await asyncio.sleep(poll_s)

    async def wait_for_edge(
        self, line: int, rising: bool = True, *, timeout: float = 10.0, poll_s: float = 0.005
    ) -> float:
        """Wait for an edge on input `line` (first the opposite level, then the level);
        returns the seconds waited in total."""
        loop = asyncio.get_running_loop()
        start = loop.time()
        await self.wait_for_input(line, not rising, timeout=timeout, poll_s=poll_s)
        remaining = max(0.0, timeout - (loop.time() - start))
        await self.wait_for_input(line, rising, timeout=remaining, poll_s=poll_s)
        return loop.time() - start

    @staticmethod
    def _check(line: int, count: int, kind: str) -> None:
        if not 0 <= int(line) < count:
            raise InputError(f"Modbus {kind} line {line}: expected 0..{count - 1}")
