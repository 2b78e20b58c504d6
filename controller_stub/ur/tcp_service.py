"""One listening TCP port of the UR personality, with connection handlers that `close()`
can cancel. RTDE, the dashboard and the script port subclass it and give `_serve_connection`."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import ClassVar


class TcpService:
    """`start()` binds and accepts; each connection runs `_serve_connection` as a tracked task;
    `close()` stops accepting and cancels every connection."""

    service_name: ClassVar[str]  # for the log line, e.g. "rtde"
    default_port: ClassVar[int]
    read_limit: ClassVar[int] = 2**16  # asyncio's default StreamReader limit

    def __init__(self) -> None:
        self._server: asyncio.Server | None = None
        self._handlers: set[asyncio.Task[None]] = set()

    async def start(self, host: str = "127.0.0.1", port: int | None = None) -> tuple[str, int]:
        """Bind and accept; returns the bound (host, port)."""
        port = self.default_port if port is None else port
        self._server = await asyncio.start_server(
            self._accept, host, port, reuse_address=True, limit=self.read_limit
        )
        bound = self._server.sockets[0].getsockname()[:2]
        logging.getLogger(type(self).__module__).info(
            "%s listening on %s:%d", self.service_name, *bound)
        return bound[0], bound[1]

    async def close(self) -> None:
        """Stop accepting and drop every client."""
        if self._server is not None:
            self._server.close()
        for task in list(self._handlers):
            task.cancel()
        for task in list(self._handlers):
            with contextlib.suppress(BaseException):
                await task
        if self._server is not None:
            with contextlib.suppress(Exception):
                await self._server.wait_closed()

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._handlers.add(task)
        try:
            await self._serve_connection(reader, writer)
        finally:
            self._handlers.discard(task)

    async def _serve_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        """Serve one connection until it ends (subclasses)."""
        raise NotImplementedError
