"""The stub's network face: the asyncio zerocal-protocol server, its sessions and request
handlers, and the digital IO as a Modbus TCP server. A thin shell around one simulation
(`controller_stub.world`)."""
