"""The end-of-line station: a long-running service for one cell that a PLC drives over
Modbus TCP, calibrating robot after robot and archiving every result (docs/station.md).

`registers` is the register map (pure), `config` the station config file, `plc` the
Modbus TCP server, `runner` one calibration as a child process, `service` the state
machine tying them together, `web` the read-only live page.
"""
