"""The simulated controller's asyncio TCP server: a thin shell around one `Simulation`.

Each client gets a sans-IO `protocol.Connection` (handshake, auth and malformed input are
handled there) and a reader loop; every accepted request runs as its own task, so `abort`,
`heartbeat` and state reads are answered while a motion is in progress. Any failure of a
handler becomes an `error` reply (`refused` with the simulation's reason for
`SimulationRefused`, `internal` otherwise) and the server keeps serving; a client that
breaks the framing gets an error reply and its connection closed, nobody else notices.

Motions are paced in wall time: the simulation plans the move (`sim.begin_move`), the
server waits `duration_s * time_scale` and then executes it (`sim.finish_move`). An `abort`
ends the wait early and the robot stops where it was: at the elapsed fraction of the motion,
with only the IO edges (and a guarded contact) that came before the stop. While a motion
runs, `get_state` reports the joint angles interpolated along the path. One motion at a time
for the whole controller: a second one is refused with `busy`, and so are offset writes.
(A simulation without `begin_move` moves at once and the abort only ends the wait.)

Limits against slow, stalled or greedy peers (all per `ControllerServer` arguments, from
`scenario.server`): a client must say hello within `handshake_timeout_s`, and a frame it has
started must be complete within the same time; a session that sends nothing for
`idle_timeout_s` while no request of its own is in flight is closed (a heartbeat keeps it
alive); at most `max_sessions` sessions (the next client gets an error reply, then the
connection closes); at most `max_requests_in_flight` requests per session run at once
(beyond that the server stops reading from that client: backpressure); the server also stops
reading while the client's unsent replies exceed `WRITE_HIGH_WATER` bytes, and drops a client
that has not read them for `idle_timeout_s`. Until a session is authenticated its frames may
not exceed `PRE_AUTH_MAX_FRAME_SIZE` (requests carry no attachments).

Injected faults (scenario.faults) handled here: `drop_after_requests` (the request with that
0-based index, counted over all connections, is not executed and its connection is dropped,
once) and `reply_delay_s` (every reply waits that long in wall time). Refused moves, lost IO
edges and the e-stop live in the simulation.

IO edges reported by the simulation are pushed as `io_edge` events to every authenticated
session. The server binds 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import os
import socket
import tempfile
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np

from controller_stub.simulation import SimulationRefused
from protocol import messages as m
from protocol.connection import (
    Connection,
    ConnectionClosed,
    ConnectionState,
    Rejected,
    Role,
    StateChanged,
)
from protocol.errors import ErrorCode, LocalProtocolError
from protocol.framing import DEFAULT_MAX_FRAME_SIZE

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
SERVER_NAME = "controller-stub"
READ_CHUNK = 1 << 20
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


class RequestRefusedError(Exception):
    """A handler refuses a request with a protocol error code (busy, unknown rollback...)."""

    def __init__(self, code: ErrorCode, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.reason = reason


class ControllerServer:
    """Serve one simulation to many clients over the zerocal protocol.

    sim: a `controller_stub.simulation.Simulation` (or anything with its interface).
    token: the shared secret clients prove with HMAC. max_frame_size: largest frame
    accepted from an authenticated client (bytes). drop_after_requests / reply_delay_s:
    injected faults (see the module docstring). truth_out: file rewritten with `sim.truth()`
    as JSON at start and whenever the offsets change. handshake_timeout_s, idle_timeout_s
    (s), max_sessions, max_requests_in_flight: the limits of the module docstring.
    """

    def __init__(
        self,
        sim: Any,
        *,
        token: str,
        max_frame_size: int = DEFAULT_MAX_FRAME_SIZE,
        drop_after_requests: int | None = None,
        reply_delay_s: float = 0.0,
        truth_out: str | Path | None = None,
        handshake_timeout_s: float = 10.0,
        idle_timeout_s: float = 300.0,
        max_sessions: int = 32,
        max_requests_in_flight: int = 8,
    ) -> None:
        self.sim = sim
        self.token = token
        self.max_frame_size = max_frame_size
        self.handshake_timeout_s = float(handshake_timeout_s)
        self.idle_timeout_s = float(idle_timeout_s)
        self.max_sessions = int(max_sessions)
        self.max_requests_in_flight = max(1, int(max_requests_in_flight))
        self.sessions_refused = 0
        self.drop_after_requests = drop_after_requests
        self.reply_delay_s = reply_delay_s
        self.truth_out = Path(truth_out) if truth_out else None
        self.requests_seen = 0
        self._dropped = False
        self._server: asyncio.Server | None = None
        self._sessions: set[_Session] = set()
        self._motion: asyncio.Future[None] | None = None
        # the planned motion being paced: (plan, loop time at its start, wall duration s)
        self._progress: tuple[Any, float, float] | None = None
        self._rollbacks: dict[str, list[float]] = {}
        self._rollback_counter = 0
        sim.on_io_edge = self._on_io_edge

    @classmethod
    def from_scenario(cls, scenario: Any, truth_out: str | Path | None = None) -> ControllerServer:
        """Build the simulation of `scenario` and a server with its token and faults."""
        from controller_stub.simulation import create_simulation

        return cls(
            create_simulation(scenario),
            token=scenario.server.token,
            max_frame_size=scenario.server.max_frame_bytes,
            drop_after_requests=scenario.faults.drop_after_requests,
            reply_delay_s=scenario.faults.reply_delay_s,
            truth_out=truth_out,
            handshake_timeout_s=scenario.server.handshake_timeout_s,
            idle_timeout_s=scenario.server.idle_timeout_s,
            max_sessions=scenario.server.max_sessions,
            max_requests_in_flight=scenario.server.max_requests_in_flight,
        )

    # ----------------------------------------------------------------------- lifecycle

    async def start(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Bind and start accepting; returns the bound (host, port) (port 0 = any free)."""
        self._server = await asyncio.start_server(
            self._accept, host, port, limit=READ_CHUNK, reuse_address=True
        )
        self.write_truth()
        bound = self.address
        logger.info("listening on %s:%d", *bound)
        return bound

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port)."""
        if self._server is None or not self._server.sockets:
            raise RuntimeError("server not started")
        host, port = self._server.sockets[0].getsockname()[:2]
        return host, port

    async def serve_forever(self) -> None:
        """Serve until cancelled."""
        if self._server is None:
            raise RuntimeError("call start() first")
        await self._server.serve_forever()

    async def close(self) -> None:
        """Stop accepting, drop every session and cancel their requests."""
        if self._server is not None:
            self._server.close()
        for session in list(self._sessions):
            session.abort()
        for session in list(self._sessions):
            await session.finished()
        if self._server is not None:
            with contextlib.suppress(Exception):
                await self._server.wait_closed()

    async def __aenter__(self) -> ControllerServer:
        if self._server is None:
            await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    @property
    def session_count(self) -> int:
        """Connected clients."""
        return len(self._sessions)

    # ---------------------------------------------------------------------- internals

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if len(self._sessions) >= self.max_sessions:
            await self._refuse_session(reader, writer)
            return
        session = _Session(self, reader, writer)
        self._sessions.add(session)
        try:
            await session.run()
        finally:
            self._sessions.discard(session)

    async def _refuse_session(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        """Session limit reached: one `busy` error reply, then close."""
        self.sessions_refused += 1
        peer = writer.get_extra_info("peername")
        logger.warning("refusing %s: %d sessions already (the limit)", peer, len(self._sessions))
        conn = Connection(Role.SERVER, token=self.token)
        error = conn.send_error(
            None,
            ErrorCode.BUSY,
            f"too many sessions: the controller serves at most {self.max_sessions}; "
            "try again later",
        )
        try:
            writer.write(error)
            writer.write_eof()
            # wait (briefly) for the client to close, discarding what it sends, so that
            # closing does not reset the connection before it has read the error
            async with asyncio.timeout(CLOSE_DRAIN_S):
                while await reader.read(SESSION_READ_CHUNK):
                    pass
        except (TimeoutError, ConnectionError, OSError):
            pass
        finally:
            writer.transport.abort()

    def count_request(self) -> bool:
        """Count one request; True if the drop fault says to drop its connection now."""
        index = self.requests_seen
        self.requests_seen += 1
        if self.drop_after_requests is not None and not self._dropped:
            if index >= self.drop_after_requests:
                self._dropped = True
                return True
        return False

    def _on_io_edge(self, line: int, value: bool, time: float, q_latched: np.ndarray) -> None:
        event = m.IoEdge(
            line=int(line), value=bool(value), time=float(time), q_latched=_floats(q_latched)
        )
        for session in list(self._sessions):
            session.push(event)

    def write_truth(self) -> None:
        """Rewrite the --truth-out file atomically (no-op without one)."""
        if self.truth_out is None:
            return
        text = json.dumps(self.sim.truth(), indent=2, default=_json_default)
        directory = self.truth_out.parent
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=".truth-", suffix=".json")
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, self.truth_out)

    def mode(self) -> str:
        """Controller mode for the state reply."""
        if self.sim.estopped:
            return "estop"
        return "moving" if self._motion is not None else "idle"

    def joint_positions(self) -> np.ndarray:
        """(n,) reported joint angles now: along the path while a planned motion runs."""
        progress = self._progress
        if progress is None:
            return np.asarray(self.sim.joint_positions(), dtype=float)
        plan, started, wall = progress
        elapsed = asyncio.get_running_loop().time() - started
        return np.asarray(plan.q_at(elapsed / wall if wall > 0.0 else 1.0), dtype=float)

    async def execute_motion(self, plan: Any) -> Any:
        """Pace `plan` (from `sim.begin_move`) in wall time, then finish it in the simulation:
        at its end, or at the elapsed fraction if it was aborted (or cancelled: shutdown).
        Returns the simulation's MoveResult / GuardedMoveResult."""
        loop = asyncio.get_running_loop()
        wall = max(0.0, float(plan.duration_s) * float(self.sim.time_scale))
        started = loop.time()
        self._progress = (plan, started, wall)
        finished = False
        try:
            finished = await self.run_motion(plan.duration_s)
        finally:
            self._progress = None
            fraction = 1.0 if finished or wall <= 0.0 else (loop.time() - started) / wall
            result = self.sim.finish_move(plan, min(fraction, 1.0))
        return result

    async def run_motion(self, duration_s: float) -> bool:
        """Pace a motion in wall time; False if it was aborted before the end."""
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        self._motion = waiter
        try:
            wall = max(0.0, float(duration_s) * float(self.sim.time_scale))
            done, _ = await asyncio.wait({waiter}, timeout=wall)
            return waiter not in done
        finally:
            if self._motion is waiter:
                self._motion = None
            if not waiter.done():
                waiter.cancel()

    def begin_motion(self) -> None:
        """Refuse with `busy` if a motion is in progress."""
        if self._motion is not None:
            raise RequestRefusedError(ErrorCode.BUSY, "another motion is in progress")

    def abort_motion(self) -> bool:
        """Stop the paced motion in progress; True if there was one."""
        if self._motion is None or self._motion.done():
            return False
        self._motion.set_result(None)
        return True

    def new_rollback_id(self, previous: list[float]) -> str:
        """Remember `previous` offsets under a fresh rollback id."""
        self._rollback_counter += 1
        rollback_id = f"rb-{self._rollback_counter}"
        self._rollbacks[rollback_id] = previous
        return rollback_id

    def rollback_offsets(self, rollback_id: str) -> list[float]:
        """The offsets saved under `rollback_id`; RequestRefusedError if unknown."""
        try:
            return self._rollbacks[rollback_id]
        except KeyError:
            raise RequestRefusedError(
                ErrorCode.UNKNOWN_ROLLBACK, f"unknown rollback id {rollback_id!r}"
            ) from None


class _Session:
    """One client connection: reader loop, request tasks, event pushes (and its limits)."""

    def __init__(
        self, server: ControllerServer, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        self.server = server
        self.sim = server.sim
        self.reader = reader
        self.writer = writer
        peer = writer.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
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
        loop = asyncio.get_running_loop()
        self._handshake_deadline = loop.time() + server.handshake_timeout_s
        self._frame_started: float | None = None  # loop time the frame in progress began
        writer.transport.set_write_buffer_limits(high=WRITE_HIGH_WATER)
        self._handlers: dict[str, Callable[[Any], Awaitable[m._Message]]] = {
            "get_state": self._get_state,
            "read_io": self._read_io,
            "move_joints": self._move_joints,
            "guarded_move": self._guarded_move,
            "abort": self._abort,
            "capture": self._capture,
            "measure_targets": self._measure_targets,
            "get_offsets": self._get_offsets,
            "set_offsets": self._set_offsets,
            "rollback_offsets": self._rollback,
            "heartbeat": self._heartbeat,
        }
        sock = writer.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    async def run(self) -> None:
        logger.info("client %s connected", self.peer)
        try:
            while self.conn.state is not ConnectionState.CLOSED:
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

    def abort(self) -> None:
        """Drop the connection now and cancel its requests (server shutdown)."""
        for task in self._tasks:
            task.cancel()
        self._close_transport(abort=True)

    def push(self, event: m._Message) -> None:
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
        if self.conn.state is ConnectionState.AWAITING_HELLO:
            waits.append(
                (
                    self._handshake_deadline - now,
                    f"no hello within {self.server.handshake_timeout_s:g} s",
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
        if isinstance(event, m.Request):
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
        elif isinstance(event, StateChanged):
            if event.new is ConnectionState.READY:
                logger.info("client %s authenticated", self.peer)
        elif isinstance(event, m.ErrorReply):
            logger.info("client %s reports error %s: %s", self.peer, event.code, event.message)
        elif isinstance(event, ConnectionClosed):
            pass

    async def _serve(self, request: m.Request) -> None:
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
            if self.conn.state is ConnectionState.CLOSED or self.writer.is_closing():
                return
            if not await self._wait_writable():
                return
            if self.conn.state is ConnectionState.CLOSED or self.writer.is_closing():
                return
            try:
                data = self.conn.send(reply)
            except LocalProtocolError:
                logger.exception("cannot send %s to %s", reply.kind, self.peer)
                return
            self._write(data)

    def _write(self, data: bytes) -> None:
        if data and not self.writer.is_closing():
            self.writer.write(data)

    def _close_transport(self, abort: bool = False) -> None:
        if abort:
            self.writer.transport.abort()
        elif not self.writer.is_closing():
            self.writer.close()

    # ---------------------------------------------------------------------- handlers

    async def _get_state(self, request: m.GetState) -> m.State:
        sim = self.sim
        q_min, q_max = sim.joint_limits()
        return m.State(
            reply_to=request.id,
            robot_name=str(sim.robot_name),
            n_joints=int(sim.n_joints),
            mode=self.server.mode(),  # type: ignore[arg-type]
            time=float(sim.time),
            q=_floats(self.server.joint_positions()),  # along the path while moving
            zero_offsets=_floats(sim.zero_offsets()),
            q_min=_floats(q_min),
            q_max=_floats(q_max),
            digital_inputs=[bool(v) for v in sim.digital_inputs()],
            digital_outputs=[bool(v) for v in sim.digital_outputs()],
            camera=json.loads(json.dumps(sim.camera_description(), default=_json_default)),
            authenticated=self.conn.authenticated,
        )

    async def _read_io(self, request: m.ReadIo) -> m.IoState:
        return m.IoState(
            reply_to=request.id,
            digital_inputs=[bool(v) for v in self.sim.digital_inputs()],
            digital_outputs=[bool(v) for v in self.sim.digital_outputs()],
            time=float(self.sim.time),
        )

    def _check_joints(self, q: list[float]) -> np.ndarray:
        n = int(self.sim.n_joints)
        if len(q) != n:
            raise RequestRefusedError(
                ErrorCode.BAD_MESSAGE, f"expected {n} joint values, got {len(q)}"
            )
        return np.asarray(q, dtype=float)

    async def _run_motion(self, q_target: np.ndarray, speed: float, io_line: int | None) -> Any:
        """Plan, pace and finish a motion (stopped part-way by an abort); the simulation's
        MoveResult / GuardedMoveResult. A simulation without `begin_move` moves at once
        and an abort only ends the wait (its result then says "aborted")."""
        self.server.begin_motion()
        if hasattr(self.sim, "begin_move"):
            plan = self.sim.begin_move(q_target, speed, io_line)
            return await self.server.execute_motion(plan)
        if io_line is None:
            result = self.sim.move_joints(q_target, speed)
        else:
            result = self.sim.guarded_move(q_target, speed, io_line)
        if await self.server.run_motion(result.duration_s):
            return result
        if io_line is None:
            return dataclasses.replace(result, completed=False, reason="aborted")
        return dataclasses.replace(result, reason="aborted")

    async def _move_joints(self, request: m.MoveJoints) -> m.MoveDone:
        q_target = self._check_joints(request.q)
        result = await self._run_motion(q_target, request.speed, None)
        return m.MoveDone(
            reply_to=request.id,
            completed=bool(result.completed),
            q=_floats(result.q),
            duration_s=float(result.duration_s),
            reason=result.reason,
        )

    async def _guarded_move(self, request: m.GuardedMove) -> m.GuardedMoveDone:
        q_target = self._check_joints(request.q)
        result = await self._run_motion(q_target, request.speed, request.io_line)
        return m.GuardedMoveDone(
            reply_to=request.id,
            contact=bool(result.contact),
            q_latched=None if result.q_latched is None else _floats(result.q_latched),
            q=_floats(result.q),
            io_line=int(result.io_line),
            duration_s=float(result.duration_s),
            speed_mps=None if result.speed_mps is None else float(result.speed_mps),
            reason=result.reason,
        )

    def _refuse_while_moving(self, what: str) -> None:
        if self.server.mode() == "moving":
            raise RequestRefusedError(
                ErrorCode.BUSY, f"cannot {what} while a motion is in progress"
            )

    async def _abort(self, request: m.Abort) -> m.Aborted:
        return m.Aborted(reply_to=request.id, was_moving=self.server.abort_motion())

    async def _capture(self, request: m.Capture) -> m.CaptureDone:
        frame = self.sim.capture_stereo(pattern=request.pattern, view=request.view)
        infos: list[m.ImageInfo] = []
        payloads: list[bytes | memoryview] = []
        for camera, image in (("left", frame.left), ("right", frame.right)):
            pixels = np.ascontiguousarray(image, dtype=np.uint8)
            if pixels.ndim != 2:
                raise RuntimeError(f"{camera} image has shape {pixels.shape}, expected (H, W)")
            height, width = pixels.shape
            payload = _encode_png(pixels) if request.encoding == "png" else pixels.reshape(-1).data
            infos.append(
                m.ImageInfo(
                    camera=camera,  # type: ignore[arg-type]
                    width=width,
                    height=height,
                    encoding=request.encoding,
                    nbytes=memoryview(payload).nbytes,
                )
            )
            payloads.append(payload)
        reply = m.CaptureDone(
            reply_to=request.id,
            pattern=request.pattern,
            view=request.view,
            q=_floats(frame.q),
            time=float(frame.time),
            images=infos,
        )
        reply.with_attachments(*payloads)
        return reply

    async def _measure_targets(self, request: m.MeasureTargets) -> m.TargetsMeasured:
        """The simulation's triangulated targets (`sim.measure_targets()`); a simulation
        without that sensor refuses with reason `unsupported`."""
        measure = getattr(self.sim, "measure_targets", None)
        if measure is None:
            raise SimulationRefused("unsupported", f"{self.sim.robot_name} has no target "
                                    "measurement; use capture")
        result = measure()  # during a motion: at its start pose, with that q (as capture)
        targets = [
            m.TargetObservation(chain=str(chain), p=_floats(seen["p"]),
                                cov=np.asarray(seen["cov"], dtype=float).reshape(3, 3).tolist())
            for chain, seen in result["targets"].items()
        ]
        return m.TargetsMeasured(reply_to=request.id, q=_floats(result["q"]),
                                 time=float(result["time"]), targets=targets)

    async def _get_offsets(self, request: m.GetOffsets) -> m.Offsets:
        return m.Offsets(reply_to=request.id, offsets=_floats(self.sim.zero_offsets()))

    async def _set_offsets(self, request: m.SetOffsets) -> m.OffsetsSet:
        offsets = self._check_joints(request.offsets)
        self._refuse_while_moving("write the zero offsets")
        previous = _floats(self.sim.set_zero_offsets(offsets))
        rollback_id = self.server.new_rollback_id(previous)
        logger.info("client %s set zero offsets (rollback id %s)", self.peer, rollback_id)
        self.server.write_truth()
        return m.OffsetsSet(
            reply_to=request.id,
            offsets=_floats(self.sim.zero_offsets()),
            previous=previous,
            rollback_id=rollback_id,
        )

    async def _rollback(self, request: m.RollbackOffsets) -> m.OffsetsRolledBack:
        saved = self.server.rollback_offsets(request.rollback_id)
        self._refuse_while_moving("roll back the zero offsets")
        replaced = _floats(self.sim.set_zero_offsets(np.asarray(saved, dtype=float)))
        logger.info("client %s rolled back offsets to %s", self.peer, request.rollback_id)
        self.server.write_truth()
        return m.OffsetsRolledBack(
            reply_to=request.id, offsets=_floats(self.sim.zero_offsets()), replaced=replaced
        )

    async def _heartbeat(self, request: m.Heartbeat) -> m.HeartbeatReply:
        return m.HeartbeatReply(reply_to=request.id, time=float(self.sim.time))


def _error(
    request: m.Request, code: ErrorCode, message: str, reason: str | None = None
) -> m.ErrorReply:
    return m.ErrorReply(reply_to=request.id, code=code, message=message[:4000], reason=reason)


def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).reshape(-1)]


def _encode_png(pixels: np.ndarray) -> bytes:
    import cv2

    ok, buffer = cv2.imencode(".png", pixels)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buffer.tobytes()


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
