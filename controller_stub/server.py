"""The simulated controller's asyncio TCP server: a thin shell around one `Simulation`.

Each client gets a sans-IO `protocol.Connection` (handshake, auth and malformed input are
handled there) and a reader loop; every accepted request runs as its own task, so `abort`,
`heartbeat` and state reads are answered while a motion is in progress. Any failure of a
handler becomes an `error` reply (`refused` with the simulation's reason for
`SimulationRefused`, `internal` otherwise) and the server keeps serving; a client that
breaks the framing gets an error reply and its connection closed, nobody else notices.

Motions are paced in wall time: the simulation computes the move at once, the server sleeps
`duration_s * time_scale` before replying (an `abort` ends the sleep early). One motion at
a time for the whole controller: a second one is refused with `busy`.

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
    accepted from a client (bytes). drop_after_requests / reply_delay_s: injected faults
    (see the module docstring). truth_out: file rewritten with `sim.truth()` as JSON at
    start and whenever the offsets change.
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
    ) -> None:
        self.sim = sim
        self.token = token
        self.max_frame_size = max_frame_size
        self.drop_after_requests = drop_after_requests
        self.reply_delay_s = reply_delay_s
        self.truth_out = Path(truth_out) if truth_out else None
        self.requests_seen = 0
        self._dropped = False
        self._server: asyncio.Server | None = None
        self._sessions: set[_Session] = set()
        self._motion: asyncio.Future[None] | None = None
        self._rollbacks: dict[str, list[float]] = {}
        self._rollback_counter = 0
        sim.on_io_edge = self._on_io_edge

    @classmethod
    def from_scenario(cls, scenario: Any, truth_out: str | Path | None = None) -> ControllerServer:
        """Build the simulation of `scenario` and a server with its token and faults."""
        from controller_stub.simulation import Simulation

        return cls(
            Simulation(scenario),
            token=scenario.server.token,
            max_frame_size=scenario.server.max_frame_bytes,
            drop_after_requests=scenario.faults.drop_after_requests,
            reply_delay_s=scenario.faults.reply_delay_s,
            truth_out=truth_out,
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
        session = _Session(self, reader, writer)
        self._sessions.add(session)
        try:
            await session.run()
        finally:
            self._sessions.discard(session)

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
    """One client connection: reader loop, request tasks, event pushes."""

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
            server_name=SERVER_NAME,
            robot_name=str(self.sim.robot_name),
        )
        self._tasks: set[asyncio.Task[None]] = set()
        self._done = asyncio.Event()
        self._handlers: dict[str, Callable[[Any], Awaitable[m._Message]]] = {
            "get_state": self._get_state,
            "read_io": self._read_io,
            "move_joints": self._move_joints,
            "guarded_move": self._guarded_move,
            "abort": self._abort,
            "capture": self._capture,
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
                try:
                    data = await self.reader.read(READ_CHUNK)
                except (ConnectionError, OSError):
                    data = b""
                try:
                    events = self.conn.receive_data(data)
                except Exception:  # a protocol-layer bug must not outlive this connection
                    logger.exception("protocol failure with %s; closing", self.peer)
                    break
                self._write(self.conn.data_to_send())
                for event in events:
                    self._dispatch(event)
            with contextlib.suppress(ConnectionError, OSError):
                await self.writer.drain()
        finally:
            self._close_transport()
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
        """Push an event if this session is authenticated."""
        if self.conn.state is ConnectionState.READY:
            self._write(self.conn.send(event))

    # ------------------------------------------------------------------------ events

    def _dispatch(self, event: object) -> None:
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
            task = asyncio.get_running_loop().create_task(self._serve(event))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
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
        if self.conn.state is ConnectionState.CLOSED or self.writer.is_closing():
            return
        try:
            data = self.conn.send(reply)
        except LocalProtocolError:
            logger.exception("cannot send %s to %s", reply.kind, self.peer)
            return
        self._write(data)
        with contextlib.suppress(ConnectionError, OSError):
            await self.writer.drain()

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
            q=_floats(sim.joint_positions()),
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

    async def _move_joints(self, request: m.MoveJoints) -> m.MoveDone:
        q_target = self._check_joints(request.q)
        self.server.begin_motion()
        result = self.sim.move_joints(q_target, request.speed)
        finished = await self.server.run_motion(result.duration_s)
        completed, reason = bool(result.completed), result.reason
        if not finished and completed:
            completed, reason = False, "aborted"
        return m.MoveDone(
            reply_to=request.id,
            completed=completed,
            q=_floats(self.sim.joint_positions() if reason == "aborted" else result.q),
            duration_s=float(result.duration_s),
            reason=reason,
        )

    async def _guarded_move(self, request: m.GuardedMove) -> m.GuardedMoveDone:
        q_target = self._check_joints(request.q)
        self.server.begin_motion()
        result = self.sim.guarded_move(q_target, request.speed, request.io_line)
        finished = await self.server.run_motion(result.duration_s)
        reason = result.reason if finished else "aborted"
        return m.GuardedMoveDone(
            reply_to=request.id,
            contact=bool(result.contact),
            q_latched=None if result.q_latched is None else _floats(result.q_latched),
            q=_floats(result.q),
            io_line=int(result.io_line),
            duration_s=float(result.duration_s),
            speed_mps=None if result.speed_mps is None else float(result.speed_mps),
            reason=reason,
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

    async def _get_offsets(self, request: m.GetOffsets) -> m.Offsets:
        return m.Offsets(reply_to=request.id, offsets=_floats(self.sim.zero_offsets()))

    async def _set_offsets(self, request: m.SetOffsets) -> m.OffsetsSet:
        offsets = self._check_joints(request.offsets)
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
