"""`hostpc camera serve`: a stereo camera on this host, served over the zerocal protocol.

Any driver that fetches captures from "the zerocal camera service" (the UR driver: the
robot's host, port 47800) uses it unchanged. The service answers, after hello and auth
(the protocol's own `Connection` runs the handshake):

    capture     the next pair from the `StereoCamera` (pattern and view are accepted and
                ignored: the cameras show what is in front of them), PNG or raw as asked;
                q = [] (the camera knows no joints: the driver reads them itself), time =
                host clock of the left grab (s). A frozen or skewed pair, or a camera that
                stops delivering, is refused (`refused`, reason `camera`) with the one-line
                reason, and the service keeps serving.
    get_state   a robot-less state: no joints, `camera` = image size plus the --describe
                file (nominal mount, target, chessboard: what a controller would report)
    heartbeat   liveness; anything else is refused with reason `unsupported`.

Every capture's timing (host grab times, backend stamps, skew) is logged on one line.
Binds 127.0.0.1 unless told otherwise; one capture at a time for all sessions.

Against hostile peers, the controller's admission (docs/security.md), from the same
shared policies (`protocol.admission`): at most MAX_SESSIONS sessions, of which
MAX_UNAUTHENTICATED not yet authenticated; a newcomer evicts an unauthenticated session
(`busy`, then close: from the address holding the most, those that made requests before
authenticating first, the oldest first), so a peer holding idle sockets cannot lock a
driver with the token out; hello and auth must both happen within HANDSHAKE_TIMEOUT_S of
connecting; failed authentications delay every later session from that address
(`AuthThrottle`: 0.1, 0.2, 0.4 ... 2 s apart, a queue beyond half the handshake deadline
refused `busy`); an authenticated session silent for IDLE_TIMEOUT_S is closed. Refusals and
client errors are logged once per interval with a count.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time

import numpy as np

from hostpc.errors import ZerocalError
from hostpc.json_object import JsonObject
from hostpc.sensors.stereo_camera import StereoCamera, StereoPair
from hostpc.transport.waiting import wait_for_reply
from protocol import messages as m
from protocol.admission import AuthThrottle, LogBudget, SessionSlots
from protocol.connection import Connection
from protocol.errors import ErrorCode, LocalProtocolError
from protocol.measurement_messages import Capture, CaptureDone, ImageInfo
from protocol.message_base import Request, _Message
from protocol.session_states import ConnectionState, Rejected, Role, StateChanged

logger = logging.getLogger(__name__)

SERVER_NAME = "zerocal-camera-service"
READ_CHUNK = 64 * 1024
PRE_AUTH_MAX_FRAME_SIZE = 64 * 1024
HANDSHAKE_TIMEOUT_S = 5.0
"""hello AND auth must be done this long after connecting (s); as the controller's."""
IDLE_TIMEOUT_S = 300.0
MAX_SESSIONS = 16
MAX_UNAUTHENTICATED = 8
LOG_INTERVAL_S = 10.0
CLOSE_DRAIN_S = 1.0


class _Session:
    """One client connection of the service: its protocol state and socket."""

    def __init__(self, conn: Connection, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter) -> None:
        self.conn, self.reader, self.writer = conn, reader, writer
        peer = writer.get_extra_info("peername")
        self.host = str(peer[0]) if isinstance(peer, tuple) else str(peer)
        self.evicted = False

    def close_with(self, why: str) -> None:
        """A `busy` error (if the session can still take one), then close."""
        self.evicted = True
        if not self.conn.closed and not self.writer.is_closing():
            with contextlib.suppress(LocalProtocolError):
                self.writer.write(self.conn.send_error(None, ErrorCode.BUSY, why))
        if not self.writer.is_closing():
            self.writer.close()


class CameraService:
    """Serve `camera` to zerocal protocol clients proving `token`. description: extra
    keys of the `camera` mapping in get_state (e.g. the cell's nominal mount and target)."""

    def __init__(self, camera: StereoCamera, token: str,
                 description: JsonObject | None = None) -> None:
        self.camera = camera
        self.token = token
        self.description = dict(description or {})
        self.image_size: tuple[int, int] | None = None
        self.captures = 0
        self._capture_lock = asyncio.Lock()
        self._slots: SessionSlots[_Session] = SessionSlots(MAX_SESSIONS, MAX_UNAUTHENTICATED)
        self.auth_throttle = AuthThrottle(max_wait_s=HANDSHAKE_TIMEOUT_S / 2)
        self.sessions_evicted = 0
        self.sessions_refused = 0
        self._log_budget = LogBudget(interval_s=LOG_INTERVAL_S)
        self._t0 = time.monotonic()

    async def start(self, host: str = "127.0.0.1", port: int = 47800) -> asyncio.Server:
        """Listen on host:port (port 0: a free one); returns the asyncio server."""
        return await asyncio.start_server(self._session, host, port)

    def _warn(self, kind: str, message: str, *args: object) -> None:
        """One warning per kind every LOG_INTERVAL_S, with the count held back."""
        held = self._log_budget.admit(kind, time.monotonic())
        if held is not None:
            logger.warning(message + (f" ({held} more since the last report)" if held else ""),
                           *args)

    async def _session(self, reader: asyncio.StreamReader,
                       writer: asyncio.StreamWriter) -> None:
        loop = asyncio.get_running_loop()
        session = _Session(Connection(Role.SERVER, token=self.token, server_name=SERVER_NAME,
                                      pre_auth_max_frame_size=PRE_AUTH_MAX_FRAME_SIZE),
                           reader, writer)
        wait = self.auth_throttle.reserve(session.host, loop.time())
        admitted, evicted = (False, []) if wait is None else self._slots.admit(session,
                                                                               session.host)
        for old in evicted:
            self.sessions_evicted += 1
            old.close_with(f"evicted for a newer connection: at most {MAX_UNAUTHENTICATED} "
                           f"sessions may be unauthenticated (and {MAX_SESSIONS} in all)")
        if evicted:
            self._warn("evicted", "evicted %d unauthenticated session(s) for newer ones",
                       len(evicted))
        if not admitted:
            self.sessions_refused += 1
            why = (f"too many failed authentications from {session.host}; try again later"
                   if wait is None else f"too many sessions: at most {MAX_SESSIONS}")
            self._warn(why, "refusing %s: %s", session.host, why)
            session.close_with(why)
            await _closed(writer)
            return
        try:
            if wait:
                await asyncio.sleep(wait)
            await self._serve(session, loop.time() + HANDSHAKE_TIMEOUT_S)
        except (ConnectionError, OSError):
            pass
        finally:
            self._slots.remove(session)
            await _closed(writer)

    async def _serve(self, session: _Session, handshake_deadline: float) -> None:
        conn, reader, writer = session.conn, session.reader, session.writer
        loop = asyncio.get_running_loop()
        while not conn.closed and not session.evicted:
            timeout = IDLE_TIMEOUT_S if conn.state is ConnectionState.READY \
                else handshake_deadline - loop.time()
            try:
                data = await wait_for_reply(reader.read(READ_CHUNK), max(timeout, 0.0))
            except (TimeoutError, ConnectionError, OSError):
                break
            events = conn.receive_data(data)
            writer.write(conn.data_to_send())
            for event in events:
                if isinstance(event, Request):
                    if conn.state is not ConnectionState.READY:
                        self._slots.loitering(session)
                    writer.write(conn.send(await self._answer(event)))
                elif isinstance(event, Rejected):
                    self._warn(f"client {event.code}", "client %s: %s (%s)", session.host,
                               event.message, event.code)
                    if event.code is ErrorCode.AUTH_FAILED:
                        self.auth_throttle.failed(session.host, loop.time())
                elif isinstance(event, StateChanged) and event.new is ConnectionState.READY:
                    self._slots.authenticated(session)
            await writer.drain()
            if not data:
                break

    async def _answer(self, request: Request) -> _Message:
        try:
            if isinstance(request, Capture):
                return await self._capture(request)
            if isinstance(request, m.GetState):
                return self._state(request)
            if isinstance(request, m.Heartbeat):
                return m.HeartbeatReply(reply_to=request.id, time=self._now())
        except ZerocalError as exc:
            logger.warning("capture refused: %s", exc)
            return m.ErrorReply(reply_to=request.id, code=ErrorCode.REFUSED,
                                message=str(exc)[:4000], reason="camera")
        return m.ErrorReply(reply_to=request.id, code=ErrorCode.REFUSED,
                            message=f"{SERVER_NAME} serves captures only, not {request.kind}",
                            reason="unsupported")

    def _now(self) -> float:
        return time.monotonic() - self._t0

    def _state(self, request: m.GetState) -> m.State:
        camera: JsonObject = dict(self.description)  # the wire's camera object
        if self.image_size is not None:
            camera.setdefault("image_width", self.image_size[0])
            camera.setdefault("image_height", self.image_size[1])
        return m.State(reply_to=request.id, robot_name="", n_joints=0, mode="idle",
                       time=self._now(), q=[], zero_offsets=[], q_min=[], q_max=[],
                       digital_inputs=[], digital_outputs=[], camera=camera,
                       authenticated=True)

    async def _capture(self, request: Capture) -> CaptureDone:
        async with self._capture_lock:
            pair: StereoPair = await asyncio.to_thread(self.camera.capture)
        self.captures += 1
        height, width = pair.left.shape
        self.image_size = (width, height)
        logger.info("capture %d: skew %.3f ms, grab left %.6f s right %.6f s, stamps "
                    "%.6f / %.6f s", pair.index, pair.skew_s * 1e3, pair.t_left - self._t0,
                    pair.t_right - self._t0, pair.stamp_left, pair.stamp_right)
        infos, payloads = [], []
        for camera, image in (("left", pair.left), ("right", pair.right)):
            pixels = np.ascontiguousarray(image, dtype=np.uint8)
            payload: bytes | memoryview = _png(pixels) if request.encoding == "png" \
                else pixels.reshape(-1).data
            infos.append(ImageInfo(camera=camera, width=pixels.shape[1],  # type: ignore[arg-type]
                                     height=pixels.shape[0], encoding=request.encoding,
                                     nbytes=memoryview(payload).nbytes))
            payloads.append(payload)
        reply = CaptureDone(reply_to=request.id, pattern=request.pattern, view=request.view,
                              q=[], time=pair.t_left - self._t0, images=infos)
        reply.with_attachments(*payloads)
        return reply


async def _closed(writer: asyncio.StreamWriter) -> None:
    """Close `writer` and wait (briefly) until it is."""
    if not writer.is_closing():
        writer.close()
    with contextlib.suppress(Exception):  # a cancel lost here (gh-86296): the session ends
        await asyncio.wait_for(writer.wait_closed(), CLOSE_DRAIN_S)


def _png(pixels: np.ndarray) -> bytes:
    import cv2

    ok, encoded = cv2.imencode(".png", pixels)
    if not ok:
        raise ZerocalError("PNG encoding failed")
    return bytes(encoded)
