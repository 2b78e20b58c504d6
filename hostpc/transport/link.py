"""One TCP connection of the client: the sans-IO `Connection`, its reader task, pending replies.

`_Link` feeds received bytes to the protocol state machine, resolves the future of each
request when its reply arrives, reports the handshake's outcome and, when the connection
ends, fails every pending request with `_LinkLostError` (the client decides whether to
re-send). Reconnection policy lives in `ControllerClient`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Any

from hostpc.errors import ConnectionFailed, ProtocolViolation
from hostpc.transport.error_mapping import _handshake_error
from protocol import messages as m
from protocol.connection import Connection
from protocol.message_base import Reply, Request, _Message
from protocol.session_states import ConnectionState, Rejected, StateChanged

# the client's logger: log records keep the name they had before the client was split
logger = logging.getLogger("hostpc.transport.client")

READ_CHUNK = 1 << 20


class _LinkLostError(Exception):
    """The TCP connection ended while a request was in flight."""


class _Link:
    """One TCP connection: the sans-IO Connection, the reader task, pending replies."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        conn: Connection,
        on_event: Callable[[m.IoEdge], None],
    ) -> None:
        self.reader = reader
        self.writer = writer
        self.conn = conn
        self.pending: dict[int, asyncio.Future[_Message]] = {}
        self.handshake: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        # The opener waits on a shield of the handshake; if it gave up (timeout), a later
        # failure set here must not be reported as "Future exception was never retrieved".
        self.handshake.add_done_callback(_retrieve_exception)
        self.closed_reason: str | None = None
        self._on_event = on_event
        self.task = asyncio.get_running_loop().create_task(self._read_loop())

    @property
    def alive(self) -> bool:
        return self.closed_reason is None and self.conn.state is not ConnectionState.CLOSED

    def send(self, request: Request) -> asyncio.Future[_Message]:
        data = self.conn.send(request)
        future: asyncio.Future[_Message] = asyncio.get_running_loop().create_future()
        self.pending[request.id] = future
        self.writer.write(data)
        return future

    async def _read_loop(self) -> None:
        reason = "connection closed by the controller"
        try:
            while True:
                try:
                    data = await self.reader.read(READ_CHUNK)
                except (ConnectionError, OSError) as exc:
                    reason = f"connection lost ({exc})"
                    data = b""
                events = self.conn.receive_data(data)
                outgoing = self.conn.data_to_send()
                if outgoing:
                    self.writer.write(outgoing)
                for event in events:
                    self._dispatch(event)
                if self.conn.state is ConnectionState.CLOSED:
                    break
        finally:
            self._lost(reason)

    def _dispatch(self, event: object) -> None:
        if isinstance(event, m.IoEdge):
            self._on_event(event)
        elif isinstance(event, (Reply, m.ErrorReply)):
            future = self.pending.pop(event.reply_to, None) if event.reply_to is not None else None
            if future is not None:
                if not future.done():
                    future.set_result(event)
            elif isinstance(event, m.ErrorReply) and not self.handshake.done():
                self.handshake.set_exception(_handshake_error(event))
            elif isinstance(event, m.ErrorReply):
                logger.warning("controller error %s: %s", event.code, event.message)
        elif isinstance(event, StateChanged):
            ready = ConnectionState.READY if self.conn.has_token else ConnectionState.AUTHENTICATING
            if event.new is ready and not self.handshake.done():
                self.handshake.set_result(None)
        elif isinstance(event, Rejected):
            self._rejected(event)

    def _rejected(self, event: Rejected) -> None:
        """The controller sent something invalid: the request it answers fails with
        ProtocolViolation. A reply naming no request in flight (a wrong id) fails every
        request in flight instead, unless the link closes (then they are re-sent or fail
        as lost): their replies can no longer be told apart, and waiting for them would
        only end in a timeout after the real reason. Logged only when no caller hears it."""
        error = ProtocolViolation(f"controller sent an invalid message: {event.message}")
        heard = not self.handshake.done()
        if heard:
            self.handshake.set_exception(error)
        future = self.pending.pop(event.reply_to, None) if event.reply_to is not None else None
        if future is not None:
            waiting = [future]
        elif event.fatal:
            waiting = []
        else:
            waiting, self.pending = list(self.pending.values()), {}
        for waiter in waiting:
            if not waiter.done():
                waiter.set_exception(error)
                heard = True
        if not heard:
            logger.warning("controller broke the protocol: %s (%s)", event.message, event.code)

    def _lost(self, reason: str) -> None:
        if self.closed_reason is None:
            self.closed_reason = reason
        if not self.handshake.done():
            self.handshake.set_exception(ConnectionFailed(f"handshake failed: {reason}"))
        for future in self.pending.values():
            if not future.done():
                future.set_exception(_LinkLostError(reason))
        self.pending.clear()
        if not self.writer.is_closing():
            self.writer.close()

    async def close(self) -> None:
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await self.task
        self._lost("closed by the client")
        with contextlib.suppress(Exception):
            await self.writer.wait_closed()


def _retrieve_exception(future: asyncio.Future[Any]) -> None:
    if not future.cancelled():
        future.exception()
