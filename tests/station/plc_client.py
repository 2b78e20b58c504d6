"""The PLC side of the station tests: the real pymodbus TCP client on the register map."""

from __future__ import annotations

import time

from pymodbus.client import ModbusTcpClient

from hostpc.station import registers as reg


class Plc:
    def __init__(self, port: int):
        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=5)
        assert self.client.connect(), f"no Modbus server on 127.0.0.1:{port}"

    def read(self) -> list[int]:
        reply = self.client.read_holding_registers(0, count=reg.N_REGISTERS)
        assert not reply.isError(), reply
        return list(reply.registers)

    def start(self, serial: str, model: str = "ur5e") -> None:
        assert not self.client.write_registers(
            reg.SERIAL, reg.encode_text(serial, reg.SERIAL_LENGTH)).isError()
        assert not self.client.write_registers(
            reg.MODEL, reg.encode_text(model, reg.MODEL_LENGTH)).isError()
        assert not self.client.write_register(reg.COMMAND, reg.Command.START).isError()

    def command(self, command: reg.Command) -> None:
        assert not self.client.write_register(reg.COMMAND, int(command)).isError()

    def wait_state(self, states: set[reg.State], timeout: float) -> list[int]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            values = self.read()
            if values[reg.COMMAND] == 0 and reg.State(values[reg.STATE]) in states:
                return values
            time.sleep(0.1)
        raise AssertionError(f"station not in {states} after {timeout} s: {self.read()[:14]}")

    def run(self, serial: str, timeout: float = 300) -> list[int]:
        """START robot `serial`; the registers once its run has finished."""
        self.start(serial)
        return self.wait_state({reg.State.PASS, reg.State.FAIL, reg.State.ERROR}, timeout)

    def close(self) -> None:
        self.client.close()


def run_one(port: int, serial: str, timeout: float = 300) -> list[int]:
    """A PLC connected to the station on `port` for one run of robot `serial`: the
    registers once it finished."""
    plc = Plc(port)
    try:
        return plc.run(serial, timeout)
    finally:
        plc.close()
