"""The request handlers of a controller-stub session: one coroutine per request kind.

Each handler turns one protocol request into calls on the simulation (through the server for
what is shared by all sessions: motion pacing, rollback ids, the truth file) and returns the
reply. A handler refuses with `RequestRefusedError` (a protocol error code) or lets the
simulation's `SimulationRefused` through; the session turns both into `error` replies. Joint
angles and offsets are radians (reported frame), times seconds.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.sensors.registry import SensorRequestError, SimSensors, UnknownSensor
from controller_stub.world.controller_state import SimulatedController
from controller_stub.world.motion import GuardedMoveResult, MotionPlan, MoveResult
from protocol import messages as m
from protocol.connection import Connection
from protocol.errors import ErrorCode
from protocol.measurement_messages import (
    Capture,
    CaptureDone,
    ImageInfo,
    MeasureTargets,
    MeasureTracker,
    ReflectorObservation,
    SensorRead,
    SensorReading,
    TargetObservation,
    TargetsMeasured,
    TrackerMeasured,
)
from protocol.message_base import _Message

# the server's logger: log records keep the name they had before the server was split
logger = logging.getLogger("controller_stub.network.server")

Handler = Callable[[Any], Awaitable[_Message]]

MIN_MOTION_SPEED = 1e-3
"""Slowest speed fraction a motion may ask for: slower ones are refused (reason "speed"),
so that no request can make a motion last practically forever (or overflow the clock)."""


class RequestRefusedError(Exception):
    """A handler refuses a request with a protocol error code (busy, unknown rollback...)."""

    def __init__(self, code: ErrorCode, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.reason = reason


class MotionHost(Protocol):
    """What the handlers use of the server (`controller_stub.network.server.ControllerServer`):
    the state shared by all sessions (motion pacing, mode, the truth file)."""

    def mode(self) -> str: ...
    def joint_positions(self) -> np.ndarray: ...
    def begin_motion(self) -> None: ...
    async def execute_motion(self, plan: MotionPlan) -> MoveResult | GuardedMoveResult: ...
    def abort_motion(self) -> bool: ...
    def write_truth(self) -> None: ...
    @property
    def sensors(self) -> SimSensors: ...


ROLLBACK_ID_PREFIX = "rb-"
"""A rollback id names a write in the simulation's offset history: "rb-<history id>"."""


class RequestHandlers:
    """The request handlers of one `controller_stub.network.session.Session`, by request kind.

    server: what is shared by all sessions (`MotionHost`); sim: the simulation; conn: the
    session's protocol connection (authenticated or not); peer: its address, for the log.
    The session holds one and dispatches through `table()`.
    """

    def __init__(self, server: MotionHost, sim: SimulatedController, conn: Connection,
                 peer: str) -> None:
        self.server = server
        self.sim = sim
        self.conn = conn
        self.peer = peer

    def table(self) -> dict[str, Handler]:
        """Request kind -> bound handler."""
        return {
            "get_state": self._get_state,
            "read_io": self._read_io,
            "move_joints": self._move_joints,
            "guarded_move": self._guarded_move,
            "abort": self._abort,
            "capture": self._capture,
            "measure_targets": self._measure_targets,
            "measure_tracker": self._measure_tracker,
            "sensor_read": self._sensor_read,
            "get_offsets": self._get_offsets,
            "set_offsets": self._set_offsets,
            "rollback_offsets": self._rollback,
            "heartbeat": self._heartbeat,
        }

    async def _get_state(self, request: m.GetState) -> m.State:
        sim = self.sim
        q_min, q_max = sim.joint_limits()
        return m.State(
            reply_to=request.id,
            robot_name=str(sim.robot_name),
            n_joints=int(sim.n_joints),
            mode=self.server.mode(),  # type: ignore[arg-type]
            time=float(sim.time),
            q=float_list(self.server.joint_positions()),  # along the path while moving
            zero_offsets=float_list(sim.zero_offsets()),
            q_min=float_list(q_min),
            q_max=float_list(q_max),
            digital_inputs=[bool(v) for v in sim.digital_inputs()],
            digital_outputs=[bool(v) for v in sim.digital_outputs()],
            camera=json.loads(json.dumps(sim.camera_description(), default=json_default)),
            authenticated=self.conn.authenticated,
            max_joint_speed=float_list(sim.max_joint_speed()),
            max_joint_acceleration=float_list(sim.max_joint_acceleration()),
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

    async def _run_motion(
        self, q_target: np.ndarray, speed: float, io_line: int | None
    ) -> MoveResult | GuardedMoveResult:
        """Plan, pace and finish a motion (stopped part-way by an abort); the simulation's
        MoveResult / GuardedMoveResult."""
        if not speed >= MIN_MOTION_SPEED:
            raise RequestRefusedError(
                ErrorCode.REFUSED,
                f"speed {speed:g} is below the slowest this controller moves "
                f"({MIN_MOTION_SPEED:g} of the maximum)",
                reason="speed",
            )
        self.server.begin_motion()
        plan = self.sim.begin_move(q_target, speed, io_line)
        return await self.server.execute_motion(plan)

    async def _move_joints(self, request: m.MoveJoints) -> m.MoveDone:
        q_target = self._check_joints(request.q)
        result = await self._run_motion(q_target, request.speed, None)
        assert isinstance(result, MoveResult)
        return m.MoveDone(
            reply_to=request.id,
            completed=bool(result.completed),
            q=float_list(result.q),
            duration_s=float(result.duration_s),
            reason=result.reason,
        )

    async def _guarded_move(self, request: m.GuardedMove) -> m.GuardedMoveDone:
        q_target = self._check_joints(request.q)
        result = await self._run_motion(q_target, request.speed, request.io_line)
        assert isinstance(result, GuardedMoveResult)
        return m.GuardedMoveDone(
            reply_to=request.id,
            contact=bool(result.contact),
            q_latched=None if result.q_latched is None else float_list(result.q_latched),
            q=float_list(result.q),
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

    async def _capture(self, request: Capture) -> CaptureDone:
        frame = self.sim.capture_stereo(pattern=request.pattern, view=request.view)
        infos: list[ImageInfo] = []
        payloads: list[bytes | memoryview] = []
        for camera, image in (("left", frame.left), ("right", frame.right)):
            pixels = np.ascontiguousarray(image, dtype=np.uint8)
            if pixels.ndim != 2:
                raise RuntimeError(f"{camera} image has shape {pixels.shape}, expected (H, W)")
            height, width = pixels.shape
            payload = _encode_png(pixels) if request.encoding == "png" else pixels.reshape(-1).data
            infos.append(
                ImageInfo(
                    camera=camera,  # type: ignore[arg-type]
                    width=width,
                    height=height,
                    encoding=request.encoding,
                    nbytes=memoryview(payload).nbytes,
                )
            )
            payloads.append(payload)
        reply = CaptureDone(
            reply_to=request.id,
            pattern=request.pattern,
            view=request.view,
            q=float_list(frame.q),
            time=float(frame.time),
            images=infos,
        )
        reply.with_attachments(*payloads)
        return reply

    async def _measure_targets(self, request: MeasureTargets) -> TargetsMeasured:
        """The simulation's triangulated targets (its `targets` sensor); a simulation
        without that sensor refuses with reason `unsupported`."""
        sensor = self.sim.targets
        if sensor is None:
            raise SimulationRefused("unsupported", f"{self.sim.robot_name} has no target "
                                    "measurement; use capture")
        # during a motion: at its start pose, with that q (as capture)
        result = sensor.measure_targets()
        targets = [
            TargetObservation(chain=str(chain), p=float_list(seen["p"]),
                                cov=np.asarray(seen["cov"], dtype=float).reshape(3, 3).tolist(),
                                uv=(None if seen.get("uv") is None else
                                    np.asarray(seen["uv"], dtype=float).reshape(2, 2).tolist()))
            for chain, seen in result["targets"].items()
        ]
        return TargetsMeasured(reply_to=request.id, q=float_list(result["q"]),
                                 time=float(result["time"]), targets=targets)

    async def _measure_tracker(self, request: MeasureTracker) -> TrackerMeasured:
        """The laser tracker's reflectors (the simulation's `tracker` sensor,
        controller_stub/sensors/world_point.py); a simulation without a tracker refuses with
        reason `unsupported`."""
        tracker = self.sim.tracker
        if tracker is None:
            raise SimulationRefused("unsupported", f"{self.sim.robot_name} has no tracker")
        result = tracker.measure_tracker()
        reflectors = [
            ReflectorObservation(name=str(name), p=float_list(seen["p"]),
                                   cov=np.asarray(seen["cov"], dtype=float).reshape(3, 3).tolist())
            for name, seen in result["seen"].items()
        ]
        return TrackerMeasured(reply_to=request.id, q=float_list(result["q"]),
                                 time=float(result["time"]), reflectors=reflectors,
                                 lost=[str(n) for n in result["lost"]],
                                 description=json.loads(json.dumps(result["description"])))

    async def _sensor_read(self, request: SensorRead) -> SensorReading:
        """A reading of a kind's own simulated sensor (controller_stub/sensors/registry.py)
        with the joint angles and clock at the reading: `unsupported` for a sensor this
        stub does not simulate, `bad_message` for a request the sensor cannot read."""
        try:
            sensor = self.server.sensors.sensor(request.sensor)
        except UnknownSensor as exc:
            raise SimulationRefused("unsupported", f"{self.sim.robot_name}: {exc}") from None
        self.sim.settle_for_measurement()  # a reading of the robot: it stands still first
        q, time = float_list(self.sim.joint_positions()), float(self.sim.time)
        try:
            reading = sensor.read(request.request)
        except SensorRequestError as exc:
            raise RequestRefusedError(ErrorCode.BAD_MESSAGE,
                                      f"sensor_read {request.sensor}: {exc}") from None
        self.sim.hold_for_capture()  # the reading takes capture_s, as any measurement does
        return SensorReading(reply_to=request.id, sensor=request.sensor, q=q, time=time,
                               reading=json.loads(json.dumps(reading, default=json_default)))

    async def _get_offsets(self, request: m.GetOffsets) -> m.Offsets:
        return m.Offsets(reply_to=request.id, offsets=float_list(self.sim.zero_offsets()))

    async def _set_offsets(self, request: m.SetOffsets) -> m.OffsetsSet:
        offsets = self._check_joints(request.offsets)
        self._refuse_while_moving("write the zero offsets")
        previous = float_list(self.sim.set_zero_offsets(offsets))
        rollback_id = f"{ROLLBACK_ID_PREFIX}{self.sim.last_history_id}"
        logger.info("client %s set zero offsets (rollback id %s)", self.peer, rollback_id)
        self.server.write_truth()
        return m.OffsetsSet(
            reply_to=request.id,
            offsets=float_list(self.sim.zero_offsets()),
            previous=previous,
            rollback_id=rollback_id,
        )

    async def _rollback(self, request: m.RollbackOffsets) -> m.OffsetsRolledBack:
        history_id = self._written_history_id(request.rollback_id)
        self._refuse_while_moving("roll back the zero offsets")
        replaced = float_list(self.sim.undo_write(history_id))
        logger.info("client %s rolled back offsets to %s", self.peer, request.rollback_id)
        self.server.write_truth()
        return m.OffsetsRolledBack(
            reply_to=request.id, offsets=float_list(self.sim.zero_offsets()), replaced=replaced
        )

    def _written_history_id(self, rollback_id: str) -> int:
        """The offset-history id of the write `rollback_id` names (one that can be undone);
        RequestRefusedError(UNKNOWN_ROLLBACK) otherwise."""
        digits = rollback_id.removeprefix(ROLLBACK_ID_PREFIX)
        if rollback_id.startswith(ROLLBACK_ID_PREFIX) and digits.isascii() and digits.isdigit():
            history_id = int(digits)
            if history_id > 0 and any(i == history_id for i, _ in self.sim.offset_history()):
                return history_id
        raise RequestRefusedError(
            ErrorCode.UNKNOWN_ROLLBACK, f"unknown rollback id {rollback_id!r}"
        )

    async def _heartbeat(self, request: m.Heartbeat) -> m.HeartbeatReply:
        return m.HeartbeatReply(reply_to=request.id, time=float(self.sim.time))


def float_list(values: Any) -> list[float]:
    """A flat list of Python floats from any array-like (for the wire)."""
    return [float(v) for v in np.asarray(values, dtype=float).reshape(-1)]


def _encode_png(pixels: np.ndarray) -> bytes:
    import cv2

    ok, buffer = cv2.imencode(".png", pixels)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buffer.tobytes()



def json_default(value: Any) -> Any:
    """`json.dumps` fallback for numpy arrays and scalars and paths."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
