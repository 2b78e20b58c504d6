"""Values the zerocal transport hands to its callers (frozen dataclasses) and its error.

Angles are radians (reported frame), times seconds; arrays are numpy float64 (n,).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.errors import ControllerError
from hostpc.json_object import JsonObject


class ControllerRefusedError(ControllerError):
    """The controller answered a request with an error reply.

    code: the protocol `ErrorCode` value (e.g. "refused", "busy", "auth_required");
    reason: the controller's specific reason for "refused" (e.g. "joint_limit", "estop").
    """

    def __init__(self, message: str, code: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.reason = reason


@dataclass(frozen=True)
class ControllerState:
    """Snapshot of the controller. q, zero_offsets, q_min, q_max: (n,) rad."""

    robot_name: str
    n_joints: int
    mode: str
    time: float
    q: np.ndarray
    zero_offsets: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    digital_inputs: tuple[bool, ...]
    digital_outputs: tuple[bool, ...]
    camera: JsonObject  # the controller's camera description (open: RobotState.camera)
    authenticated: bool
    max_joint_speed: np.ndarray | None = None  # (n,) rad/s at speed 1, if reported
    max_joint_acceleration: np.ndarray | None = None  # (n,) rad/s^2, if reported


@dataclass(frozen=True)
class MoveOutcome:
    """completed, or stopped early with `reason`; q: (n,) rad where the robot stopped."""

    completed: bool
    q: np.ndarray
    duration_s: float
    reason: str | None


@dataclass(frozen=True)
class GuardedMoveOutcome:
    """contact False = no contact at the end of travel; q_latched: (n,) rad at the edge."""

    contact: bool
    q_latched: np.ndarray | None
    q: np.ndarray
    io_line: int
    duration_s: float
    speed_mps: float | None
    reason: str | None


@dataclass(frozen=True)
class TargetPoint:
    """One triangulated target: chain (the kinematic chain carrying it, e.g. "left");
    p: (3,) m in the camera frame; cov: (3, 3) m^2; uv: (2, 2) px, the pixel centres it was
    triangulated from, if the controller sent them."""

    chain: str
    p: np.ndarray
    cov: np.ndarray
    uv: np.ndarray | None = None


@dataclass(frozen=True)
class TargetsMeasurement:
    """The targets the controller's camera saw (in reply order) at joint angles q (n,) rad
    and controller time `time` (s)."""

    q: np.ndarray
    time: float
    targets: tuple[TargetPoint, ...]


@dataclass(frozen=True)
class IoSnapshot:
    """Digital inputs and outputs (line 0 first) at controller time `time` (s)."""

    digital_inputs: tuple[bool, ...]
    digital_outputs: tuple[bool, ...]
    time: float


@dataclass(frozen=True)
class IoEdgeEvent:
    """A digital input changed: line, new value, controller time, (n,) latched q (rad)."""

    line: int
    value: bool
    time: float
    q_latched: np.ndarray


@dataclass(frozen=True)
class TrackerReading:
    """A laser tracker reading (`measure_tracker`): q (n,) rad at the measurement; time (s);
    points: reflector name -> ((3,) m in the tracker (world) frame, (3, 3) m^2 covariance);
    lost: reflectors whose beam is lost; description: the tracker's nominal facts
    (docs/protocol.md)."""

    q: np.ndarray
    time: float
    points: dict[str, tuple[np.ndarray, np.ndarray]]
    lost: tuple[str, ...]
    description: JsonObject  # open: each kind reads its own keys


@dataclass(frozen=True)
class SensorReading:
    """A reading of a measurement kind's own instrument (`sensor_read`): sensor: its name;
    q (n,) rad at the reading; time (s); reading: the instrument's JSON answer, whose shape
    is the contract between the kind's method and its sensor (docs/protocol.md), parsed
    into the kind's typed sample by its method."""

    sensor: str
    q: np.ndarray
    time: float
    reading: JsonObject
