"""asyncio client of the zerocal protocol: a thin driver around `protocol.Connection`.

    async with ControllerClient.connect("127.0.0.1", 47800, token=token, timeout=5.0) as robot:
        state = await robot.state()
        outcome = await robot.move_joints(q, speed=0.2)
        left, right, q_exposure, t = await robot.capture("target")

Every request has a timeout (`RequestTimeout`); motions have their own, longer one
(MOTION_TIMEOUT_MARGIN times the host's prediction of the move from the controller's
reported limits and the pace of the last move, at least `motion_timeout`), and a motion
that times out, or whose caller is cancelled (Ctrl-C, SIGTERM: hostpc.cli.termination), is
followed by a best-effort `abort` (at most ABORT_AFTER_TIMEOUT_S) so the robot does not
keep moving unattended; a cancelled motion's CancelledError carries a note saying what the
abort did. If the connection drops, requests that are
safe to repeat (state, get_offsets, read_io, capture, heartbeat) are re-sent on a new
connection; a motion, an offset write, a rollback or an abort is NEVER re-sent: the caller
gets `ConnectionFailed` and decides (the robot may or may not have executed it). A request
made while the link is already known to be down opens a new connection first (that is not
a re-send). Errors map onto `hostpc.errors`: `ConnectionFailed` (cannot connect / link
lost), `RequestTimeout`, `ProtocolViolation` (the controller broke the protocol or rejected
ours), `ControllerError` (refused: code and reason in the message and as attributes).

Angles are radians (reported frame), times seconds; arrays are numpy float64 (n,).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable, Generator
from typing import Any, TypeVar

import numpy as np

from hostpc.errors import ConnectionFailed, ProtocolViolation, RequestTimeout
from hostpc.json_object import JsonObject
from hostpc.planning.robot_time import TimeLimits
from hostpc.planning.tour import move_times
from hostpc.transport.error_mapping import _os_error_text, _reply_error
from hostpc.transport.io_events import IoEventSubscription
from hostpc.transport.link import READ_CHUNK, _Link, _LinkLostError
from hostpc.transport.reply_values import _array, _decode_image, _floats
from hostpc.transport.types import (
    ControllerState,
    GuardedMoveOutcome,
    IoEdgeEvent,
    IoSnapshot,
    MoveOutcome,
    SensorReading,
    TargetPoint,
    TargetsMeasurement,
    TrackerReading,
)
from hostpc.transport.waiting import wait_for_reply
from protocol import DEFAULT_PORT, measurement_messages
from protocol import messages as m
from protocol.connection import Connection
from protocol.errors import LocalProtocolError
from protocol.measurement_messages import (
    Capture,
    CaptureDone,
    MeasureTargets,
    MeasureTracker,
    SensorRead,
    TargetsMeasured,
    TrackerMeasured,
)
from protocol.message_base import Reply, Request
from protocol.session_states import Role

logger = logging.getLogger(__name__)

IDEMPOTENT_KINDS = frozenset(
    {"get_state", "get_offsets", "read_io", "capture", "measure_targets", "measure_tracker",
     "sensor_read", "heartbeat"}
)
"""Requests re-sent after a reconnection; everything else raises instead."""
MOTION_KINDS = frozenset({"move_joints", "guarded_move"})
"""Requests that move the robot: timed by their prediction (`_motion_timeout`), aborted
when they time out or are cancelled."""
MOTION_TIMEOUT_MARGIN = 3.0
"""A motion's default timeout is this many times the host's prediction of it (`_motion_timeout`),
never below `motion_timeout`."""
PACE_MIN_MOVE_S = 0.5
"""Moves at least this long (controller time, s) measure the wall seconds per controller
second of motion (a simulator's time_scale; 1 for a real robot)."""
ABORT_AFTER_TIMEOUT_S = 2.0
"""How long the abort sent after a motion timeout or interruption may take (s)."""

ReplyT = TypeVar("ReplyT", bound=Reply)


class _Connect:
    """`ControllerClient.connect(...)`: await it, or use it as an async context manager."""

    def __init__(self, client: ControllerClient) -> None:
        self._client = client

    def __await__(self) -> Generator[Any, None, ControllerClient]:
        return self._open().__await__()

    async def _open(self) -> ControllerClient:
        await self._client.open()
        return self._client

    async def __aenter__(self) -> ControllerClient:
        return await self._open()

    async def __aexit__(self, *exc_info: object) -> None:
        await self._client.close()


class ControllerClient:
    """A session with a zerocal controller (see the module docstring).

    token: shared secret (None = read-only session: motions, captures and writes are
    refused). timeout: default per-request timeout (s); motion_timeout: the least default
    timeout of move_joints / guarded_move (s), which wait until the robot has stopped; on a
    motion timeout the client sends `abort` (best effort) before raising RequestTimeout.
    connect_timeout: TCP connect + handshake (s). reconnect_attempts: how often an
    idempotent request is re-sent after a lost link.
    """

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        token: str | None = None,
        timeout: float = 5.0,
        motion_timeout: float = 120.0,
        connect_timeout: float | None = None,
        reconnect_attempts: int = 3,
        max_frame_size: int = 256 * 1024 * 1024,
        client_name: str = "hostpc",
    ) -> None:
        self.host = host
        self.port = port
        self.token = token
        self.timeout = timeout
        self.motion_timeout = motion_timeout
        self.connect_timeout = connect_timeout if connect_timeout is not None else timeout
        self.reconnect_attempts = reconnect_attempts
        self.max_frame_size = max_frame_size
        self.client_name = client_name
        self.connections_opened = 0
        self._link: _Link | None = None
        self._connecting: asyncio.Lock | None = None
        self._subscriptions: set[IoEventSubscription] = set()
        self._q: np.ndarray | None = None  # the last reported joint angles (n,) rad
        self._limits: TimeLimits | None = None  # the controller's, from its last state
        self._wall_per_robot_s = 1.0  # of the last move of at least PACE_MIN_MOVE_S

    @classmethod
    def connect(
        cls,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        token: str | None = None,
        timeout: float = 5.0,
        **options: Any,
    ) -> _Connect:
        """Open a session: `async with ControllerClient.connect(...) as client` or `await`."""
        return _Connect(cls(host, port, token=token, timeout=timeout, **options))

    @property
    def robot_name(self) -> str:
        """The robot the controller announced in its hello reply."""
        return self._link.conn.robot_name if self._link is not None else ""

    @property
    def authenticated(self) -> bool:
        """True if the current session proved the token."""
        return self._link is not None and self._link.alive and self._link.conn.authenticated

    async def open(self) -> None:
        """Open the connection now (requests also open it, and reopen a lost one, on demand)."""
        await self._ensure_link()

    async def close(self) -> None:
        """Close the connection (pending requests fail with ConnectionFailed)."""
        if self._link is not None:
            await self._link.close()
            self._link = None

    # -------------------------------------------------------------------- requests

    async def state(self, timeout: float | None = None) -> ControllerState:
        """The controller state."""
        reply = await self._request(lambda i: m.GetState(id=i), m.State, timeout)
        state = ControllerState(
            robot_name=reply.robot_name,
            n_joints=reply.n_joints,
            mode=reply.mode,
            time=reply.time,
            q=_array(reply.q),
            zero_offsets=_array(reply.zero_offsets),
            q_min=_array(reply.q_min),
            q_max=_array(reply.q_max),
            digital_inputs=tuple(reply.digital_inputs),
            digital_outputs=tuple(reply.digital_outputs),
            camera=reply.camera,
            authenticated=reply.authenticated,
            max_joint_speed=(None if reply.max_joint_speed is None
                             else _array(reply.max_joint_speed)),
            max_joint_acceleration=(None if reply.max_joint_acceleration is None
                                    else _array(reply.max_joint_acceleration)),
        )
        self._q = state.q
        self._limits = TimeLimits.from_extra(
            {"max_joint_speed": state.max_joint_speed,
             "max_joint_acceleration": state.max_joint_acceleration}, state.n_joints)
        return state

    async def move_joints(self, q: Any, speed: float, timeout: float | None = None) -> MoveOutcome:
        """Move to q (n,) rad at speed (fraction of max, (0, 1]); returns when it stopped.

        timeout: default `MOTION_TIMEOUT_MARGIN` times the host's prediction of the move,
        at least `motion_timeout` (`_motion_timeout`); when it passes, `abort` is sent and
        RequestTimeout raised.
        """
        q_list = _floats(q)
        started = asyncio.get_running_loop().time()
        reply = await self._request(
            lambda i: m.MoveJoints(id=i, q=q_list, speed=speed),
            m.MoveDone,
            self._motion_timeout(q_list, speed) if timeout is None else timeout,
        )
        self._moved(reply.q, reply.duration_s, started)
        return MoveOutcome(reply.completed, _array(reply.q), reply.duration_s, reply.reason)

    async def guarded_move(
        self, q: Any, speed: float, io_line: int, timeout: float | None = None
    ) -> GuardedMoveOutcome:
        """Move toward q (n,) rad until a rising edge on input `io_line`.

        timeout: as move_joints'; when it passes, `abort` is sent and RequestTimeout raised.
        """
        q_list = _floats(q)
        started = asyncio.get_running_loop().time()
        reply = await self._request(
            lambda i: m.GuardedMove(id=i, q=q_list, speed=speed, io_line=io_line),
            m.GuardedMoveDone,
            self._motion_timeout(q_list, speed) if timeout is None else timeout,
        )
        self._moved(reply.q, reply.duration_s, started)
        return GuardedMoveOutcome(
            contact=reply.contact,
            q_latched=None if reply.q_latched is None else _array(reply.q_latched),
            q=_array(reply.q),
            io_line=reply.io_line,
            duration_s=reply.duration_s,
            speed_mps=reply.speed_mps,
            reason=reply.reason,
        )

    async def capture(
        self,
        pattern: str = "target",
        view: int = 0,
        *,
        encoding: str = "raw",
        timeout: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Expose a stereo pair -> (left (H, W) uint8, right (H, W) uint8, q (n,) rad, t s).

        Raw images are read-only views of the received frame (no copy).
        """
        reply = await self._request(
            lambda i: Capture(id=i, pattern=pattern, view=view, encoding=encoding),  # type: ignore[arg-type]
            CaptureDone,
            timeout,
        )
        images = [
            _decode_image(info, data)
            for info, data in zip(reply.images, reply.attachments, strict=True)
        ]
        by_camera = {info.camera: image for info, image in zip(reply.images, images, strict=True)}
        if set(by_camera) != {"left", "right"}:
            raise ProtocolViolation(
                f"capture reply has cameras {sorted(by_camera)}, not left/right"
            )
        return by_camera["left"], by_camera["right"], _array(reply.q), reply.time

    async def measure_targets(self, timeout: float | None = None) -> TargetsMeasurement:
        """The targets the controller's camera sees now, triangulated by the controller:
        each with its chain, p (3,) m in the camera frame and cov (3, 3) m^2, and the joint
        angles q (n,) rad at the measurement."""
        reply = await self._request(lambda i: MeasureTargets(id=i), TargetsMeasured,
                                    timeout)
        targets = tuple(
            TargetPoint(chain=t.chain, p=_array(t.p), cov=np.asarray(t.cov, dtype=float),
                        uv=None if t.uv is None else np.asarray(t.uv, dtype=float))
            for t in reply.targets
        )
        return TargetsMeasurement(q=_array(reply.q), time=reply.time, targets=targets)

    async def measure_tracker(self, timeout: float | None = None) -> TrackerReading:
        """The cell's laser tracker now: each reflector's point (3,) m in the tracker frame
        and covariance (3, 3) m^2, the lost ones, q (n,) rad and the tracker's nominal
        description (`measure_tracker`, docs/protocol.md)."""
        reply = await self._request(lambda i: MeasureTracker(id=i), TrackerMeasured,
                                    timeout)
        points = {r.name: (_array(r.p), np.asarray(r.cov, dtype=float))
                  for r in reply.reflectors}
        return TrackerReading(q=_array(reply.q), time=reply.time, points=points,
                              lost=tuple(reply.lost), description=dict(reply.description))

    async def sensor_read(self, sensor: str, request: JsonObject,
                          timeout: float | None = None) -> SensorReading:
        """A reading of the instrument `sensor` (`sensor_read`, docs/protocol.md): `request`
        and the reading are the instrument's own small JSON objects; q (n,) rad and the
        controller time at the reading. A controller without the instrument refuses
        (reason `unsupported`), a request it cannot read is a `bad_message` error."""
        reply = await self._request(
            lambda i: SensorRead(id=i, sensor=sensor, request=request),
            measurement_messages.SensorReading,
            timeout)
        return SensorReading(sensor=reply.sensor, q=_array(reply.q), time=reply.time,
                             reading=reply.reading)

    async def read_io(self, timeout: float | None = None) -> IoSnapshot:
        """Digital inputs and outputs."""
        reply = await self._request(lambda i: m.ReadIo(id=i), m.IoState, timeout)
        return IoSnapshot(tuple(reply.digital_inputs), tuple(reply.digital_outputs), reply.time)

    async def get_offsets(self, timeout: float | None = None) -> np.ndarray:
        """The zero offsets (n,) rad."""
        reply = await self._request(lambda i: m.GetOffsets(id=i), m.Offsets, timeout)
        return _array(reply.offsets)

    async def set_offsets(
        self, offsets: Any, timeout: float | None = None
    ) -> tuple[np.ndarray, str]:
        """Write the zero offsets (n,) rad -> (previous offsets (n,), rollback id)."""
        values = _floats(offsets)
        reply = await self._request(
            lambda i: m.SetOffsets(id=i, offsets=values), m.OffsetsSet, timeout
        )
        return _array(reply.previous), reply.rollback_id

    async def rollback(self, rollback_id: str, timeout: float | None = None) -> np.ndarray:
        """Undo the offset write `rollback_id`; returns the offsets now in force (n,) rad."""
        reply = await self._request(
            lambda i: m.RollbackOffsets(id=i, rollback_id=rollback_id),
            m.OffsetsRolledBack,
            timeout,
        )
        return _array(reply.offsets)

    async def abort(self, timeout: float | None = None) -> bool:
        """Stop the motion in progress; True if one was stopped."""
        reply = await self._request(lambda i: m.Abort(id=i), m.Aborted, timeout)
        return reply.was_moving

    async def heartbeat(self, timeout: float | None = None) -> float:
        """Liveness check; returns the controller's clock (s)."""
        reply = await self._request(lambda i: m.Heartbeat(id=i), m.HeartbeatReply, timeout)
        return reply.time

    def subscribe_io(self, maxsize: int = 10000) -> IoEventSubscription:
        """Receive IO edge events from now on (see IoEventSubscription)."""
        subscription = IoEventSubscription(maxsize, on_close=self._subscriptions.discard)
        self._subscriptions.add(subscription)
        return subscription

    # ------------------------------------------------------------------- internals

    def _motion_timeout(self, q: list[float], speed: float) -> float:
        """A motion's timeout (s): MOTION_TIMEOUT_MARGIN x the host's prediction of the move
        from the last reported angles to q at `speed` with the controller's reported limits
        (hostpc.planning.tour.move_times, the robot time's law) x the wall seconds per
        controller second the last move took; never below `motion_timeout` (nor when the
        client has no state of the controller yet)."""
        if self._q is None or self._limits is None or len(q) != self._q.size:
            return self.motion_timeout
        predicted = float(move_times(self._q, np.asarray(q, float), self._limits.rates(speed)))
        return max(self.motion_timeout,
                   MOTION_TIMEOUT_MARGIN * predicted * self._wall_per_robot_s)

    def _moved(self, q: list[float], duration_s: float, started: float) -> None:
        """Note where a motion ended and, for one of at least PACE_MIN_MOVE_S, its pace."""
        self._q = _array(q)
        if duration_s >= PACE_MIN_MOVE_S:
            wall = asyncio.get_running_loop().time() - started
            self._wall_per_robot_s = max(1.0, wall / duration_s)

    async def _request(
        self,
        make: Callable[[int], Request],
        reply_type: type[ReplyT],
        timeout: float | None,
    ) -> ReplyT:
        timeout = self.timeout if timeout is None else timeout
        attempt = 0
        while True:
            link = await self._ensure_link()
            request = make(link.conn.next_id())
            future = link.send(request)
            try:
                reply = await wait_for_reply(future, timeout)
            except asyncio.CancelledError as exc:  # Ctrl-C / SIGTERM (hostpc.cli.termination)
                link.pending.pop(request.id, None)
                if request.kind in MOTION_KINDS:
                    stopped = await self._abort_motion(link)
                    logger.info("%s interrupted: %s", request.kind, stopped)
                    exc.add_note(f"{request.kind} interrupted: {stopped}")
                raise
            except TimeoutError:
                link.pending.pop(request.id, None)
                stopped = ""
                if request.kind in MOTION_KINDS:
                    stopped = "; " + await self._abort_motion(link)
                raise RequestTimeout(
                    f"{request.kind} (request {request.id}) got no reply within {timeout} s "
                    f"from {self.host}:{self.port}{stopped}"
                ) from None
            except _LinkLostError as exc:
                if request.kind in IDEMPOTENT_KINDS and attempt < self.reconnect_attempts:
                    attempt += 1
                    logger.info("link lost during %s (%s); re-sending", request.kind, exc)
                    await asyncio.sleep(0.05 * attempt)
                    continue
                what = (
                    "not re-sent: it may or may not have been executed"
                    if request.kind not in IDEMPOTENT_KINDS
                    else f"gave up after {attempt} reconnections"
                )
                raise ConnectionFailed(
                    f"{exc} at {self.host}:{self.port} during {request.kind}; {what}"
                ) from None
            if isinstance(reply, m.ErrorReply):
                raise _reply_error(request.kind, reply)
            if not isinstance(reply, reply_type):
                raise ProtocolViolation(f"{request.kind} answered by {reply.kind}")
            return reply

    async def _abort_motion(self, link: _Link) -> str:
        """Best effort, within ABORT_AFTER_TIMEOUT_S: stop the robot after a motion timed out
        or was interrupted (its caller cancelled); says what happened."""
        if not link.alive:
            return "the link is down, abort not sent"
        try:
            future = link.send(m.Abort(id=link.conn.next_id()))
            reply = await wait_for_reply(future, ABORT_AFTER_TIMEOUT_S)
        except (TimeoutError, _LinkLostError, OSError, LocalProtocolError) as exc:
            logger.warning("abort of a motion failed: %s", str(exc) or type(exc).__name__)
            return "abort sent, not confirmed"
        if isinstance(reply, m.Aborted):
            return "abort sent: motion stopped" if reply.was_moving else "abort sent: not moving"
        return f"abort answered by {reply.kind}"

    async def _ensure_link(self) -> _Link:
        if self._link is not None and self._link.alive:
            return self._link
        if self._connecting is None:
            self._connecting = asyncio.Lock()
        async with self._connecting:
            if self._link is not None and self._link.alive:
                return self._link
            if self._link is not None:
                await self._link.close()
                self._link = None
            self._link = await self._open_link()
            return self._link

    async def _open_link(self) -> _Link:
        address = f"{self.host}:{self.port}"
        try:
            reader, writer = await wait_for_reply(
                asyncio.open_connection(self.host, self.port, limit=READ_CHUNK),
                self.connect_timeout, lambda opened: opened[1].close(),
            )
        except TimeoutError:
            raise ConnectionFailed(
                f"cannot reach controller at {address}: no answer within {self.connect_timeout} s"
            ) from None
        except OSError as exc:
            raise ConnectionFailed(
                f"cannot reach controller at {address}: {_os_error_text(exc)}"
            ) from None
        sock = writer.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = Connection(
            Role.CLIENT,
            token=self.token,
            max_frame_size=self.max_frame_size,
            client_name=self.client_name,
        )
        link = _Link(reader, writer, conn, self._on_io_edge)
        writer.write(conn.initiate())
        try:
            await wait_for_reply(asyncio.shield(link.handshake), self.connect_timeout)
        except TimeoutError:
            await link.close()
            raise ConnectionFailed(
                f"controller at {address} did not complete the handshake within "
                f"{self.connect_timeout} s"
            ) from None
        except BaseException:
            await link.close()
            raise
        self.connections_opened += 1
        return link

    def _on_io_edge(self, event: m.IoEdge) -> None:
        edge = IoEdgeEvent(event.line, event.value, event.time, _array(event.q_latched))
        for subscription in list(self._subscriptions):
            subscription.deliver(edge)
