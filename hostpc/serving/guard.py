"""A guarded TCP listener for servers whose peers do not authenticate (Modbus, HTTP).

`ConnectionGuard` owns the listening socket (`loop.create_server`) and puts a thin
`GuardedConnection` protocol in front of the library's own per-connection protocol
(pymodbus's request handler, aiohttp's RequestHandler): the guard counts every connection
in a `protocol.connection_table.ConnectionTable` (the shared policy: caps in all and per
address, silent connections evicted first, deadlines) and closes what the table evicts or
finds overdue; a sweep once a second closes silent and idle connections. The library never
sees a connection the guard refused, and its own code is not patched: the guard uses only
the asyncio protocol contract both libraries implement.

Why a front and not the library's own options: neither pymodbus 3.16 nor aiohttp caps
connections, and at the usual 1024 open-file limit 1,100 idle sockets locked the station
out (EMFILE on every accept). With the guard, a connection over a cap costs one accept and
one close, so the station never holds more than the caps (plus one accept batch) sockets.

The library tells the guard when a connection completed a request: `GuardedConnection.
request_done()` (the Modbus front does, per whole frame; the page's middleware does, per
request, through `connection_of(transport)`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable

from protocol.admission import LogBudget
from protocol.connection_table import ConnectionTable

SWEEP_INTERVAL_S = 0.5
"""How often silent and idle connections are looked for (s)."""
ACCEPT_BACKLOG = 100
"""Listen backlog: one accept batch; caps + backlog stay well under 1024 open files."""


class GuardedConnection(asyncio.Protocol):
    """One accepted connection: counted by the guard, then handed to `inner`."""

    def __init__(self, guard: ConnectionGuard) -> None:
        self.guard = guard
        self.transport: asyncio.Transport | None = None
        self.inner: asyncio.Protocol | None = None
        self.peer = "?"

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = str(peer[0]) if isinstance(peer, tuple) else str(peer)
        self.guard.admit(self)
        self.inner = self.guard.inner_factory(self)
        self.inner.connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if self.inner is not None:
            self.inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self.inner.eof_received() if self.inner is not None else None

    def connection_lost(self, exc: Exception | None) -> None:
        self.guard.forget(self)
        if self.inner is not None:
            self.inner.connection_lost(exc)

    def pause_writing(self) -> None:
        if self.inner is not None:
            self.inner.pause_writing()

    def resume_writing(self) -> None:
        if self.inner is not None:
            self.inner.resume_writing()

    def request_done(self) -> None:
        """This connection completed a request (it serves, and is active now)."""
        self.guard.table.request_done(self, self.guard.now())

    def close(self) -> None:
        """Drop the connection now (evicted or overdue)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.abort()


class ConnectionGuard:
    """Listen on (host, port) and admit connections through `table` (see module docstring).

    name: what the log lines say ("Modbus", "page"). inner_factory: builds the library's
    protocol for an admitted connection (it may keep the GuardedConnection to report
    completed requests). logger: where evictions and closes are reported, at most one line
    per kind every `log_interval_s` with the count held back.
    """

    def __init__(
        self,
        name: str,
        table: ConnectionTable[GuardedConnection],
        inner_factory: Callable[[GuardedConnection], asyncio.Protocol],
        logger: logging.Logger,
        log_interval_s: float = 10.0,
    ) -> None:
        self.name = name
        self.table = table
        self.inner_factory = inner_factory
        self.logger = logger
        self.evicted = 0
        self.overdue = 0
        self._log_budget = LogBudget(interval_s=log_interval_s)
        self._by_transport: dict[asyncio.BaseTransport, GuardedConnection] = {}
        self._server: asyncio.Server | None = None
        self._sweeper: asyncio.Task[None] | None = None

    async def listen(self, host: str, port: int) -> tuple[str, int]:
        """Bind and start accepting; returns the bound (host, port)."""
        loop = asyncio.get_running_loop()
        self._server = await loop.create_server(
            lambda: GuardedConnection(self), host, port, reuse_address=True,
            backlog=ACCEPT_BACKLOG)
        self._sweeper = loop.create_task(self._sweep())
        bound = self._server.sockets[0].getsockname()
        return str(bound[0]), int(bound[1])

    async def close(self) -> None:
        """Stop accepting and drop every connection."""
        if self._sweeper is not None:
            self._sweeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._sweeper
        if self._server is not None:
            self._server.close()
        for connection in list(self._by_transport.values()):
            connection.close()
        if self._server is not None:
            with contextlib.suppress(Exception):  # closing: a cancel lost here is harmless
                await asyncio.wait_for(self._server.wait_closed(), 5.0)

    def now(self) -> float:
        return asyncio.get_running_loop().time()

    def connection_of(self, transport: asyncio.BaseTransport | None) -> GuardedConnection | None:
        """The guarded connection of a library's transport (None if not ours)."""
        return self._by_transport.get(transport) if transport is not None else None

    def admit(self, connection: GuardedConnection) -> None:
        assert connection.transport is not None
        self._by_transport[connection.transport] = connection
        evicted = self.table.admit(connection, connection.peer, self.now())
        for old in evicted:
            old.close()
        if evicted:
            self.evicted += len(evicted)
            self._report("evicted", f"{self.name}: evicted %d connection(s) for newer ones "
                         f"(at most {self.table.max_connections} in all, "
                         f"{self.table.max_per_address} per address; silent ones first)",
                         len(evicted))

    def forget(self, connection: GuardedConnection) -> None:
        self.table.remove(connection)
        if connection.transport is not None:
            self._by_transport.pop(connection.transport, None)

    def _report(self, kind: str, message: str, count: int) -> None:
        held = self._log_budget.admit(kind, self.now())
        if held is not None:
            self.logger.warning(message + " (%d more since the last report)", count, held)

    async def _sweep(self) -> None:
        while True:
            await asyncio.sleep(SWEEP_INTERVAL_S)
            late = self.table.overdue(self.now())
            for connection in late:
                connection.close()
            if late:
                self.overdue += len(late)
                self._report("overdue", f"{self.name}: closed %d connection(s) silent for "
                             f"{self.table.first_request_timeout_s:g} s or idle for "
                             f"{self.table.idle_timeout_s:g} s", len(late))
