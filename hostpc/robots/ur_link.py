"""The RTDE link of the UR driver: ur_rtde's interfaces, read and moved in the UR's own angles.

`UrLink` owns the three ur_rtde interfaces (receive, control, IO) and the motion lock; it
knows nothing of the host zero offsets (`ur_offsets.py`) and hands the guarded move
(`ur_guarded.py`) its samples and moves. Every ur_rtde call runs in a worker thread
(`asyncio.to_thread`), never on the event loop (ur.py's module docstring: its calls hold
the GIL).

`move` issues moveJ asynchronously and polls its progress (getAsyncOperationProgressEx), so
that a move whose caller is cancelled (Ctrl-C, SIGTERM: `hostpc.cli.termination`) is stopped
on the robot: stopJ(INTERRUPT_DECELERATION) decelerates the arm to rest, and the
cancellation carries a note saying where it stopped ("move_joints interrupted: stopJ sent:
motion stopped ... short of the target"), which the interrupt line shows. A blocking moveJ
could not be stopped: the control script runs it to its end before it reads another
command. When the move has ended, the receive interface may still hold a sample from before
its end, so `move` waits for a sample newer than the one held then and at the target (within
SETTLE_TOLERANCE_RAD, up to SETTLE_TIMEOUT_S). Angles rad, times s.

A controller that dies or freezes mid-move does not make ur_rtde fail: its getters return the
last state they received (the move "running", the program running, the same timestamp).
So `move` gives up with ConnectionFailed ("connection lost") when the receive timestamp has
not advanced for `timeout` s or the control interface reports itself disconnected. The
ur_rtde calls run in daemon threads: one blocked on a dead link (stopScript, disconnect) is
left behind, `close` bounds every step, and the process can still exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from hostpc.errors import ConnectionFailed, ControllerError, InputError, RequestTimeout
from hostpc.planning.robot_time import DEFAULT_JOINT_ACCELERATION, DEFAULT_SETTLE_S
from hostpc.robots.base import MoveOutcome

logger = logging.getLogger("hostpc.robots.ur")

Sample = tuple[float, np.ndarray, int, int]
"""(RTDE timestamp s, actual q (6,) rad, digital input bits, digital output bits)."""

MAX_JOINT_SPEED = 3.14
"""rad/s; ur_rtde's UR_JOINT_VELOCITY_MAX, `speed` 1.0 maps to it."""
JOINT_ACCELERATION = DEFAULT_JOINT_ACCELERATION
"""rad/s^2, UR's default movej acceleration (1.4; the robot time's default when a
controller does not report one, written once there)."""
SETTLE_S = DEFAULT_SETTLE_S
"""s the arm must have stood still, on the controller's clock, before a measurement taken
in motion starts (a guarded approach, `ur_guarded.py`): a UR does not settle by itself (a
moveJ carries no "measure" flag). The robot time's default (written once there)."""
SETTLE_TOLERANCE_RAD = 1e-3
SETTLE_TIMEOUT_S = 2.0
INTERRUPT_DECELERATION = 2.0
"""rad/s^2 of the stopJ that ends a move whose caller was cancelled (ur_rtde's default stopJ
rate; above JOINT_ACCELERATION, so the arm stops sooner than the move's own ramp would)."""
STOP_TIMEOUT_S = 10.0
"""How long that stopJ may take (a 3.14 rad/s joint stops in 1.6 s at 2 rad/s^2)."""
POLL_INTERVAL_S = 0.004
"""Pause between two reads of a move's progress."""
PROGRAM_CHECK_S = 0.25
"""While a move's operation has not started, how often to check the control script runs."""
CLOSE_STEP_TIMEOUT_S = 2.0
"""How long each step of `close` may take (a dead controller never answers stopScript)."""
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


def _settle(future: asyncio.Future[Any], result: Any, exc: BaseException | None) -> None:
    """Resolve `future` (on its loop) unless its awaiter gave up on it already."""
    if future.done():
        return
    if exc is None:
        future.set_result(result)
    else:
        future.set_exception(exc)


async def in_daemon_thread(function: Callable[..., T], *args: Any) -> T:
    """function(*args) in a new daemon thread: a call blocked on a dead controller is left
    behind when its awaiter gives up, and never holds up the process's exit (asyncio's
    default executor joins its threads at exit)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[T] = loop.create_future()

    def run() -> None:
        try:
            result, exc = function(*args), None
        except BaseException as error:  # handed to the awaiter
            result, exc = None, error
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(_settle, future, result, exc)

    threading.Thread(target=run, name="ur_rtde call", daemon=True).start()
    return await future


def at_target(q: np.ndarray, target: np.ndarray) -> bool:
    """True if q is at target (6,) within SETTLE_TOLERANCE_RAD."""
    return bool(np.max(np.abs(q - target)) <= SETTLE_TOLERANCE_RAD)


class FreshSamples:
    """The dead-controller check (the module docstring): `check(stamp)` with each RTDE
    timestamp read; ConnectionFailed from `link.lost` once it has not advanced for the
    link's timeout (s of host time). Blocking-safe (no event loop)."""

    def __init__(self, link: UrLink) -> None:
        self.link = link
        self.stamp = -math.inf
        self.fresh_at = time.monotonic()

    def check(self, stamp: float) -> None:
        now = time.monotonic()
        if stamp > self.stamp:
            self.stamp, self.fresh_at = stamp, now
        elif now - self.fresh_at > self.link.timeout:
            raise self.link.lost(f"no new RTDE sample for {self.link.timeout:.1f} s")


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
        self.rest_since: float | None = None
        """RTDE timestamp (s) at which the arm came to rest after this session's last
        motion; None before any (at rest, settled)."""

    async def call(self, function: Callable[..., T], *args: Any) -> T:
        """Run a blocking ur_rtde call in a worker thread; errors -> ControllerError."""
        try:
            return await in_daemon_thread(function, *args)
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
                if target is None or at_target(q, target):
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

    async def failure_reason(self, otherwise: str | None = "refused") -> str | None:
        """Why the controller refused (or ended) a move: estop, protective_stop,
        control_script_stopped, or `otherwise` when none of these holds."""
        if await self.call(self.receive.isEmergencyStopped):
            return "estop"
        if await self.call(self.receive.isProtectiveStopped):
            return "protective_stop"
        if not await self.call(self.control.isProgramRunning):
            return "control_script_stopped"
        return otherwise

    async def move(self, target: np.ndarray, velocity: float) -> MoveOutcome:
        """moveJ to the UR angles target (6,) at velocity rad/s, the motion lock held by the
        caller; the outcome's q is a measured sample in UR angles. Asynchronous moveJ, its
        end polled; cancelled, the arm is stopped first (the module docstring)."""
        op0 = (await self.call(self.control.getAsyncOperationProgressEx)).operationId()
        command = asyncio.ensure_future(
            self.call(self.control.moveJ, target.tolist(), velocity, JOINT_ACCELERATION, True))
        try:
            ok = await asyncio.shield(command)
            if ok:
                await self._wait_async(op0)
        except asyncio.CancelledError as exc:
            await self.interrupted(exc, "move_joints", target, command)
            raise
        # a sample from after the end: its safety flags say whether the move was refused
        after = float(await self.call(self.receive.getTimestamp))
        q = await self.fresh_q(after, None)
        reason = await self.failure_reason(None if ok else "refused")
        if reason is None and not at_target(q, target):
            q = await self.fresh_q(after, target)
            reason = None if at_target(q, target) else "stopped"
        await self.came_to_rest()
        return MoveOutcome(completed=reason is None, q=q, reason=reason)

    def lost(self, why: str) -> ConnectionFailed:
        """The error of a controller that stopped talking mid-move (`why`)."""
        return ConnectionFailed(f"UR {self.host}: connection lost ({why})")

    async def _wait_async(self, op0: int) -> None:
        """Poll the asynchronous operation after `op0` until it has started and ended (or the
        control script stopped: a refused move ends the program). ConnectionFailed if the
        link is lost: no new RTDE sample for `timeout` s, or the control interface
        disconnected. (No deadline from the move's planned duration: the teach pendant's
        speed slider slows a move by a factor the host does not know.)"""
        loop = asyncio.get_running_loop()
        started = False
        check_at = loop.time() + PROGRAM_CHECK_S
        fresh = FreshSamples(self)
        while True:
            fresh.check(float(await self.call(self.receive.getTimestamp)))
            if not await self.call(self.control.isConnected):
                raise self.lost("the control interface disconnected")
            status = await self.call(self.control.getAsyncOperationProgressEx)
            started = started or status.operationId() != op0
            if started and not status.isAsyncOperationRunning():
                return
            if not started and loop.time() > check_at:
                if not await self.call(self.control.isProgramRunning):
                    return
                check_at = loop.time() + PROGRAM_CHECK_S
            await asyncio.sleep(POLL_INTERVAL_S)

    async def came_to_rest(self) -> None:
        """The arm is at rest after a motion (a sample where it ended was read): note the
        controller's time (`rest_since`). Read after that sample, never before it: a move
        that took no wall time shows its simulated time in the same sample as its end."""
        self.rest_since = float(await self.call(self.receive.getTimestamp))

    async def settle(self, settle_s: float = SETTLE_S) -> float:
        """Before a measurement taken in motion: wait until the arm has stood still
        `settle_s` since its last motion ended (`rest_since`), on the controller's clock
        (its RTDE timestamp, which runs while the host waits); returns the controller
        seconds waited. ConnectionFailed if the timestamp stops advancing (`FreshSamples`).
        A timestamp below `rest_since` is a restarted controller (its uptime began again
        behind a live link): the rest counts from that sample."""
        rest = self.rest_since
        if rest is None:
            return 0.0
        fresh = FreshSamples(self)
        first: float | None = None
        while True:
            stamp = float(await self.call(self.receive.getTimestamp))
            fresh.check(stamp)
            first = stamp if first is None else first
            if stamp < rest:  # a restart: never wait out the old uptime
                rest = self.rest_since = stamp
            if stamp - rest >= settle_s:
                return stamp - first
            await asyncio.sleep(min(max(rest + settle_s - stamp, POLL_INTERVAL_S), 0.1))

    async def interrupted(self, exc: asyncio.CancelledError, kind: str, target: np.ndarray,
                          *commands: asyncio.Future[Any] | None) -> None:
        """A `kind` motion toward the UR angles target (6,) was cancelled (`exc`): let its
        ur_rtde `commands` in flight finish (one ur_rtde command at a time), stop the arm
        (`stop_interrupted`) and note on `exc` what was done, as the zerocal client does
        ("move_joints interrupted: ..."). The caller re-raises."""
        pending = [command for command in commands if command is not None]
        if pending:  # bounded: a command on a dead link never returns
            done, _ = await asyncio.wait(pending, timeout=STOP_TIMEOUT_S)
            for command in done:  # its failure is the stop's business now
                if not command.cancelled():
                    command.exception()
        stopped = await self.stop_interrupted(target)
        logger.info("UR %s: %s interrupted: %s", self.host, kind, stopped)
        exc.add_note(f"{kind} interrupted: {stopped}")

    async def stop_interrupted(self, target: np.ndarray) -> str:
        """Best effort, within STOP_TIMEOUT_S: stopJ(INTERRUPT_DECELERATION) after a move to
        the UR angles target (6,) was cancelled, and wait for the arm at rest; says what
        happened and where the arm stopped (logged in UR angles)."""
        # plain wait_for: only ever run for a cancellation its caller re-raises, so a second
        # one lost here (CPython gh-86296, hostpc.transport.waiting) changes nothing
        try:
            await asyncio.wait_for(
                self.call(self.control.stopJ, INTERRUPT_DECELERATION, False), STOP_TIMEOUT_S)
            after = float(await self.call(self.receive.getTimestamp))
            q = await asyncio.wait_for(self.fresh_q(after, None), STOP_TIMEOUT_S)
            await self.came_to_rest()
        except (ControllerError, RequestTimeout, TimeoutError) as exc:
            logger.warning("UR %s: stopJ after an interrupted move failed: %s", self.host,
                           str(exc) or type(exc).__name__)
            return "stopJ sent, not confirmed"
        short = float(np.degrees(np.max(np.abs(target - q))))
        logger.info("UR %s: stopJ(%.1f rad/s^2): the arm stopped at %s deg (UR angles), %.2f "
                    "deg from the target", self.host, INTERRUPT_DECELERATION,
                    np.round(np.degrees(q), 3).tolist(), short)
        if short <= math.degrees(SETTLE_TOLERANCE_RAD):
            return "stopJ sent: not moving (at the target)"
        return f"stopJ sent: motion stopped {short:.1f} deg short of the target"

    async def close(self) -> None:
        """Stop the control script and disconnect every interface (each failure logged,
        closing goes on; each step bounded by CLOSE_STEP_TIMEOUT_S: a dead controller never
        answers, and its blocked call is left in its daemon thread)."""
        steps: tuple[tuple[str, Any, Callable[[Any], object]], ...] = (
            ("stopScript", self.control, lambda control: control.stopScript()),
            ("control.disconnect", self.control, lambda control: control.disconnect()),
            ("io.disconnect", self.io, lambda io: io.disconnect()),
            ("receive.disconnect", self.receive, lambda receive: receive.disconnect()),
        )
        for name, interface, step in steps:
            if interface is None:
                continue
            try:  # a cancel lost with a step's result (gh-86296) only lets closing go on
                await asyncio.wait_for(in_daemon_thread(step, interface),
                                       CLOSE_STEP_TIMEOUT_S)
            except Exception as exc:  # closing must go on
                logger.warning("UR %s: %s failed: %s", self.host, name,
                               str(exc) or type(exc).__name__)
