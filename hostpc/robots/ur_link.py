"""The RTDE link of the UR driver: ur_rtde's interfaces, read and moved in the UR's own angles.

`UrLink` owns the three ur_rtde interfaces (receive, control, IO) and the motion lock; it
knows nothing of the host zero offsets (`ur_offsets.py`) and hands the guarded move
(`ur_guarded.py`) its samples and moves. Every ur_rtde call runs in a worker thread
(`asyncio.to_thread`), never on the event loop (ur.py's module docstring: its calls hold
the GIL). Right after `moveJ` returns, the receive interface may still hold a sample from
before the end of the motion, so `move` waits for a sample newer than the one held when
moveJ returned and at the target (within SETTLE_TOLERANCE_RAD, up to SETTLE_TIMEOUT_S).
Angles rad, times s.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from hostpc.errors import ControllerError, InputError, RequestTimeout
from hostpc.planning.robot_time import DEFAULT_JOINT_ACCELERATION
from hostpc.robots.base import MoveOutcome

logger = logging.getLogger("hostpc.robots.ur")

Sample = tuple[float, np.ndarray, int, int]
"""(RTDE timestamp s, actual q (6,) rad, digital input bits, digital output bits)."""

MAX_JOINT_SPEED = 3.14
"""rad/s; ur_rtde's UR_JOINT_VELOCITY_MAX, `speed` 1.0 maps to it."""
JOINT_ACCELERATION = DEFAULT_JOINT_ACCELERATION
"""rad/s^2, UR's default movej acceleration (1.4; the robot time's default when a
controller does not report one, written once there)."""
SETTLE_TOLERANCE_RAD = 1e-3
SETTLE_TIMEOUT_S = 2.0
T = TypeVar("T")


def check_joints(q: np.ndarray | list[float], name: str = "q") -> np.ndarray:
    """q as 6 finite joint angles (6,) rad; InputError naming `name` otherwise."""
    values = np.asarray(q, dtype=float).reshape(-1)
    if values.shape != (6,) or not np.all(np.isfinite(values)):
        raise InputError(f"{name}: expected 6 finite joint angles (rad), got {values.tolist()}")
    return values


def joint_velocity(speed: float) -> float:
    """A speed fraction in (0, 1] -> rad/s (InputError otherwise)."""
    if not 0.0 < float(speed) <= 1.0:
        raise InputError(f"speed {speed!r}: expected a fraction in (0, 1]")
    return max(1e-3, float(speed) * MAX_JOINT_SPEED)


class UrLink:
    """ur_rtde's receive / control / IO interfaces of the UR at `host` (tests may pass
    fakes), the lock that keeps one motion at a time, timeout: s per request."""

    def __init__(self, host: str, receive: Any, control: Any, io: Any,
                 timeout: float = 10.0) -> None:
        self.host = host
        self.receive = receive
        self.control = control
        self.io = io
        self.timeout = float(timeout)
        self.motion_lock = asyncio.Lock()

    async def call(self, function: Callable[..., T], *args: Any) -> T:
        """Run a blocking ur_rtde call in a worker thread; errors -> ControllerError."""
        try:
            return await asyncio.to_thread(function, *args)
        except (RuntimeError, ValueError, TypeError) as exc:
            name = getattr(function, "__name__", "ur_rtde call")  # a function's, for the message
            raise ControllerError(f"UR {self.host}: {name} failed: {exc}") from exc

    def sample(self) -> Sample:
        """(timestamp, actual q (6,), input bits, output bits) of ONE RTDE package: read
        again if the receive thread stored a newer package between the getters. Blocking."""
        for _ in range(10):
            stamp = float(self.receive.getTimestamp())
            sample = (
                stamp,
                np.asarray(self.receive.getActualQ(), float),
                int(self.receive.getActualDigitalInputBits()),
                int(self.receive.getActualDigitalOutputBits()),
            )
            if float(self.receive.getTimestamp()) == stamp:
                return sample
        return sample

    async def fresh_q(self, after: float, target: np.ndarray | None) -> np.ndarray:
        """Measured q (6,) from a sample newer than timestamp `after` (and at `target` within
        SETTLE_TOLERANCE_RAD if given, waiting up to SETTLE_TIMEOUT_S for it)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + SETTLE_TIMEOUT_S
        fresh: np.ndarray | None = None
        while True:
            stamp, q, _, _ = await self.call(self.sample)
            if stamp > after:
                fresh = q
                if target is None or np.max(np.abs(q - target)) <= SETTLE_TOLERANCE_RAD:
                    return q
            if loop.time() > deadline:
                if fresh is not None:
                    logger.warning("UR %s: robot %.2e rad from the target after the move",
                                   self.host, float(np.max(np.abs(fresh - target))))
                    return fresh
                raise RequestTimeout(
                    f"UR {self.host}: no new RTDE sample within {SETTLE_TIMEOUT_S:.1f} s"
                )
            await asyncio.sleep(0.002)

    async def failure_reason(self) -> str:
        """Why the controller refused a move: estop, protective_stop, control_script_stopped
        or refused."""
        if await self.call(self.receive.isEmergencyStopped):
            return "estop"
        if await self.call(self.receive.isProtectiveStopped):
            return "protective_stop"
        if not await self.call(self.control.isProgramRunning):
            return "control_script_stopped"
        return "refused"

    async def move(self, target: np.ndarray, velocity: float) -> MoveOutcome:
        """moveJ to the UR angles target (6,) at velocity rad/s, the motion lock held by the
        caller; the outcome's q is a measured sample in UR angles."""
        ok = await self.call(
            self.control.moveJ, target.tolist(), velocity, JOINT_ACCELERATION, False
        )
        after = float(await self.call(self.receive.getTimestamp))
        if not ok:
            reason = await self.failure_reason()
            return MoveOutcome(completed=False, q=await self.fresh_q(after, None), reason=reason)
        return MoveOutcome(completed=True, q=await self.fresh_q(after, target))

    async def close(self) -> None:
        """Stop the control script and disconnect every interface (each failure logged,
        closing goes on)."""
        steps: tuple[tuple[str, Any, Callable[[Any], object]], ...] = (
            ("stopScript", self.control, lambda control: control.stopScript()),
            ("control.disconnect", self.control, lambda control: control.disconnect()),
            ("io.disconnect", self.io, lambda io: io.disconnect()),
            ("receive.disconnect", self.receive, lambda receive: receive.disconnect()),
        )
        for name, interface, step in steps:
            if interface is None:
                continue
            try:
                await asyncio.to_thread(step, interface)
            except Exception as exc:  # closing must go on
                logger.warning("UR %s: %s failed: %s", self.host, name, exc)
