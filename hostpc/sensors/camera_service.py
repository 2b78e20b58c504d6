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
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from hostpc.errors import ZerocalError
from hostpc.sensors.stereo_camera import StereoCamera, StereoPair
from protocol import messages as m
from protocol.connection import Connection, ConnectionState, Rejected, Role
from protocol.errors import ErrorCode

logger = logging.getLogger(__name__)

SERVER_NAME = "zerocal-camera-service"
READ_CHUNK = 64 * 1024
PRE_AUTH_MAX_FRAME_SIZE = 64 * 1024
HANDSHAKE_TIMEOUT_S = 10.0
MAX_SESSIONS = 8


class CameraService:
    """Serve `camera` to zerocal protocol clients proving `token`. description: extra
    keys of the `camera` mapping in get_state (e.g. the cell's nominal mount and target)."""

    def __init__(self, camera: StereoCamera, token: str,
                 description: Mapping[str, Any] | None = None) -> None:
        self.camera = camera
        self.token = token
        self.description = dict(description or {})
        self.image_size: tuple[int, int] | None = None
        self.captures = 0
        self._capture_lock = asyncio.Lock()
        self._sessions: set[asyncio.Task[None]] = set()
        self._t0 = time.monotonic()

    async def start(self, host: str = "127.0.0.1", port: int = 47800) -> asyncio.Server:
        """Listen on host:port (port 0: a free one); returns the asyncio server."""
        return await asyncio.start_server(self._session, host, port)

    async def _session(self, reader: asyncio.StreamReader,
                       writer: asyncio.StreamWriter) -> None:
        if len(self._sessions) >= MAX_SESSIONS:
            writer.close()
            return
        task = asyncio.current_task()
        assert task is not None
        self._sessions.add(task)
        conn = Connection(Role.SERVER, token=self.token, server_name=SERVER_NAME,
                          pre_auth_max_frame_size=PRE_AUTH_MAX_FRAME_SIZE)
        try:
            while not conn.closed:
                timeout = None if conn.state is ConnectionState.READY else HANDSHAKE_TIMEOUT_S
                try:
                    data = await asyncio.wait_for(reader.read(READ_CHUNK), timeout)
                except (TimeoutError, ConnectionError, OSError):
                    break
                events = conn.receive_data(data)
                writer.write(conn.data_to_send())
                for event in events:
                    if isinstance(event, m.Request):
                        writer.write(conn.send(await self._answer(event)))
                    elif isinstance(event, Rejected):
                        logger.warning("client: %s (%s)", event.message, event.code)
                await writer.drain()
                if not data:
                    break
        except (ConnectionError, OSError):
            pass
        finally:
            self._sessions.discard(task)
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()

    async def _answer(self, request: m.Request) -> m._Message:
        try:
            if isinstance(request, m.Capture):
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
        camera: dict[str, Any] = dict(self.description)
        if self.image_size is not None:
            camera.setdefault("image_width", self.image_size[0])
            camera.setdefault("image_height", self.image_size[1])
        return m.State(reply_to=request.id, robot_name="", n_joints=0, mode="idle",
                       time=self._now(), q=[], zero_offsets=[], q_min=[], q_max=[],
                       digital_inputs=[], digital_outputs=[], camera=camera,
                       authenticated=True)

    async def _capture(self, request: m.Capture) -> m.CaptureDone:
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
            infos.append(m.ImageInfo(camera=camera, width=pixels.shape[1],  # type: ignore[arg-type]
                                     height=pixels.shape[0], encoding=request.encoding,
                                     nbytes=memoryview(payload).nbytes))
            payloads.append(payload)
        reply = m.CaptureDone(reply_to=request.id, pattern=request.pattern, view=request.view,
                              q=[], time=pair.t_left - self._t0, images=infos)
        reply.with_attachments(*payloads)
        return reply


def _png(pixels: np.ndarray) -> bytes:
    import cv2

    ok, encoded = cv2.imencode(".png", pixels)
    if not ok:
        raise ZerocalError("PNG encoding failed")
    return bytes(encoded)
