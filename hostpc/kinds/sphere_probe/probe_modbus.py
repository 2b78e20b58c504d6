"""Alternative sphere_probe acquisition: move in steps while polling the probe's IO line
over Modbus TCP (pymodbus ``AsyncModbusTcpClient``), for controllers without a latched
guarded move.

The probe line is read as a Modbus discrete input (UR-style map: input i at address i; the
stub's map is in docs/protocol.md). A guarded move toward ``q_target`` becomes:

1. step along the joint-space line ``q(s) = q_0 + s (q_target - q_0)`` in ``coarse_steps``
   equal joint moves, reading the line after each (the robot is at rest when it is read);
2. at the first step that finds the line high, bisect the last step (move to the middle,
   read, keep the half that contains the edge) until the bracket is shorter than
   ``resolution`` of the path (in path units s);
3. report the middle of the final bracket as the latched pose. The robot was at rest at
   every reading, so there is no trigger latency: the approach ``speed`` is 0 and the
   contact error is the probe's repeatability plus half the final bracket.

With a real controller the same client can poll while a single move is running (abort on
the edge); the simulated controller computes a move at once (its state and IO jump to the
end of the move), so stepping is the form that works against it. All angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from hostpc.errors import ConnectionFailed
from hostpc.kinds.sphere_probe.planning.contacts import (
    STEP_COARSE,
    STEP_RESOLUTION,
    STEP_SPEED,
)
from hostpc.robots.base import ContactOutcome, RobotAdapter


class ModbusProbe:
    """The probe's digital input read over Modbus TCP.

    host, port: the Modbus server; line: discrete-input address of the probe; device_id:
    the Modbus unit id; timeout: per request (s). Use as ``async with ModbusProbe(...)``.
    """

    def __init__(self, host: str, port: int, line: int, *, device_id: int = 1,
                 timeout: float = 3.0) -> None:
        self.host, self.port, self.line, self.device_id = host, int(port), int(line), device_id
        self.client = AsyncModbusTcpClient(host, port=self.port, timeout=timeout, retries=1)
        self.reads = 0

    async def connect(self) -> ModbusProbe:
        """Open the connection; ConnectionFailed if the server cannot be reached."""
        if not await self.client.connect():
            raise ConnectionFailed(f"Modbus server {self.host}:{self.port} unreachable")
        return self

    async def close(self) -> None:
        """Close the connection."""
        self.client.close()

    async def __aenter__(self) -> ModbusProbe:
        return await self.connect()

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def triggered(self) -> bool:
        """The probe line's current state (True: stylus in contact)."""
        try:
            reply = await self.client.read_discrete_inputs(self.line, count=1,
                                                           device_id=self.device_id)
        except ModbusException as exc:
            raise ConnectionFailed(f"Modbus read of input {self.line} failed: {exc}") from exc
        if reply.isError():
            raise ConnectionFailed(f"Modbus read of input {self.line} refused: {reply}")
        self.reads += 1
        return bool(reply.bits[0])


@dataclass
class SteppedGuardedMove:
    """A guarded move made of joint steps and Modbus reads (see the module docstring).

    robot: moves the joints; probe: reads the line; coarse_steps: equal steps over the
    whole travel; resolution: final bracket length in path units (fraction of the travel);
    step_speed: speed fraction of the step moves. Callable as the ``guarded`` hook of
    ``sphere_probe.acquire``: ``await stepped(q_target, speed) -> ContactOutcome``. The
    plan predicts its steps with ``planning.contacts.step_fractions``; no reading settles
    (a digital read at rest after a short slow step), so neither does the plan.
    """

    robot: RobotAdapter
    probe: ModbusProbe
    coarse_steps: int = STEP_COARSE
    resolution: float = STEP_RESOLUTION
    step_speed: float = STEP_SPEED
    moves: int = 0

    async def _go(self, q: np.ndarray) -> None:
        outcome = await self.robot.move_joints(q, self.step_speed)
        self.moves += 1
        if not outcome.completed:
            from hostpc.errors import ControllerError

            raise ControllerError(f"step move did not complete: {outcome.reason}")

    async def __call__(self, q_target: np.ndarray, speed: float) -> ContactOutcome:
        """Step from the current pose toward q_target (n,); speed is not used (the robot is
        at rest at every reading)."""
        q_0 = np.asarray((await self.robot.state()).q, float)
        q_target = np.asarray(q_target, float)
        travel = q_target - q_0
        if await self.probe.triggered():
            return ContactOutcome(contact=False, q_latched=None, q=q_0,
                                  reason="triggered_at_start")
        s_lo = 0.0
        s_hi: float | None = None
        for k in range(1, self.coarse_steps + 1):
            s = k / self.coarse_steps
            await self._go(q_0 + s * travel)
            if await self.probe.triggered():
                s_hi = s
                break
            s_lo = s
        if s_hi is None:
            return ContactOutcome(contact=False, q_latched=None, q=q_target,
                                  reason="no_contact")
        while s_hi - s_lo > self.resolution:
            s_mid = 0.5 * (s_lo + s_hi)
            await self._go(q_0 + s_mid * travel)
            if await self.probe.triggered():
                s_hi = s_mid
            else:
                s_lo = s_mid
        q_contact = q_0 + 0.5 * (s_lo + s_hi) * travel
        return ContactOutcome(contact=True, q_latched=q_contact, q=q_0 + s_hi * travel,
                              speed=0.0)
