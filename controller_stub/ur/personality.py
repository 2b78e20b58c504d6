"""The Universal Robots personality of the simulated controller.

`controller-stub serve --ur` serves, next to the zerocal protocol and from the SAME
`Simulation`, what the unmodified ur_rtde library needs of a UR controller:

    30004  RTDE (`rtde_server.py`): joint angles, IO, registers, robot / safety state
    29999  dashboard (`dashboard.py`)
    30003  script port (`script_server.py`): ur_rtde uploads its control program here;
           `control_script.py` emulates that program on the simulation

The ports are fixed by ur_rtde (it has no option for 30004 and 29999), so only one UR
personality can run per host. The personality runs in the stub's own process: ur_rtde's
constructors hold the Python GIL while they wait for the controller, so a stub in the same
interpreter as ur_rtde deadlocks.

State shown to RTDE clients (docs/robots.md has the table), cycle by cycle like a real
controller (`paced_motion.py`: a 2 ms cycle, one RTDE package carries the angles and inputs of
one cycle): `actual_q` / `target_q` are the simulation's reported angles (along the path while
a paced move runs), `actual_digital_input_bits` bit i = simulated digital input i (the probe
line is input `probe.io_line`; it rises along an asynchronous movej when the stylus touches
the sphere, after the probe's trigger latency), `actual_digital_output_bits` bit i = output
i, standard digital outputs 0..7 write simulated outputs 0..7 and configurable outputs 0..7
write outputs 8..15 where they exist. Motions run through the simulation's begin_move /
finish_move, so a stopj ends one where it was (docs/ur-probe.md); one motion at a time holds
across both interfaces (a zerocal move meanwhile is refused "busy").
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import re
from typing import Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.network.server import ControllerServer
from controller_stub.ur.control_script import ControlScript
from controller_stub.ur.dashboard import DashboardServer
from controller_stub.ur.paced_motion import CYCLE_S, PacedMotion
from controller_stub.ur.registers import UrRegisters
from controller_stub.ur.rtde_server import RtdeServer
from controller_stub.ur.rtde_values import (
    RtdeValues,
)
from controller_stub.ur.rtde_wire import N_REGISTERS
from controller_stub.ur.script_server import ScriptServer
from controller_stub.ur.uptime import ControllerUptime
from controller_stub.world.controller_state import SimulatedController
from controller_stub.world.motion import GuardedMoveResult
from controller_stub.world.robot_model import forward
from controller_stub.world.simulation import Simulation

logger = logging.getLogger(__name__)


RTDE_PORT = 30004
DASHBOARD_PORT = 29999
SCRIPT_PORT = 30003
CONTROLLER_VERSION = (5, 11, 1, 108318)
SERIAL_NUMBER = "20235500001"

_WRITE_INT = re.compile(r"write_output_integer_register\(\s*([0-9+\s]+?)\s*,\s*(-?\d+)\s*\)")


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3,) axis * angle of the rotation matrix R (3, 3)."""
    cos_angle = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.acos(cos_angle)
    if angle < 1e-12:
        return np.zeros(3)
    if math.pi - angle < 1e-6:
        axis = np.sqrt(np.clip((np.diag(R) + 1.0) / 2.0, 0.0, None))
        signs = np.sign([1.0, R[0, 1] + R[1, 0], R[0, 2] + R[2, 0]])
        axis = axis * np.where(signs == 0, 1.0, signs)
        return axis / np.linalg.norm(axis) * angle
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return axis / (2.0 * math.sin(angle)) * angle


class UrPersonality:
    """Serve one `Simulation` as a Universal Robots controller (RTDE, dashboard, script).

    sim: the Simulation (6 joints). server: the stub's `ControllerServer` sharing `sim`
    (motion pacing and busy/abort across both interfaces), or None (pacing by sleeping).
    max_stream_hz: cap of the RTDE data package rate.

    Collaborators, each owning its state: `registers` (the register banks, `registers.py`),
    `rtde_values` (the RTDE data source over them, `rtde_values.py`), the three servers, the
    running program (`control_script.py`) and the paced motion (`paced_motion.py`). The
    personality itself owns the controller cycle, the protective stop and the program task.
    """

    def __init__(
        self,
        sim: SimulatedController,
        server: ControllerServer | None = None,
        *,
        controller_version: tuple[int, int, int, int] = CONTROLLER_VERSION,
        serial_number: str = SERIAL_NUMBER,
        max_stream_hz: float = 500.0,
    ) -> None:
        if sim.n_joints != 6 or not isinstance(sim, Simulation):
            raise ValueError(f"the UR personality needs a 6-joint robot, {sim.robot_name} has "
                             f"{sim.n_joints}")
        self.sim: Simulation = sim
        self.server = server
        self.controller_version = controller_version
        self.serial_number = serial_number
        self.robot_model = sim.robot_name.upper().rstrip("E") if sim.robot_name.startswith(
            "ur") else "UR5"
        self.registers = UrRegisters()
        self.rtde_values = RtdeValues(self, self.registers)
        self._program_name = ""
        self._program: asyncio.Task[None] | None = None
        self._protective_stop = False
        self._motion: PacedMotion | None = None
        self._stop = asyncio.Event()
        self.cycle = 0
        """The controller cycle counter (`paced_motion.py`)."""
        self._cycle_event = asyncio.Event()
        self._uptime = ControllerUptime(sim.state)
        self._clock: asyncio.Task[None] | None = None
        self._rtde = RtdeServer(self.rtde_values, max_stream_hz=max_stream_hz)
        self._dashboard = DashboardServer(self)
        self._script = ScriptServer(self)

    # ------------------------------------------------------------------ lifecycle

    async def start(
        self,
        host: str = "127.0.0.1",
        rtde_port: int = RTDE_PORT,
        dashboard_port: int = DASHBOARD_PORT,
        script_port: int = SCRIPT_PORT,
    ) -> dict[str, tuple[str, int]]:
        """Start the three servers; returns {"rtde"|"dashboard"|"script": (host, port)}."""
        bound: dict[str, tuple[str, int]] = {}
        self._clock = asyncio.create_task(self._run_clock())
        try:
            bound["rtde"] = await self._rtde.start(host, rtde_port)
            bound["dashboard"] = await self._dashboard.start(host, dashboard_port)
            bound["script"] = await self._script.start(host, script_port)
        except BaseException:
            await self.close()
            raise
        return bound

    async def close(self) -> None:
        """Stop the program and the servers."""
        await self._stop_program_task()
        for server in (self._script, self._dashboard, self._rtde):
            await server.close()
        clock, self._clock = self._clock, None
        if clock is not None:
            clock.cancel()
            with contextlib.suppress(BaseException):
                await clock

    async def _run_clock(self) -> None:
        """Advance the controller cycle every CYCLE_S of wall time (never more than one
        cycle per wake-up: a late event loop slows the controller instead of skipping)."""
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            next_at = max(next_at + CYCLE_S, loop.time())
            await asyncio.sleep(next_at - loop.time())
            self.cycle += 1
            self._uptime.tick(self._motion is not None
                              or (self.server is not None and self.server.mode() == "moving"))
            event, self._cycle_event = self._cycle_event, asyncio.Event()
            event.set()

    @property
    def uptime(self) -> float:
        """The controller's uptime (s), RTDE `timestamp` (`uptime.py`): 2 ms per cycle
        (slower than the wall clock when a loaded machine slows the cycles) plus the
        simulated time it charged beyond them."""
        return self._uptime.seconds

    async def next_cycle(self, after: int) -> int:
        """Wait until the controller cycle is past `after`; returns the cycle."""
        while self.cycle <= after:
            await self._cycle_event.wait()
        return self.cycle

    # ------------------------------------------------------------------ state

    @property
    def moving(self) -> bool:
        """True while a paced motion runs."""
        return self._motion is not None

    def program_running(self) -> bool:
        """A program runs, and no stop of it was asked (dashboard `stop`): a UR reports its
        program stopped once the stop is taken, not when its task has wound down (a host
        asking why a move ended read "running" in that gap and took a stop for a miss)."""
        return (self._program is not None and not self._program.done()
                and not self._program.cancelling())

    def program_name(self) -> str:
        return self._program_name

    def protective_stopped(self) -> bool:
        return self._protective_stop

    def emergency_stopped(self) -> bool:
        return bool(self.sim.estopped)

    def unlock_protective_stop(self) -> None:
        self._protective_stop = False

    def protective_stop(self, reason: str) -> None:
        """Enter a protective stop (the program is stopped by its caller)."""
        logger.warning("protective stop: %s", reason)
        self._protective_stop = True

    def displayed_q(self) -> np.ndarray:
        """(6,) reported angles of the current controller cycle (along a paced motion)."""
        motion = self._motion
        if motion is None:
            return np.asarray(self.sim.joint_positions(), float)
        return motion.q_at(self.cycle)

    def displayed_qd(self) -> np.ndarray:
        """(6,) joint speeds (rad/s) of the paced motion, zeros at rest."""
        motion = self._motion
        if motion is None:
            return np.zeros(6)
        return motion.qd_at(self.cycle)

    def displayed_inputs(self) -> list[bool]:
        """Digital inputs of the current cycle: the probe line follows the paced motion."""
        inputs = list(self.sim.digital_inputs())
        motion = self._motion
        if motion is not None and 0 <= motion.probe_line < len(inputs):
            line = motion.probe_line
            inputs[line] = motion.probe_level(self.cycle, inputs[line])
        return inputs

    def tcp_pose(self, q: np.ndarray | None = None) -> list[float]:
        """UR pose [x, y, z, rx, ry, rz] of the flange (nominal model, reported angles)."""
        q = self.displayed_q() if q is None else q
        _, T = forward(self.sim.model, np.asarray(q, float)[None, :])
        return [*T[0, :3, 3].tolist(), *_rotation_vector(T[0, :3, :3]).tolist()]

    # ------------------------------------------------------------------ programs

    def run_program(self, name: str, text: str) -> None:
        """Start program `name` from the script port, replacing the running one."""
        old = self._program
        self._program_name = name
        if self._is_control_script(name, text):
            script = ControlScript(self, text)
            self._program = asyncio.create_task(self._run_after(old, script.run()))
        else:
            logger.warning(
                "program %r is not emulated (only ur_rtde's control script is); its "
                "write_output_integer_register calls are applied and it ends at once", name
            )
            self._program = asyncio.create_task(self._run_after(old, self._generic(text)))

    @staticmethod
    def _is_control_script(name: str, text: str) -> bool:
        return name == "rtde_control" or ("def rtde_cmd():" in text and "signal_ready" in text)

    async def _run_after(self, old: asyncio.Task[None] | None, body: Any) -> None:
        if old is not None and not old.done():
            old.cancel()
            with contextlib.suppress(BaseException):
                await old
        await body

    async def _generic(self, text: str) -> None:
        for index_text, value in _WRITE_INT.findall(text):
            try:
                index = sum(int(part) for part in index_text.split("+") if part.strip())
            except ValueError:
                continue
            if 0 <= index < N_REGISTERS:
                self.registers.output_int[index] = int(value)
        await asyncio.sleep(0.01)

    def stop_program(self) -> None:
        """Dashboard `stop`: end the running program."""
        if self._program is not None and not self._program.done():
            self._program.cancel()

    async def _stop_program_task(self) -> None:
        task, self._program = self._program, None
        if task is not None and not task.done():
            task.cancel()
            with contextlib.suppress(BaseException):
                await task

    # ------------------------------------------------------------------ motion

    async def move_joints(
        self, q_target: np.ndarray, velocity: float, acceleration: float | None = None, *,
        watch_probe: bool = False
    ) -> tuple[bool, str | None]:
        """A movej to q_target (6,) reported rad at joint `velocity` (rad/s) and joint
        `acceleration` (rad/s^2, capped by the scenario's motion.max_joint_acceleration;
        None: the scenario's), paced cycle by cycle (`PacedMotion`) until its end or
        `stop_motion`.

        The speed fraction handed to the simulation is velocity over the slowest joint's
        maximum speed (clipped to (0, 1]). watch_probe (an asynchronous movej, which a host
        may watch over RTDE to stop it on the probe input): if the stylus touches the sphere
        along the path, planned as the simulation's guarded move on the probe line (the
        probe's trigger latency and repeatability, the contact and the stop point past it: a
        move nobody stops ends there, stylus overtravelled) and paced in real time (one cycle
        per 2 ms, so a 500 Hz RTDE client sees every cycle). A UR does not settle before a
        movej (it carries no "measure" flag): a host that measures during the move waits
        until the arm has stood still long enough, on the controller's clock (`uptime.py`;
        hostpc's UR driver does, `ur_guarded.py`), and that wait counts toward the
        simulation's settling (`ControllerState.stand_still`). The simulation's guarded
        move starts settled (it does not model a touch taken unsettled), so a touching
        movej whose host did not wait is charged the rest it still needs; a watched movej
        that misses the sphere is a plain move. Any other movej, synchronous or not, is a
        joint move like the zerocal protocol's (settling is charged before a measurement,
        not here), paced by the scenario's time_scale: a real UR moves the same way whether
        the host waits for the move or polls its progress. A stop ramp
        that runs past the plan's end ends the motion (the settle timer) at the ramp's end.
        Returns (completed, reason): reason
        "busy" (another motion runs), "stopped" (stop_motion, or the program ended),
        "contact" (a watched move that reached its stop point past the contact),
        "invalid_acceleration" (an acceleration of 0, negative or not finite), or the
        simulation's refusal code ("joint_limit", "estop", ...); the last two also raise a
        protective stop.
        """
        from controller_stub.network.handlers import RequestRefusedError

        max_speed = float(np.min(self.sim.max_joint_speed()))
        slider = max(self.registers.speed_slider, 1e-3)
        fraction = float(np.clip(velocity / max_speed, 1e-3, 1.0)) * slider
        if self._protective_stop or self.emergency_stopped():
            return False, "estop" if self.emergency_stopped() else "protective_stop"
        if acceleration is not None and not (math.isfinite(acceleration) and acceleration > 0.0):
            # a real controller refuses a movej with a = 0 (no motion profile) or a < 0
            self.protective_stop(f"movej refused: acceleration {acceleration!r} rad/s^2 is "
                                 "not a positive number")
            return False, "invalid_acceleration"
        probe_line = int(self.sim.scenario.probe.io_line)
        target = np.asarray(q_target, float)
        try:
            if self.server is not None:
                self.server.begin_motion()
            if watch_probe:
                watch_probe = self._touches(target, min(fraction, 1.0), acceleration)
            plan = self.sim.begin_move(target, min(fraction, 1.0),
                                       probe_line if watch_probe else None,
                                       None if acceleration is None else float(acceleration))
        except RequestRefusedError:
            return False, "busy"
        except SimulationRefused as exc:
            if exc.code == "busy":
                return False, "busy"
            self.protective_stop(f"movej refused: {exc}")
            return False, exc.code
        pace = max(1.0, float(self.sim.time_scale)) if watch_probe else float(self.sim.time_scale)
        motion = self._motion = PacedMotion(plan, self.cycle, pace, probe_line)
        self._stop = asyncio.Event()
        try:
            while not self._stop.is_set():
                motion = self._motion or motion  # stop_motion may have added a stop ramp
                if motion.finished(self.cycle):
                    break
                await self.next_cycle(self.cycle)
        finally:
            # at its end, at the end of a stop's ramp, or at once (program ended, cancelled):
            # the plan ends where the arm is; a ramp took longer than the plan would have
            motion = self._motion or motion
            fraction_done = motion.fraction_at(self.cycle)
            self._motion = None
            ramp_s = (0.0 if motion.stop is None else
                      max(motion.sim_time_at(self.cycle) - fraction_done * plan.duration_s, 0.0))
            result = self.sim.finish_move(plan, fraction_done)
            if ramp_s > 0.0:
                self.sim.state.advance_clock(ramp_s)
                if fraction_done >= 1.0 and plan.duration_s > 0.0:
                    # finish_move's end_motion came a ramp early: the arm rests only now
                    self.sim.state.end_motion()
        if plan.contact is not None:
            logger.info("probe contact: latched q %s, edge time %.6f s, stopped %.1f ms later",
                        np.round(plan.contact.q_latched, 9).tolist(), plan.contact.time_latch,
                        1e3 * (fraction_done * plan.duration_s
                               - float(plan.profile.time_at(plan.contact.s_latch))))
        if fraction_done < 1.0:
            return False, "stopped"
        if plan.contact is not None:
            contact = isinstance(result, GuardedMoveResult) and result.contact
            return False, "contact" if contact else "no_contact"
        return True, None

    def _touches(self, q_target: np.ndarray, fraction: float, acceleration: float | None
                 ) -> bool:
        """True if the stylus would touch the sphere along a move to q_target (6,) from where
        the arm is (a rising probe edge on the path, without the probe's noise draw)."""
        sim = self.sim
        q_start = sim.joint_positions()
        if q_target.shape != q_start.shape:
            return False  # begin_move refuses it
        profile = sim.state.move_profile(q_start, q_target, fraction, acceleration)
        return any(crossing.rising for crossing in
                   sim.guarded.path_crossings(q_start, q_target, profile, sim.state.time))

    def stop_motion(self, deceleration: float | None = None) -> bool:
        """stopj / stopl: the paced motion decelerates at `deceleration` (rad/s^2 of the
        leading joint, > 0) from the cycle reached (`PacedMotion.stopped`; move_joints
        returns at rest), or with None ends at that cycle at once (the program ended, a new
        movej); True if one ran."""
        if self._motion is None:
            return False
        if deceleration is None:
            self._stop.set()
        else:
            self._motion = self._motion.stopped(self.cycle, deceleration)
        return True
