"""One client connection of the controller stub: reader loop, request tasks, limits.

A session feeds the client's bytes to a sans-IO `protocol.Connection`, runs every accepted
request as its own task (at most `max_requests_in_flight` at once: beyond that it stops
reading), turns any handler failure into an `error` reply, and pushes `io_edge` events once
authenticated. It closes a client that does not say hello and authenticate, or finish a
frame, within `handshake_timeout_s`, that is idle for `idle_timeout_s`, or that does not read
its replies; the server may evict it while it is unauthenticated. See
`controller_stub.network.server` for the limits as a whole.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from typing import Protocol

from controller_stub.errors import SimulationRefused
from controller_stub.network.handlers import MotionHost, RequestHandlers, RequestRefusedError
from controller_stub.world.controller_state import SimulatedController
from protocol import messages as m
from protocol.connection import Connection
from protocol.errors import ErrorCode, LocalProtocolError
from protocol.message_base import Request, _Message
from protocol.session_states import ConnectionClosed, ConnectionState, Rejected, Role, StateChanged

# the server's logger: log records keep the name they had before the server was split
logger = logging.getLogger("controller_stub.network.server")

SERVER_NAME = "controller-stub"
SESSION_READ_CHUNK = 64 * 1024
"""Bytes read from a client at a time (requests are small; bounds the events per read)."""
PRE_AUTH_MAX_FRAME_SIZE = 64 * 1024
"""Largest frame accepted from a session that has not authenticated (bytes)."""
WRITE_HIGH_WATER = 256 * 1024
"""Unsent reply bytes per session above which the server stops reading from it."""
EVENT_DROP_BYTES = 4 * WRITE_HIGH_WATER
"""Unsent bytes above which io_edge events to a session are dropped (it does not read)."""
CLOSE_DRAIN_S = 2.0
"""How long a closing session waits for its last bytes (an error reply) to be sent."""


class SessionHost(MotionHost, Protocol):
    """What a session uses of the server (`controller_stub.network.server.ControllerServer`): the
    simulation, the token, the limits, the fault counters and the admission bookkeeping."""

    sim: SimulatedController
    token: str
    max_frame_size: int
    handshake_timeout_s: float
    idle_timeout_s: float
    max_requests_in_flight: int
    reply_delay_s: float
    requests_seen: int

    def count_request(self) -> bool: ...
    def session_authenticated(self, session: Session) -> None: ...
    def session_loitering(self, session: Session) -> None: ...
    def authentication_failed(self, session: Session) -> None: ...


class Session:
    """One client connection: reader loop, request tasks, event pushes (and its limits)."""

    server: SessionHost

    def __init__(
        self, server: SessionHost, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        self.server = server
        self.sim = server.sim
        self.reader = reader
        self.writer = writer
        peer = writer.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        self.host = str(peer[0]) if isinstance(peer, tuple) else str(peer)
        """The peer's address without the port (what failed authentications are counted by)."""
        self.conn = Connection(
            Role.SERVER,
            token=server.token,
            max_frame_size=server.max_frame_size,
            pre_auth_max_frame_size=PRE_AUTH_MAX_FRAME_SIZE,
            server_name=SERVER_NAME,
            robot_name=str(self.sim.robot_name),
        )
        self._tasks: set[asyncio.Task[None]] = set()
        self._slot_freed = asyncio.Event()
        self._write_lock = asyncio.Lock()
        self._done = asyncio.Event()
        self._evicted = False
        loop = asyncio.get_running_loop()
        self._handshake_deadline = loop.time() + server.handshake_timeout_s
        self._frame_started: float | None = None  # loop time the frame in progress began
        writer.transport.set_write_buffer_limits(high=WRITE_HIGH_WATER)
        self._handlers = RequestHandlers(server, self.sim, self.conn, self.peer).table()
        sock = writer.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    async def run(self, wait_s: float = 0.0) -> None:
        """Serve the client until it leaves or is closed; first wait `wait_s` (the auth
        throttle's turn of this peer address; the handshake deadline keeps running)."""
        logger.info("client %s connected", self.peer)
        try:
            if wait_s > 0.0:
                await asyncio.sleep(wait_s)
            while self.conn.state is not ConnectionState.CLOSED and not self._evicted:
                if not await self._wait_writable():
                    break
                data = await self._read()
                if data is None:
                    break
                try:
                    events = self.conn.receive_data(data)
                except Exception:  # a protocol-layer bug must not outlive this connection
                    logger.exception("protocol failure with %s; closing", self.peer)
                    break
                self._note_partial_frame()
                self._write(self.conn.data_to_send())
                for event in events:
                    await self._dispatch(event)
            with contextlib.suppress(TimeoutError, ConnectionError, OSError):
                await asyncio.wait_for(self.writer.drain(), CLOSE_DRAIN_S)
        finally:
            # a client that does not read cannot hold the transport (and its buffer) open
            self._close_transport(abort=self.writer.transport.get_write_buffer_size() > 0)
            # Requests in flight finish (a motion keeps its pacing) but cannot reply.
            if self._tasks:
                await asyncio.gather(*self._tasks, return_exceptions=True)
            logger.info("client %s disconnected", self.peer)
            self._done.set()

    async def finished(self) -> None:
        """Wait until the session has ended."""
        await self._done.wait()

    def evict(self, why: str) -> None:
        """Close this (unauthenticated) session to make room: a `busy` error, then close."""
        self._evicted = True
        logger.info("client %s: %s", self.peer, why)
        if self.conn.state is not ConnectionState.CLOSED and not self.writer.is_closing():
            with contextlib.suppress(LocalProtocolError):
                self._write(self.conn.send_error(None, ErrorCode.BUSY, why))
        for task in self._tasks:
            task.cancel()
        self._close_transport()

    def abort(self) -> None:
        """Drop the connection now and cancel its requests (server shutdown)."""
        for task in self._tasks:
            task.cancel()
        self._close_transport(abort=True)

    def push(self, event: _Message) -> None:
        """Push an event if this session is authenticated (dropped, with a warning, if the
        client has not read EVENT_DROP_BYTES of earlier output)."""
        if self.conn.state is not ConnectionState.READY or self.writer.is_closing():
            return
        if self.writer.transport.get_write_buffer_size() > EVENT_DROP_BYTES:
            logger.warning("client %s does not read; dropping %s", self.peer, event.kind)
            return
        self._write(self.conn.send(event))

    # ------------------------------------------------------------------------ limits

    def _read_deadline(self) -> tuple[float, str]:
        """(seconds to wait for the next bytes, what is overdue if they do not come)."""
        now = asyncio.get_running_loop().time()
        waits = [(self.server.idle_timeout_s, f"idle for {self.server.idle_timeout_s:g} s")]
        if self.conn.state is not ConnectionState.READY:
            said = "no hello" if self.conn.state is ConnectionState.AWAITING_HELLO else "no auth"
            waits.append(
                (
                    self._handshake_deadline - now,
                    f"{said} within {self.server.handshake_timeout_s:g} s",
                )
            )
        if self._frame_started is not None:
            waits.append(
                (
                    self._frame_started + self.server.handshake_timeout_s - now,
                    f"frame of {self.conn.buffered}+ bytes not completed within "
                    f"{self.server.handshake_timeout_s:g} s",
                )
            )
        return min(waits)

    async def _read(self) -> bytes | None:
        """The next bytes from the client (b"" = end of stream), or None once a deadline
        has passed (handshake, frame in progress, idle). Waiting for replies to our own
        requests in flight is not idleness."""
        while True:
            timeout, overdue = self._read_deadline()
            try:
                return await asyncio.wait_for(
                    self.reader.read(SESSION_READ_CHUNK), max(timeout, 0.0)
                )
            except TimeoutError:  # before OSError, of which it is a subclass
                if self._evicted:
                    return None
                if overdue.startswith("idle") and self._tasks:
                    continue
                logger.warning("client %s: %s; closing", self.peer, overdue)
                return None
            except (ConnectionError, OSError):
                return b""

    def _note_partial_frame(self) -> None:
        if self.conn.buffered == 0:
            self._frame_started = None
        elif self._frame_started is None:
            self._frame_started = asyncio.get_running_loop().time()

    async def _wait_writable(self) -> bool:
        """Backpressure: wait while this client's unsent output is above the high-water
        mark. False (and the transport aborted) if it has not read for idle_timeout_s, or
        the connection is gone."""
        try:
            await asyncio.wait_for(self.writer.drain(), self.server.idle_timeout_s)
        except TimeoutError:
            logger.warning(
                "client %s has not read its replies for %g s; closing",
                self.peer,
                self.server.idle_timeout_s,
            )
            self._close_transport(abort=True)
            return False
        except (ConnectionError, OSError):
            return False
        return True

    async def _request_slot(self) -> None:
        """Wait until fewer than max_requests_in_flight requests of this session run."""
        while len(self._tasks) >= self.server.max_requests_in_flight:
            self._slot_freed.clear()
            await self._slot_freed.wait()

    def _task_done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        self._slot_freed.set()

    # ------------------------------------------------------------------------ events

    async def _dispatch(self, event: object) -> None:
        if isinstance(event, Request):
            if self.conn.state is not ConnectionState.READY:
                self.server.session_loitering(self)
            if self.server.count_request():
                logger.warning(
                    "fault: dropping %s after request %d (%s)",
                    self.peer,
                    self.server.requests_seen - 1,
                    event.kind,
                )
                self._close_transport(abort=True)
                return
            await self._request_slot()  # backpressure: no more reading until a slot frees
            task = asyncio.get_running_loop().create_task(self._serve(event))
            self._tasks.add(task)
            task.add_done_callback(self._task_done)
        elif isinstance(event, Rejected):
            logger.warning("client %s: %s (%s)", self.peer, event.message, event.code)
            if event.code is ErrorCode.AUTH_FAILED:
                self.server.authentication_failed(self)
        elif isinstance(event, StateChanged):
            if event.new is ConnectionState.READY:
                logger.info("client %s authenticated", self.peer)
                self.server.session_authenticated(self)
        elif isinstance(event, m.ErrorReply):
            logger.info("client %s reports error %s: %s", self.peer, event.code, event.message)
        elif isinstance(event, ConnectionClosed):
            pass

    async def _serve(self, request: Request) -> None:
        handler = self._handlers[request.kind]
        try:
            reply = await handler(request)
        except SimulationRefused as exc:
            logger.info("refused %s from %s: %s (%s)", request.kind, self.peer, exc, exc.code)
            reply = _error(request, ErrorCode.REFUSED, str(exc), reason=exc.code)
        except RequestRefusedError as exc:
            reply = _error(request, exc.code, str(exc), reason=exc.reason)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # any handler failure becomes an error reply
            logger.exception("handler %s failed for %s", request.kind, self.peer)
            reply = _error(request, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")
        if self.server.reply_delay_s > 0:
            await asyncio.sleep(self.server.reply_delay_s)
        # one reply at a time, each only once the output is below the high-water mark:
        # the unsent bytes stay bounded by WRITE_HIGH_WATER plus one reply
        async with self._write_lock:
            if self._closed() or not await self._wait_writable() or self._closed():
                return
            try:
                data = self.conn.send(reply)
            except LocalProtocolError:
                logger.exception("cannot send %s to %s", reply.kind, self.peer)
                return
            self._write(data)

    def _closed(self) -> bool:
        """True once the connection or its transport is closed (no more replies)."""
        return self.conn.state is ConnectionState.CLOSED or self.writer.is_closing()

    def _write(self, data: bytes) -> None:
        if data and not self.writer.is_closing():
            self.writer.write(data)

    def _close_transport(self, abort: bool = False) -> None:
        if abort:
            self.writer.transport.abort()
        elif not self.writer.is_closing():
            self.writer.close()


def _error(
    request: Request, code: ErrorCode, message: str, reason: str | None = None
) -> m.ErrorReply:
    return m.ErrorReply(reply_to=request.id, code=code, message=message[:4000], reason=reason)

