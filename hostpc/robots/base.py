"""The one interface the measurement methods use to drive a robot.

Adapters: the zerocal protocol (`hostpc.robots.zerocal`, the simulated controller or a
controller speaking our protocol), Universal Robots through ur_rtde (`hostpc.robots.ur`), and
Modbus IO (`hostpc.robots.modbus_io`) for triggers and station bits; the driver table is
`hostpc.robots.drivers`. Methods never import a transport or a vendor library; they receive a
RobotAdapter. What an adapter offers beyond it (measure_targets, measure_tracker,
export_offsets, last_timing) is a typed capability (the Protocols below, collected in the
adapter's `Capabilities`), never an attribute probed with getattr.

All angles radians, lengths metres (docs/conventions.md). Joint angles are the controller's
reported ("commanded") angles, `q_cmd`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject

if TYPE_CHECKING:  # the I/O layer's value types; loaded with the adapter that returns them
    from hostpc.transport import SensorReading, TrackerReading


@dataclass(frozen=True)
class RobotState:
    """q: (n,) joint angles; zero_offsets: (n,) the controller's zero offsets (conventions.md);
    q_min, q_max: (n,) joint limits; digital_inputs / digital_outputs: IO lines;
    camera: what the controller reports of its camera and cell (image size, nominal mount,
    target, chessboard geometry), or {}; robot: model name; extra: anything else reported.
    camera and extra are the controller's report as it sent it (a JSON object the protocol
    leaves open: each driver, kind and plugin reads its own keys; run.json and a recording
    keep it as sent): `build_cell` parses camera, `controller_time` reads the clock."""

    q: np.ndarray
    zero_offsets: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    digital_inputs: tuple[bool, ...] = ()
    digital_outputs: tuple[bool, ...] = ()
    camera: JsonObject = field(default_factory=dict)
    robot: str = ""
    extra: JsonObject = field(default_factory=dict)

    @property
    def controller_time(self) -> float | None:
        """The controller's clock (s) when it reports one (`extra["time"]`), else None."""
        now = self.extra.get("time")
        return float(now) if isinstance(now, int | float) and math.isfinite(now) else None


@dataclass(frozen=True)
class MoveOutcome:
    """completed, or aborted with reason; q: (n,) where the robot stopped."""

    completed: bool
    q: np.ndarray
    reason: str | None = None


@dataclass(frozen=True)
class ContactOutcome:
    """A guarded move: contact (IO edge before the end of travel), q_latched: (n,) angles
    latched at the edge or None, q: (n,) where it stopped, speed: approach speed at the
    contact (m/s) if the controller reports it; qd: (n,) joint velocities at the edge (rad/s)
    if measured (a controller that does not know the probe tip: the method computes the
    tip speed from them)."""

    contact: bool
    q_latched: np.ndarray | None
    q: np.ndarray
    speed: float | None = None
    reason: str | None = None
    qd: np.ndarray | None = None


@dataclass(frozen=True)
class StereoCapture:
    """left, right: (H, W) uint8 images; q: (n,) joint angles at exposure; t: controller
    time (s)."""

    left: np.ndarray
    right: np.ndarray
    q: np.ndarray
    t: float


@dataclass(frozen=True)
class MeasuredTarget:
    """One target point triangulated by the controller's own vision: chain (the kinematic
    chain carrying it, e.g. "left"); p: (3,) m in the camera frame; cov: (3, 3) m^2; uv:
    (2, 2) px, the pixel centres [[u_l, v_l], [u_r, v_r]] it was triangulated from (None if
    the controller does not send them)."""

    chain: str
    p: np.ndarray
    cov: np.ndarray
    uv: np.ndarray | None = None


@dataclass(frozen=True)
class TargetMeasurement:
    """Every target in view (possibly none) at joint angles q: (n,) rad, all joints, at
    controller time t (s)."""

    q: np.ndarray
    t: float
    targets: tuple[MeasuredTarget, ...]


@runtime_checkable
class RobotAdapter(Protocol):
    """What a measurement method may ask of a robot. Every call may raise
    hostpc.errors.ConnectionFailed, RequestTimeout or ControllerError.

    driver: the driver's name (`zerocal`, `ur`, `replay`), for messages; capabilities: what
    it offers beyond these calls (below)."""

    @property
    def driver(self) -> str: ...

    @property
    def capabilities(self) -> Capabilities: ...

    async def state(self) -> RobotState: ...

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome: ...

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome: ...

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture: ...

    async def get_offsets(self) -> np.ndarray: ...

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Write zero offsets; returns (previous offsets, rollback id)."""
        ...

    async def rollback(self, rollback_id: str) -> np.ndarray: ...

    async def close(self) -> None: ...


# ---------------------------------------------------------------------- capabilities
#
# One typed Protocol per call an adapter MAY offer:
#
#     TargetCamera    measure_targets()   the controller triangulates targets itself (dual_loop)
#     LaserTracker    measure_tracker()   the cell's laser tracker (world_point)
#     SensorPort      read_sensor()       any other instrument by name (`sensor_read`): a
#                                         measurement kind's own, e.g. a plugin's
#     OffsetExport    export_offsets()    a robot that keeps no zero offsets writes them as
#                                         files for its own software (UR; calibrate/push.py)
#     CaptureTiming   last_timing         host cameras: stamps and skew of the last pair
#                                         (recorded by sensors/recording.py)
#
# An adapter says what it offers in one value, its `capabilities`: per capability the object
# that answers it, or None. A wrapper (recording, host cameras) builds its own from the wrapped
# adapter's, so nothing is found by probing attributes. A method declares the calls it needs
# (`Method.needs`); the runner checks them once, before the method's `prepare`
# (`check_needs`: one InputError naming the driver and the missing call); the method then
# takes the call with `targets_of` / `tracker_of`, which cannot fail after that check.


class TargetCamera(Protocol):
    """The controller's own vision triangulates the targets in view (`measure_targets`)."""

    async def measure_targets(self) -> TargetMeasurement:
        """The targets the camera sees now, with the joint angles at the measurement."""
        ...


class LaserTracker(Protocol):
    """The cell's laser tracker (`measure_tracker`)."""

    async def measure_tracker(self) -> TrackerReading:
        """Each reflector's point in the tracker frame now (hostpc.transport.TrackerReading)."""
        ...


class SensorPort(Protocol):
    """Any instrument by name (`sensor_read`): how a measurement kind brings its own
    instrument without a protocol call of its own (docs/measurement-models.md)."""

    async def read_sensor(self, sensor: str, request: JsonObject) -> SensorReading:
        """A reading of `sensor`: `request` and the reading's `reading` are the
        instrument's own small JSON objects (hostpc.transport.SensorReading)."""
        ...


class OffsetExport(Protocol):
    """A robot that keeps no zero offsets: the compensated offsets become files its own
    software loads (the only lasting form of a push)."""

    def export_offsets(self, directory: str | Path, robot: str,
                       offsets: np.ndarray) -> dict[str, Path]:
        """Write offsets (n,) rad of robot model `robot` into `directory`; returns
        {kind: path}."""
        ...


@dataclass(frozen=True)
class PairTiming:
    """When a stereo pair was grabbed on the host: index (0-based capture count); t_left /
    t_right: host clock (s) at each grab; stamp_left / stamp_right: backend timestamps (s,
    0 when the backend reports none); skew_s: right minus left exposure time (s); t: the
    controller time (s) the capture is stamped with."""

    index: int
    t_left: float
    t_right: float
    stamp_left: float
    stamp_right: float
    skew_s: float
    t: float

    def to_json(self) -> JsonObject:
        """The timing log's and the recording's form."""
        return {"index": self.index, "t_left": self.t_left, "t_right": self.t_right,
                "stamp_left": self.stamp_left, "stamp_right": self.stamp_right,
                "skew_s": self.skew_s, "t": self.t}


class CaptureTiming(Protocol):
    """Cameras on the host: the timing of the last stereo pair (stamps, skew), or None."""

    @property
    def last_timing(self) -> PairTiming | None:
        """Host grab times, backend timestamps and skew of the last capture."""
        ...


@dataclass(frozen=True)
class Capabilities:
    """What an adapter offers beyond `RobotAdapter`: per capability, the object that answers
    it, or None (not offered)."""

    targets: TargetCamera | None = None
    tracker: LaserTracker | None = None
    sensors: SensorPort | None = None
    offset_export: OffsetExport | None = None
    capture_timing: CaptureTiming | None = None


class Need(Enum):
    """A call a measurement method needs from the robot (value: the call's name)."""

    TARGETS = "measure_targets"
    TRACKER = "measure_tracker"
    SENSORS = "sensor_read"


_WHAT = {
    Need.TARGETS: "a controller that measures targets",
    Need.TRACKER: "a controller with a laser tracker",
    Need.SENSORS: "a controller that reads the kind's own instrument",
}


class MissingCapability(InputError):
    """The method needs a call the driver does not offer (exit code 2, before any pose)."""


def _capabilities(robot: RobotAdapter) -> Capabilities:
    # a caller without type checks (library use, tests) may pass something that is not an
    # adapter at all: it offers nothing
    return robot.capabilities if isinstance(robot, RobotAdapter) else Capabilities()


def _missing(robot: RobotAdapter, need: Need, who: str) -> MissingCapability:
    driver = robot.driver if isinstance(robot, RobotAdapter) else type(robot).__name__
    return MissingCapability(f"{who} needs {_WHAT[need]} ({need.value}); the {driver} "
                             "driver does not offer it")


def check_needs(robot: RobotAdapter, needs: Iterable[Need], who: str) -> None:
    """MissingCapability naming `who` (e.g. `--method dual_loop`), the call and the driver
    for the first need `robot` does not offer."""
    capabilities = _capabilities(robot)
    offered = {Need.TARGETS: capabilities.targets, Need.TRACKER: capabilities.tracker,
               Need.SENSORS: capabilities.sensors}
    for need in needs:
        if offered[need] is None:
            raise _missing(robot, need, who)


def targets_of(robot: RobotAdapter, who: str) -> TargetCamera:
    """The robot's `TargetCamera` (MissingCapability if it has none: `check_needs` first)."""
    camera = _capabilities(robot).targets
    if camera is None:
        raise _missing(robot, Need.TARGETS, who)
    return camera


def tracker_of(robot: RobotAdapter, who: str) -> LaserTracker:
    """The robot's `LaserTracker` (MissingCapability if it has none: `check_needs` first)."""
    tracker = _capabilities(robot).tracker
    if tracker is None:
        raise _missing(robot, Need.TRACKER, who)
    return tracker


def sensors_of(robot: RobotAdapter, who: str) -> SensorPort:
    """The robot's `SensorPort` (MissingCapability if it has none: `check_needs` first)."""
    sensors = _capabilities(robot).sensors
    if sensors is None:
        raise _missing(robot, Need.SENSORS, who)
    return sensors
