"""What every server of the host application shares against hostile peers: the guarded
listener of the token-less ports (Modbus, HTTP) and rate-limited, traceback-free logging.
The policies themselves live in `protocol.admission` and `protocol.connection_table`."""
