"""A "UR" that accepts connections and never answers must not freeze hostpc.

ur_rtde's constructors hold the GIL while they wait, so connecting them to a silent peer
would freeze the interpreter. hostpc's UR connect first sends an RTDE protocol-version
request with asyncio under a timeout and fails with ConnectionFailed before any ur_rtde
interface is constructed. The silent peer is a plain socket server in a thread on the fixed
RTDE port 30004 (no UR stub may run at the same time).
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from hostpc.errors import ConnectionFailed
from hostpc.robots import ur
from tests.integration.ur_stub import port_in_use


@pytest.fixture
def silent_peer() -> Iterator[list[socket.socket]]:
    """Accept on 127.0.0.1:30004, keep every connection open, never send a byte."""
    if port_in_use(30004):
        pytest.fail("port 30004 is in use (a UR stub still running?)")
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 30004))
    server.listen(8)
    server.settimeout(0.1)
    accepted: list[socket.socket] = []
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                connection, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            accepted.append(connection)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield accepted
    stop.set()
    thread.join(timeout=5)
    for connection in accepted:
        connection.close()
    server.close()


async def test_silent_rtde_peer_times_out_without_freezing(
    silent_peer: list[socket.socket], monkeypatch: pytest.MonkeyPatch
) -> None:
    constructed: list[str] = []

    def forbidden(name: str) -> object:
        def construct(*args: object, **kwargs: object) -> None:
            constructed.append(name)
            raise AssertionError(f"{name} constructed before the peer answered")

        return construct

    import rtde_control
    import rtde_io
    import rtde_receive

    monkeypatch.setattr(rtde_receive, "RTDEReceiveInterface", forbidden("receive"))
    monkeypatch.setattr(rtde_control, "RTDEControlInterface", forbidden("control"))
    monkeypatch.setattr(rtde_io, "RTDEIOInterface", forbidden("io"))

    ticks = 0

    async def heartbeat() -> None:
        nonlocal ticks
        while True:
            ticks += 1
            await asyncio.sleep(0.05)

    beating = asyncio.create_task(heartbeat())
    start = time.monotonic()
    try:
        with pytest.raises(ConnectionFailed, match="did not answer the RTDE protocol-version"):
            await ur.connect_ur("127.0.0.1", None, 47800, None, timeout=1.0)
    finally:
        beating.cancel()
    elapsed = time.monotonic() - start
    assert elapsed < 3.0
    assert ticks >= 10, "the event loop was blocked while waiting for the peer"
    assert constructed == []
    assert silent_peer, "the probe never connected"
