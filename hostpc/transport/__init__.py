"""asyncio transport to a zerocal controller (the I/O shell around `protocol`)."""

from hostpc.transport.client import (
    IDEMPOTENT_KINDS,
    MOTION_KINDS,
    ControllerClient,
)
from hostpc.transport.io_events import IoEventSubscription
from hostpc.transport.types import (
    ControllerRefusedError,
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

__all__ = [
    "IDEMPOTENT_KINDS",
    "MOTION_KINDS",
    "ControllerClient",
    "ControllerRefusedError",
    "ControllerState",
    "GuardedMoveOutcome",
    "IoEdgeEvent",
    "IoEventSubscription",
    "IoSnapshot",
    "MoveOutcome",
    "SensorReading",
    "TargetPoint",
    "TargetsMeasurement",
    "TrackerReading",
]
