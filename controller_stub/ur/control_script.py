"""Emulation of ur_rtde's control script (`rtde_control.script`) on the simulated robot.

The real script runs on the controller and talks to `RTDEControlInterface` only through RTDE
registers (offset 0, or 24 for the upper range):

    input_int_register_0      command (0 = none; 1 = movej, ... 255 = stop script)
    input_int_register_1..7   integer arguments (async flag, selection vector, ...)
    input_double_register_*   double arguments (q or pose, speed, acceleration, ...)
    output_int_register_0     script state: 1 ready for a command, 2 done with the command
    output_int_register_1     integer results (is_steady, within limits, ...)
    output_int_register_2     async status word: bits 24-30 operation id (incremented per
                              async operation), bits 16-23 write count, bit 15 running,
                              bits 0-14 progress
    output_double_register_*  double results (forward kinematics, step time, ...)

Its main loop, which this class reproduces cycle by cycle (2 ms)::

    signal_ready()
    while keep_running:
        cmd = input_int_register_0
        if cmd is a real-time command: process(cmd); signal_ready()
        elif cmd == 0: executing = False; signal_ready()
        elif not executing: keep_running = process(cmd); executing = True
                            (process ends with signal_done unless cmd == 255)

Emulated commands: movej (1, synchronous and async; an async movej moves in real time
with the probe input following the path, so a host can stop it on the input edge, or poll
its progress in the async status word), movel_fk (4, executed as a joint move: same end pose,
joint-space path), stopl / stopj (33, 34: an async move decelerates at input double 0 rad/s^2
from the cycle reached; a synchronous stop, input int 1 = 0, is done once the arm is at rest,
an asynchronous one at once), stop script
(255), protective stop (31), get step time (26), is steady (47), joints within safety
limits (37), forward kinematics at the current pose (43), get TCP offset (40, zero), and as
no-ops the settings that do not change the simulated robot (zero_ftsensor 8, set_payload 17,
force-mode damping / gain 20 / 21, set_watchdog 35, set_gravity 59). Any other command
(Cartesian moves, servo / speed / force mode, jogging, IK, ...) stops the program like a
runtime error on a real controller would, with a log line naming the command; ur_rtde then
reports "RTDE control script is not running!" and returns False.
"""

from __future__ import annotations

import asyncio
import logging
import math
import re
from typing import Protocol

import numpy as np

from controller_stub.ur.registers import UrRegisters
from controller_stub.world.controller_state import SimulatedController

logger = logging.getLogger(__name__)


class ScriptedRobot(Protocol):
    """What the control script uses of the UR controller it runs on
    (`controller_stub.ur.personality.UrPersonality`): its registers, motions and stops."""

    registers: UrRegisters

    @property
    def sim(self) -> SimulatedController: ...
    @property
    def moving(self) -> bool: ...
    def protective_stop(self, reason: str) -> None: ...
    def tcp_pose(self, q: np.ndarray | None = None) -> list[float]: ...
    async def move_joints(
        self, q_target: np.ndarray, velocity: float, acceleration: float | None = None, *,
        watch_probe: bool = False
    ) -> tuple[bool, str | None]: ...
    def stop_motion(self, deceleration: float | None = None) -> bool: ...

CYCLE_S = 0.002
READY, DONE = 1, 2

NO_CMD = 0
MOVEJ = 1
MOVEL_FK = 4
ZERO_FT_SENSOR = 8
GET_STEPTIME = 26
SET_PAYLOAD = 17
FORCE_MODE_SET_DAMPING = 20
FORCE_MODE_SET_GAIN_SCALING = 21
PROTECTIVE_STOP = 31
STOPL = 33
STOPJ = 34
SET_WATCHDOG = 35
IS_JOINTS_WITHIN_SAFETY_LIMITS = 37
GET_TCP_OFFSET = 40
GET_FORWARD_KINEMATICS_DEFAULT = 43
IS_STEADY = 47
SET_GRAVITY = 59
STOP_SCRIPT = 255

REALTIME_COMMANDS = frozenset({24, 11, 9, 10, 6, 25, 26, 27, 38, 58})
"""Commands the script processes every cycle without the done/ready handshake."""
NO_OP_COMMANDS = frozenset(
    {ZERO_FT_SENSOR, SET_PAYLOAD, FORCE_MODE_SET_DAMPING, FORCE_MODE_SET_GAIN_SCALING,
     SET_WATCHDOG, SET_GRAVITY}
)

_OFFSET = re.compile(r"reg_offset_int\s*=\s*(?:#[^\n]*\n\s*)?(\d+)")


def register_offset(script: str) -> int:
    """The int register offset injected into the control script (0 or 24; 0 if absent)."""
    match = _OFFSET.search(script)
    return int(match.group(1)) if match else 0


class ScriptStopped(Exception):  # noqa: N818 (a state, not an error of ours)
    """The emulated program ends (runtime error or stop command)."""


class ControlScript:
    """One run of the control program on `robot` (the UR personality)."""

    name = "rtde_control"

    def __init__(self, robot: ScriptedRobot, text: str) -> None:
        self.robot = robot
        self.offset = register_offset(text)
        self._async_move: asyncio.Task[None] | None = None
        self._async_write_count = 0
        self._async_op_id = 0
        self._async_fault: str | None = None

    # ----------------------------------------------------------------- registers

    def _in_int(self, index: int) -> int:
        return self.robot.registers.input_int[index + self.offset]

    def _in_double(self, index: int) -> float:
        return self.robot.registers.input_double[index + self.offset]

    def _out_int(self, index: int, value: int) -> None:
        self.robot.registers.output_int[index + self.offset] = int(value)

    def _out_double(self, index: int, value: float) -> None:
        self.robot.registers.output_double[index + self.offset] = float(value)

    def _q_from_inputs(self, start: int = 0) -> np.ndarray:
        return np.array([self._in_double(start + i) for i in range(6)])

    def _write_async_progress(self, value: int) -> None:
        """The script's write_async_progress_register: value 0 = an async operation starts,
        >= 0 its progress (running), < 0 finished."""
        self._async_write_count = (self._async_write_count + 1) % 128
        if value == 0:
            self._async_op_id = (self._async_op_id + 1) % 128
        word = self._async_write_count * 65536 + self._async_op_id * 16777216
        if value >= 0:
            word += min(value, 32767) + 32768
        self._out_int(2, word)

    # ----------------------------------------------------------------- main loop

    async def run(self) -> None:
        """The script's main loop; returns when the program ends."""
        logger.info("control script started (register offset %d)", self.offset)
        self._write_async_progress(-1)
        self._out_int(0, READY)
        executing = False
        try:
            while True:
                if self._async_fault is not None:
                    raise ScriptStopped(f"async movej refused: {self._async_fault}")
                cmd = self._in_int(0)
                if cmd in REALTIME_COMMANDS:
                    await self._process(cmd)
                    self._out_int(0, READY)
                elif cmd == NO_CMD:
                    executing = False
                    self._out_int(0, READY)
                elif not executing:
                    executing = True
                    if not await self._process(cmd):
                        break
                await asyncio.sleep(CYCLE_S)
        except ScriptStopped as exc:
            logger.warning("control script stopped: %s", exc)
        finally:
            await self._stop_async_move()
            logger.info("control script terminated")

    async def _process(self, cmd: int) -> bool:
        """Execute `cmd`; False for the stop command. Raises ScriptStopped on errors."""
        robot = self.robot
        if cmd == STOP_SCRIPT:
            logger.info("control script: received stop script")
            return False
        if cmd in (MOVEJ, MOVEL_FK):
            await self._move(cmd)
        elif cmd in (STOPJ, STOPL):
            await self._stop_command()
        elif cmd == PROTECTIVE_STOP:
            robot.protective_stop("protective stop requested by the control script")
            raise ScriptStopped("protective stop")
        elif cmd == GET_STEPTIME:
            self._out_double(0, CYCLE_S)
        elif cmd == IS_STEADY:
            self._out_int(1, int(not robot.moving))
        elif cmd == IS_JOINTS_WITHIN_SAFETY_LIMITS:
            q_min, q_max = robot.sim.joint_limits()
            q = self._q_from_inputs()
            self._out_int(1, int(bool(np.all((q >= q_min) & (q <= q_max)))))
        elif cmd == GET_FORWARD_KINEMATICS_DEFAULT:
            for i, value in enumerate(robot.tcp_pose()):
                self._out_double(i, value)
        elif cmd == GET_TCP_OFFSET:
            for i in range(6):
                self._out_double(i, 0.0)
        elif cmd in NO_OP_COMMANDS:
            logger.info("control script: command %d accepted (no effect in the simulation)", cmd)
        else:
            raise ScriptStopped(f"command {cmd} is not emulated by controller-stub")
        if cmd not in REALTIME_COMMANDS:
            self._out_int(0, DONE)
        return True

    async def _move(self, cmd: int) -> None:
        q = self._q_from_inputs()
        velocity = self._in_double(6)
        acceleration = self._in_double(7)
        is_async = self._in_int(1) == 1
        if cmd == MOVEL_FK:
            logger.info("control script: movel_fk executed as a joint move (same end pose)")
        await self._stop_async_move()
        if not is_async:
            completed, reason = await self.robot.move_joints(q, velocity, acceleration)
            if not completed and reason != "stopped":
                raise ScriptStopped(f"movej refused: {reason}")
            return
        self._write_async_progress(0)
        self._async_move = asyncio.create_task(self._run_async_move(q, velocity, acceleration))

    async def _run_async_move(self, q: np.ndarray, velocity: float, acceleration: float
                              ) -> None:
        """An asynchronous movej: paced in real time with the probe input following the
        path, until its end, a stopj / stopl, or the stop point past a probe contact."""
        try:
            completed, reason = await self.robot.move_joints(q, velocity, acceleration,
                                                             watch_probe=True)
            if not completed and reason not in ("stopped", "contact", "no_contact"):
                self._async_fault = reason
        finally:
            self._write_async_progress(-1)

    async def _stop_command(self) -> None:
        """stopj / stopl: the async move decelerates at input double 0 (rad/s^2, > 0, else
        a runtime error like a real controller's); a synchronous stop (input int 1 = 0)
        waits until the arm is at rest."""
        deceleration = self._in_double(0)
        if not (math.isfinite(deceleration) and deceleration > 0.0):
            raise ScriptStopped(f"stopj / stopl: deceleration {deceleration!r} rad/s^2 is not "
                                "a positive number")
        task = self._async_move
        if task is None or task.done() or not self.robot.stop_motion(deceleration):
            return
        if self._in_int(1) != 1:
            await asyncio.shield(task)  # the ramp is finite: at rest when the move returns

    async def _stop_async_move(self) -> None:
        """The program ends or a new move replaces the async one: the motion ends at the
        controller cycle it has reached."""
        task, self._async_move = self._async_move, None
        if task is not None and not task.done():
            self.robot.stop_motion()
            try:
                await asyncio.wait_for(task, 1.0)
            except (asyncio.CancelledError, TimeoutError):
                pass
