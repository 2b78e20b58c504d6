"""Record a run's robot traffic and images (`--record DIR`) and replay it (`--replay DIR`).

A recording is a folder:

    recording.json     {"format": "zerocal-recording/1", "settings", "cell_file", "known",
                        "default_known", "robot", "measure_targets", "sensor_read"}: what
                        the run was asked and which recorded calls the robot offered
    tape.jsonl         one line per robot call in order: {"n", "call", "args", "result"} or
                       {"n", "call", "args", "error": {"type", "message", "code", "reason"}};
                       a capture's result names its frame and timing, not the pixels
    left_%04d.png      the raw image pairs, frame k of every capture in order (lossless
    right_%04d.png     PNG, so the folder is also an image-sequence camera source)

`RecordingAdapter` wraps any RobotAdapter and writes that tape as the run goes (its
capabilities are the wrapped adapter's: `measure_targets` and `sensor_read` (any kind's own
instrument, its request and reading as they are) recorded, the others passed on
unrecorded). `ReplayAdapter` answers the same calls from the tape, so
`hostpc calibrate --replay DIR` runs the whole pipeline (rig calibration, detection, fit,
diagnose) without a robot and reaches the same dataset to the last digit: floats go through
JSON as their shortest round-trip text and images through PNG bit for bit. A replay that
asks for something the tape does not hold next (another pose, another call) stops with
`ReplayDiverged`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hostpc.errors import ConnectionFailed, ControllerError, InputError, RequestTimeout
from hostpc.json_object import JsonObject
from hostpc.robots.base import (
    Capabilities,
    ContactOutcome,
    MeasuredTarget,
    MoveOutcome,
    RobotAdapter,
    RobotState,
    SensorPort,
    StereoCapture,
    TargetCamera,
    TargetMeasurement,
)

if TYPE_CHECKING:  # the caller's and the I/O layer's value types (imported when used)
    from hostpc.calibrate.run_values import RobotInfo
    from hostpc.methods.base import RunSettings
    from hostpc.transport import SensorReading

RECORDING_FORMAT = "zerocal-recording/1"
HEADER_FILE = "recording.json"
TAPE_FILE = "tape.jsonl"
IMAGE_PATTERN = "{camera}_{index:04d}.png"


class ReplayDiverged(InputError):
    """The replayed run asked for something the recording does not hold next."""


def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, float).reshape(-1)]


def _array(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=float)


def _state_to_json(s: RobotState) -> JsonObject:
    return {"q": _floats(s.q), "zero_offsets": _floats(s.zero_offsets),
            "q_min": _floats(s.q_min), "q_max": _floats(s.q_max),
            "digital_inputs": [bool(b) for b in s.digital_inputs],
            "digital_outputs": [bool(b) for b in s.digital_outputs],
            "camera": s.camera, "robot": s.robot, "extra": s.extra}


def _state_from_json(d: JsonObject) -> RobotState:
    return RobotState(q=_array(d["q"]), zero_offsets=_array(d["zero_offsets"]),
                      q_min=_array(d["q_min"]), q_max=_array(d["q_max"]),
                      digital_inputs=tuple(d["digital_inputs"]),
                      digital_outputs=tuple(d["digital_outputs"]), camera=dict(d["camera"]),
                      robot=str(d["robot"]), extra=dict(d["extra"]))


def _error_to_json(exc: BaseException) -> JsonObject:
    return {"type": type(exc).__name__, "message": str(exc),
            "code": getattr(exc, "code", None), "reason": getattr(exc, "reason", None)}


def _error_from_json(d: JsonObject) -> BaseException:
    from hostpc.transport import ControllerRefusedError

    kind, message = d.get("type"), str(d.get("message", ""))
    if kind == "ControllerRefusedError" or d.get("code"):
        return ControllerRefusedError(message, str(d.get("code") or "refused"), d.get("reason"))
    for cls in (RequestTimeout, ConnectionFailed):
        if kind == cls.__name__:
            return cls(message)
    return ControllerError(f"{kind}: {message}")


def _targets_to_json(m: TargetMeasurement) -> JsonObject:
    return {"q": _floats(m.q), "t": float(m.t), "targets": [
        {"chain": t.chain, "p": _floats(t.p), "cov": np.asarray(t.cov, float).tolist(),
         **({} if t.uv is None else {"uv": np.asarray(t.uv, float).tolist()})}
        for t in m.targets]}


def _targets_from_json(r: JsonObject) -> TargetMeasurement:
    return TargetMeasurement(q=_array(r["q"]), t=float(r["t"]), targets=tuple(
        MeasuredTarget(chain=t["chain"], p=_array(t["p"]), cov=_array(t["cov"]),
                       uv=None if t.get("uv") is None else _array(t["uv"]))
        for t in r["targets"]))


def _reading_to_json(r: SensorReading) -> JsonObject:
    return {"sensor": r.sensor, "q": _floats(r.q), "time": float(r.time),
            "reading": r.reading}


def _reading_from_json(r: JsonObject) -> SensorReading:
    from hostpc.transport import SensorReading

    return SensorReading(sensor=str(r["sensor"]), q=_array(r["q"]), time=float(r["time"]),
                         reading=dict(r["reading"]))


@dataclass(frozen=True)
class RecordingHeader:
    """recording.json as a value: what the run was asked (its settings, its --cell
    document, the frames declared known, None: the cell's, and the simulated cell's
    default), how the robot was reached and the host cameras' sources; and which recorded
    calls the robot offered (`RecordingAdapter` fills those in). cell_file is the --cell
    document as read (hostpc.methods.cell parses it)."""

    settings: RunSettings | None
    cell_file: JsonObject | None = None
    known: tuple[str, ...] | None = None
    default_known: tuple[str, ...] = ()
    robot: RobotInfo | None = None
    cameras: tuple[str, ...] | None = None
    measure_targets: bool = False
    sensor_read: bool = False

    def to_json(self) -> JsonObject:
        """recording.json's document (a recording without `sensor_read` reads as before)."""
        document: JsonObject = {
            "format": RECORDING_FORMAT,
            "settings": None if self.settings is None else self.settings.to_dict(),
            "cell_file": self.cell_file,
            "known": None if self.known is None else list(self.known),
            "default_known": list(self.default_known),
            "robot": None if self.robot is None else self.robot.to_dict(),
            "cameras": None if self.cameras is None else list(self.cameras),
            "measure_targets": self.measure_targets}
        if self.sensor_read:
            document["sensor_read"] = True
        return document

    @classmethod
    def from_json(cls, data: JsonObject, folder: Path) -> RecordingHeader:
        """recording.json's document of `folder` as a value; InputError (one line)."""
        from hostpc.calibrate.run_values import RobotInfo
        from hostpc.methods.base import RunSettings

        try:
            settings = RunSettings.from_dict(data["settings"])
            robot = None if data.get("robot") is None else RobotInfo(**data["robot"])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"--replay {folder}: recorded settings unreadable ({exc})") from None
        known, cameras = data.get("known"), data.get("cameras")
        return cls(settings=settings, cell_file=data.get("cell_file"),
                   known=None if known is None else tuple(known),
                   default_known=tuple(data.get("default_known") or ()), robot=robot,
                   cameras=None if cameras is None else tuple(cameras),
                   measure_targets=bool(data.get("measure_targets")),
                   sensor_read=bool(data.get("sensor_read")))


class RecordingAdapter:
    """Wraps `robot`; every call and its answer go to the recording in `folder`.
    header: the run's inputs (recording.json). Images are written as PNG as they come.
    capabilities: the robot's, its target camera and named instruments recorded too
    (`RecordedTargets`, `RecordedSensors`)."""

    def __init__(self, robot: RobotAdapter, folder: Path, header: RecordingHeader) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        if (folder / TAPE_FILE).exists():
            raise InputError(f"--record {folder}: already holds a recording")
        self.robot = robot
        self.folder = folder
        self._n = 0
        self._frames = 0
        inner = robot.capabilities
        self.capabilities = replace(
            inner,
            targets=None if inner.targets is None else RecordedTargets(self, inner.targets),
            sensors=None if inner.sensors is None else RecordedSensors(self, inner.sensors))
        self.header = replace(header, measure_targets=inner.targets is not None,
                              sensor_read=inner.sensors is not None)
        (folder / HEADER_FILE).write_text(json.dumps(self.header.to_json(), indent=2) + "\n",
                                          encoding="utf-8")
        self._tape = (folder / TAPE_FILE).open("a", encoding="utf-8")

    @property
    def driver(self) -> str:
        """The recorded robot's driver."""
        return self.robot.driver

    def _write(self, entry: JsonObject) -> None:
        entry = {"n": self._n, **entry, "wall": time.time()}
        self._n += 1
        self._tape.write(json.dumps(entry, allow_nan=False) + "\n")
        self._tape.flush()

    async def record(self, call: str, args: JsonObject, run: Callable[[], Any],
                     encode: Callable[[Any], Any]) -> Any:
        """`await run()`, its answer (`encode`d) or its error written to the tape."""
        try:
            result = await run()
        except (ControllerError, ConnectionFailed) as exc:
            self._write({"call": call, "args": args, "error": _error_to_json(exc)})
            raise
        self._write({"call": call, "args": args, "result": encode(result)})
        return result

    async def state(self) -> RobotState:
        return await self.record("state", {}, self.robot.state, _state_to_json)

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        return await self.record(
            "move_joints", {"q": _floats(q), "speed": float(speed)},
            lambda: self.robot.move_joints(q, speed),
            lambda o: {"completed": o.completed, "q": _floats(o.q), "reason": o.reason})

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        return await self.record(
            "guarded_move", {"q": _floats(q), "speed": float(speed), "io_line": int(io_line)},
            lambda: self.robot.guarded_move(q, speed, io_line),
            lambda o: {"contact": o.contact, "q": _floats(o.q), "reason": o.reason,
                       "q_latched": None if o.q_latched is None else _floats(o.q_latched),
                       "speed": None if o.speed is None else float(o.speed)})

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        return await self.record(
            "capture", {"pattern": pattern, "view": int(view)},
            lambda: self.robot.capture(pattern, view), self._save_capture)

    def _save_capture(self, c: StereoCapture) -> JsonObject:
        import cv2

        frame = self._frames
        for camera, image in (("left", c.left), ("right", c.right)):
            path = self.folder / IMAGE_PATTERN.format(camera=camera, index=frame)
            if not cv2.imwrite(str(path), np.ascontiguousarray(image)):
                raise InputError(f"--record {self.folder}: cannot write {path.name}")
        self._frames += 1
        result: JsonObject = {"frame": frame, "q": _floats(c.q), "t": float(c.t)}
        clock = self.capabilities.capture_timing  # host cameras: stamps and skew
        timing = None if clock is None else clock.last_timing
        if timing is not None:
            result["timing"] = timing.to_json()
        return result

    async def get_offsets(self) -> np.ndarray:
        return await self.record("get_offsets", {}, self.robot.get_offsets, _floats)

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        return await self.record(
            "set_offsets", {"offsets": _floats(offsets)},
            lambda: self.robot.set_offsets(offsets),
            lambda r: {"previous": _floats(r[0]), "rollback_id": str(r[1])})

    async def rollback(self, rollback_id: str) -> np.ndarray:
        return await self.record("rollback", {"rollback_id": rollback_id},
                                lambda: self.robot.rollback(rollback_id), _floats)

    async def close(self) -> None:
        try:
            await self.robot.close()
        finally:
            self._tape.close()


class RecordedTargets:
    """The wrapped robot's `TargetCamera`, every measurement written to the recorder's tape."""

    def __init__(self, recorder: RecordingAdapter, camera: TargetCamera) -> None:
        self.recorder = recorder
        self.camera = camera

    async def measure_targets(self) -> TargetMeasurement:
        result: TargetMeasurement = await self.recorder.record(
            "measure_targets", {}, self.camera.measure_targets, _targets_to_json)
        return result


class RecordedSensors:
    """The wrapped robot's `SensorPort`, every reading written to the recorder's tape."""

    def __init__(self, recorder: RecordingAdapter, sensors: SensorPort) -> None:
        self.recorder = recorder
        self.sensors = sensors

    async def read_sensor(self, sensor: str, request: JsonObject) -> SensorReading:
        result: SensorReading = await self.recorder.record(
            "sensor_read", {"sensor": sensor, "request": request},
            lambda: self.sensors.read_sensor(sensor, request), _reading_to_json)
        return result


def read_header(folder: Path) -> RecordingHeader:
    """recording.json of `folder`; InputError (one line) if it is not a recording."""
    path = folder / HEADER_FILE
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except OSError:
        raise InputError(f"--replay {folder}: no {HEADER_FILE} (not a recording)") from None
    except ValueError as exc:
        raise InputError(f"--replay {folder}: {HEADER_FILE} is not valid JSON ({exc})") from None
    if not isinstance(header, dict) or header.get("format") != RECORDING_FORMAT:
        raise InputError(f"--replay {folder}: {HEADER_FILE} is not {RECORDING_FORMAT}")
    return RecordingHeader.from_json(header, folder)


class ReplayAdapter:
    """Answers a run's robot calls from the recording in `folder` (see the module
    docstring); nothing is moved or written anywhere but the new run folder.
    capabilities: a target camera and named instruments if the recorded robot had them
    (`measure_targets`, `sensor_read` from the tape), nothing else."""

    driver = "replay"

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.header = read_header(folder)
        self._entries: list[JsonObject] = []
        try:
            lines = (folder / TAPE_FILE).read_text(encoding="utf-8").splitlines()
        except OSError:
            raise InputError(f"--replay {folder}: no {TAPE_FILE}") from None
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                entry = json.loads(line)
            except ValueError as exc:
                raise InputError(f"--replay {folder}: {TAPE_FILE} line {number} is not "
                                 f"valid JSON ({exc})") from None
            if not isinstance(entry, dict):
                raise InputError(f"--replay {folder}: {TAPE_FILE} line {number} is not an "
                                 "object")
            self._entries.append(entry)
        self._next = 0
        self.capabilities = Capabilities(
            targets=self if self.header.measure_targets else None,
            sensors=self if self.header.sensor_read else None)

    def _take(self, call: str, args: JsonObject) -> Any:
        if self._next >= len(self._entries):
            raise ReplayDiverged(f"--replay {self.folder}: the run asks for {call} after the "
                                 f"last of {len(self._entries)} recorded calls")
        entry = self._entries[self._next]
        if entry.get("call") != call or entry.get("args", {}) != dict(args):
            raise ReplayDiverged(
                f"--replay {self.folder}: call {self._next} is {call} {dict(args)} but the "
                f"recording holds {entry.get('call')} {entry.get('args')} (other settings "
                "or code than the recorded run?)")
        self._next += 1
        if "error" in entry:
            raise _error_from_json(entry["error"])
        return entry["result"]

    async def state(self) -> RobotState:
        return _state_from_json(self._take("state", {}))

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        r = self._take("move_joints", {"q": _floats(q), "speed": float(speed)})
        return MoveOutcome(completed=bool(r["completed"]), q=_array(r["q"]), reason=r["reason"])

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        r = self._take("guarded_move", {"q": _floats(q), "speed": float(speed),
                                        "io_line": int(io_line)})
        return ContactOutcome(contact=bool(r["contact"]), q=_array(r["q"]), reason=r["reason"],
                              q_latched=None if r["q_latched"] is None else _array(r["q_latched"]),
                              speed=r["speed"])

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        import cv2

        r = self._take("capture", {"pattern": pattern, "view": int(view)})
        images = []
        for camera in ("left", "right"):
            path = self.folder / IMAGE_PATTERN.format(camera=camera, index=int(r["frame"]))
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise InputError(f"--replay {self.folder}: image {path.name} is missing or "
                                 "unreadable")
            images.append(image)
        return StereoCapture(left=images[0], right=images[1], q=_array(r["q"]), t=float(r["t"]))

    async def measure_targets(self) -> TargetMeasurement:
        """The next recorded target measurement (a `TargetCamera` if the header says so)."""
        return _targets_from_json(self._take("measure_targets", {}))

    async def read_sensor(self, sensor: str, request: JsonObject) -> SensorReading:
        """The next recorded reading of `sensor` (a `SensorPort` if the header says so)."""
        return _reading_from_json(self._take("sensor_read",
                                             {"sensor": sensor, "request": request}))

    async def get_offsets(self) -> np.ndarray:
        return _array(self._take("get_offsets", {}))

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        r = self._take("set_offsets", {"offsets": _floats(offsets)})
        return _array(r["previous"]), str(r["rollback_id"])

    async def rollback(self, rollback_id: str) -> np.ndarray:
        return _array(self._take("rollback", {"rollback_id": rollback_id}))

    async def close(self) -> None:
        return None
