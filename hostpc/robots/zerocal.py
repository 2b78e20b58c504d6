"""RobotAdapter over the zerocal protocol (`hostpc.transport.ControllerClient`).

This is the adapter of the simulated controller (`controller_stub`) and of any controller
speaking our protocol. It only converts values: the client's dataclasses into the
`hostpc.robots.base` ones. Errors pass through unchanged (`ConnectionFailed`,
`RequestTimeout`, `ControllerError`); nothing is retried here beyond what the client does
(idempotent reads are re-sent on a new connection, motions and writes never).

Angles are radians in the controller's reported frame, arrays numpy float64 (n,).
"""

from __future__ import annotations

import numpy as np

from hostpc.json_object import JsonObject
from hostpc.robots.base import (
    Capabilities,
    ContactOutcome,
    MeasuredTarget,
    MoveOutcome,
    RobotState,
    StereoCapture,
    TargetMeasurement,
)
from hostpc.transport import ControllerClient, SensorReading, TrackerReading


class ZerocalAdapter:
    """A `RobotAdapter` for one `ControllerClient` session (the adapter owns the client).
    capabilities: the protocol's `measure_targets`, `measure_tracker` and `sensor_read` (a
    controller without the sensor refuses the call)."""

    driver = "zerocal"

    def __init__(self, client: ControllerClient) -> None:
        self.client = client
        self.capabilities = Capabilities(targets=self, tracker=self, sensors=self)

    @property
    def address(self) -> str:
        """`HOST:PORT` of the controller."""
        return f"{self.client.host}:{self.client.port}"

    @classmethod
    async def connect(
        cls, host: str, port: int, *, token: str | None, timeout: float = 10.0
    ) -> ZerocalAdapter:
        """Open an (authenticated if `token`) session; ConnectionFailed if unreachable."""
        client = await ControllerClient.connect(host, port, token=token, timeout=timeout)
        return cls(client)

    async def state(self) -> RobotState:
        """The controller state (q, offsets, limits, IO, camera description)."""
        s = await self.client.state()
        return RobotState(
            q=s.q,
            zero_offsets=s.zero_offsets,
            q_min=s.q_min,
            q_max=s.q_max,
            digital_inputs=s.digital_inputs,
            digital_outputs=s.digital_outputs,
            camera=dict(s.camera),
            robot=s.robot_name,
            extra={"mode": s.mode, "time": s.time, "authenticated": s.authenticated,
                   **{key: [float(v) for v in value] for key, value in (
                       ("max_joint_speed", s.max_joint_speed),
                       ("max_joint_acceleration", s.max_joint_acceleration))
                      if value is not None}},
        )

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        """Joint move to q (n,) rad at `speed` (fraction of max, (0, 1])."""
        outcome = await self.client.move_joints(q, speed)
        return MoveOutcome(completed=outcome.completed, q=outcome.q, reason=outcome.reason)

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        """Move toward q (n,) until a rising edge on `io_line`."""
        outcome = await self.client.guarded_move(q, speed, io_line)
        return ContactOutcome(
            contact=outcome.contact,
            q_latched=outcome.q_latched,
            q=outcome.q,
            speed=outcome.speed_mps,
            reason=outcome.reason,
        )

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        """A stereo pair (left, right (H, W) uint8) with the joint angles at exposure."""
        left, right, q, t = await self.client.capture(pattern, view)
        return StereoCapture(left=left, right=right, q=q, t=t)

    async def measure_targets(self) -> TargetMeasurement:
        """The targets the controller triangulated now (chain, p (3,) m, cov (3, 3) m^2)
        with the joint angles q (n,) at the measurement (`measure_targets` message)."""
        reply = await self.client.measure_targets()
        return TargetMeasurement(
            q=reply.q, t=reply.time,
            targets=tuple(MeasuredTarget(chain=t.chain, p=t.p, cov=t.cov, uv=t.uv)
                          for t in reply.targets))

    async def measure_tracker(self) -> TrackerReading:
        """The cell's laser tracker reading (hostpc.transport.TrackerReading)."""
        return await self.client.measure_tracker()

    async def read_sensor(self, sensor: str, request: JsonObject) -> SensorReading:
        """A reading of the controller's instrument `sensor` (`sensor_read`)."""
        return await self.client.sensor_read(sensor, request)

    async def get_offsets(self) -> np.ndarray:
        """The zero offsets (n,) rad."""
        return await self.client.get_offsets()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Write zero offsets (n,) rad -> (previous offsets (n,), rollback id)."""
        return await self.client.set_offsets(offsets)

    async def rollback(self, rollback_id: str) -> np.ndarray:
        """Undo the offset write `rollback_id`; returns the offsets now in force (n,)."""
        return await self.client.rollback(rollback_id)

    async def close(self) -> None:
        """Close the session."""
        await self.client.close()
