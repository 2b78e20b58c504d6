"""The one interface the measurement methods use to drive a robot.

Adapters: the zerocal protocol (`hostpc.robots.zerocal`, the simulated controller or a
controller speaking our protocol), Universal Robots through ur_rtde (`hostpc.robots.ur`), and
Modbus IO (`hostpc.robots.modbus_io`) for triggers and station bits. Methods never import a
transport or a vendor library; they receive a RobotAdapter.

All angles radians, lengths metres (docs/conventions.md). Joint angles are the controller's
reported ("commanded") angles, `q_cmd`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class RobotState:
    """q: (n,) joint angles; zero_offsets: (n,) the controller's zero offsets (conventions.md);
    q_min, q_max: (n,) joint limits; digital_inputs / digital_outputs: IO lines;
    camera: what the controller reports of its camera and cell (image size, nominal mount,
    target, chessboard geometry), or {}; robot: model name; extra: anything else reported."""

    q: np.ndarray
    zero_offsets: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    digital_inputs: tuple[bool, ...] = ()
    digital_outputs: tuple[bool, ...] = ()
    camera: dict[str, Any] = field(default_factory=dict)
    robot: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


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


class RobotAdapter(Protocol):
    """What a measurement method may ask of a robot. Every call may raise
    hostpc.errors.ConnectionFailed, RequestTimeout or ControllerError."""

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


class TargetMeasuringAdapter(RobotAdapter, Protocol):
    """An adapter whose controller also triangulates targets itself (optional: the
    dual_loop method needs it; check with `supports_target_measurement`)."""

    async def measure_targets(self) -> TargetMeasurement:
        """The targets the camera sees now, with the joint angles at the measurement."""
        ...


def supports_target_measurement(robot: object) -> bool:
    """True if `robot` offers `measure_targets()` (a `TargetMeasuringAdapter`)."""
    return callable(getattr(robot, "measure_targets", None))
