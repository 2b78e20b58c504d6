"""What every simulated controller shares: its contract, and the state behind it held once.

`SimulatedController` is the typed contract the server, the request handlers, the sessions,
the Modbus IO server and the UR personality are written against (the arm `Simulation` and
the `HumanoidSimulation` both satisfy it). Its optional sensors are typed too: `targets` (a
`TargetSensor`) and `tracker` (a `TrackerSensor`) are None on a simulation without them.

`ControllerState` is the one owner of the parts they share: the reported joint angles and
their limits, the zero offsets with their history and rollback, the digital IO, the e-stop,
the simulated clock and the motion in progress. A simulation holds one and lends it to its
collaborators (motion, guarded moves, sensors), which change it only through its methods;
`controller_base.ControllerBase` answers the contract's state calls from it.

Angles are radians (reported frame: `q_reported = encoder + zero_offset`), times seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import Scenario
from controller_stub.world.motion import GuardedMoveResult, MotionPlan, MoveResult, PathProfile

__all__ = [
    "ControllerState", "OnIoEdge", "SimulatedController", "TargetSensor", "TrackerSensor",
]

OnIoEdge = Callable[[int, bool, float, np.ndarray], None]
"""Called for each IO edge the controller reports: (line, new value, sim time, latched q)."""


class TargetSensor(Protocol):
    """A sensor that returns targets already triangulated (the humanoid's head camera)."""

    def measure_targets(self) -> dict[str, Any]:
        """{"q": (n,) reported rad, "time": s, "targets": chain -> {"p": (3,) m,
        "cov": (3, 3) m^2, "uv": (2, 2) px or absent}} at the current pose."""
        ...


class TrackerSensor(Protocol):
    """A laser tracker measuring reflectors on the flange (sensors/world_point.py)."""

    def measure_tracker(self) -> dict[str, Any]:
        """{"q": (n,) reported rad, "time": s, "seen": name -> {"p": (3,) m, "cov": (3, 3)
        m^2}, "lost": [names], "description": the tracker's nominal facts}."""
        ...


class SimulatedController(Protocol):
    """The contract of a simulated controller (see controller_stub/world/simulation.py's
    docstring).

    Optional sensors are typed attributes: `targets` and `tracker` are None where a
    simulation has no such sensor (the handlers then refuse with "unsupported").
    """

    scenario: Scenario
    on_io_edge: OnIoEdge | None

    @property
    def robot_name(self) -> str: ...
    @property
    def n_joints(self) -> int: ...
    @property
    def time(self) -> float: ...
    @property
    def time_scale(self) -> float: ...
    @property
    def estopped(self) -> bool: ...
    @property
    def busy(self) -> bool: ...

    def joint_positions(self) -> np.ndarray: ...
    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]: ...
    def max_joint_speed(self) -> np.ndarray: ...
    def max_joint_acceleration(self) -> np.ndarray: ...
    def zero_offsets(self) -> np.ndarray: ...
    def set_zero_offsets(self, offsets: Any) -> np.ndarray: ...
    def offset_history(self) -> list[tuple[int, np.ndarray]]: ...
    @property
    def last_history_id(self) -> int: ...
    def rollback(self, history_id: int) -> np.ndarray: ...
    def undo_write(self, history_id: int) -> np.ndarray: ...
    def digital_inputs(self) -> list[bool]: ...
    def digital_outputs(self) -> list[bool]: ...
    def set_digital_output(self, index: int, value: bool) -> None: ...
    def estop(self) -> None: ...
    def reset_estop(self) -> None: ...
    def move_joints(self, q_target: Any, speed: float) -> MoveResult: ...
    def guarded_move(self, q_target: Any, speed: float, io_line: int) -> GuardedMoveResult: ...
    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None,
                   acceleration: float | None = None) -> MotionPlan:
        ...
    def finish_move(
        self, plan: MotionPlan, fraction: float = 1.0
    ) -> MoveResult | GuardedMoveResult: ...
    def settle_for_measurement(self) -> float: ...
    def hold_for_capture(self) -> None: ...
    def capture_stereo(self, pattern: str = "target", view: int = 0) -> Any: ...
    def camera_description(self) -> dict[str, Any]: ...
    def truth(self) -> dict[str, Any]: ...
    @property
    def targets(self) -> TargetSensor | None: ...
    @property
    def tracker(self) -> TrackerSensor | None: ...


class ControllerState:
    """The state every simulated controller holds, and the behaviour on it that they share.

    Its collaborators (motion, guarded moves, sensors) read it through the contract's calls
    and change it only through the methods below the contract's (`set_position`,
    `advance_clock`, `hold_plan` / `release_plan`, `drive_input` / `latch_input`).

    scenario: the scenario (server limits, IO count, initial offsets, motion limits).
    zero_errors: (n,) the hidden zero errors with the original offsets (rad).
    q_min, q_max: (n,) joint limits in the reported frame (rad); max_speed: (n,) rad/s.
    start: (n,) initial reported angles (clipped into the limits).
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        zero_errors: np.ndarray,
        q_min: np.ndarray,
        q_max: np.ndarray,
        max_speed: np.ndarray,
        start: Any,
    ) -> None:
        self.scenario = scenario
        self._q_min = np.asarray(q_min, dtype=float)
        self._q_max = np.asarray(q_max, dtype=float)
        n = self._q_min.size
        self._n = n
        self._zero_error_initial = np.asarray(zero_errors, dtype=float)
        self._max_speed = np.asarray(max_speed, dtype=float)
        self._max_acceleration = np.broadcast_to(
            np.asarray(scenario.motion.max_joint_acceleration, float), (n,)).copy()
        server = scenario.server
        self._offsets_initial = (
            np.zeros(n)
            if server.initial_offsets is None
            else np.asarray(server.initial_offsets, float)
        )
        self._offsets = self._offsets_initial.copy()
        self._history: list[tuple[int, np.ndarray]] = [(0, self._offsets.copy())]
        self._next_history_id = 1
        self._q = np.clip(np.asarray(start, float), self._q_min, self._q_max)
        self._time = 0.0
        self._settled_at = 0.0  # the clock when the robot has stood still settle_s since it moved
        self._n_io = server.n_digital_io
        self._inputs = [False] * self._n_io
        self._outputs = [False] * self._n_io
        self._estopped = False
        self.on_io_edge: OnIoEdge | None = None
        self._active_plan: MotionPlan | None = None  # begun, not yet finished

    # ------------------------------------------------------------------ simple state

    @property
    def n_joints(self) -> int:
        return self._n

    @property
    def time(self) -> float:
        """Simulated clock (s): robot time. Advances by motion durations, by the settling
        before a measurement that follows motion (`settle_for_measurement`) and by each
        stereo capture, target measurement or tracker reading (`motion.capture_s`)."""
        return self._time

    @property
    def time_scale(self) -> float:
        """Wall seconds per simulated second of motion."""
        return float(self.scenario.motion.time_scale)

    @property
    def estopped(self) -> bool:
        return self._estopped

    @property
    def busy(self) -> bool:
        """True while a motion from begin_move is not finished."""
        return self._active_plan is not None

    def estop(self) -> None:
        self._estopped = True

    def reset_estop(self) -> None:
        self._estopped = False

    def joint_positions(self) -> np.ndarray:
        """(n,) reported joint angles (rad)."""
        return self._q.copy()

    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """((n,), (n,)) lower and upper limits in the reported frame (rad)."""
        return self._q_min.copy(), self._q_max.copy()

    def max_joint_speed(self) -> np.ndarray:
        """(n,) maximum joint speeds (rad/s)."""
        return self._max_speed.copy()

    def max_joint_acceleration(self) -> np.ndarray:
        """(n,) joint accelerations (rad/s^2) of every move (scenario
        motion.max_joint_acceleration)."""
        return self._max_acceleration.copy()

    def move_profile(self, q_from: np.ndarray, q_to: np.ndarray, speed: float,
                     acceleration: float | None = None) -> PathProfile:
        """The time law of a move q_from -> q_to (n,) at `speed` (fraction of the top
        speeds): each joint at most speed x max_joint_speed and max_joint_acceleration
        (capped at `acceleration` rad/s^2 if given: what a UR host commands)."""
        accel = self._max_acceleration
        if acceleration is not None:
            accel = np.minimum(accel, float(acceleration))
        return PathProfile.of_move(np.asarray(q_to, float) - np.asarray(q_from, float),
                                   float(speed) * self._max_speed, accel)

    # ------------------------------------------------------------------ zero offsets

    def zero_offsets(self) -> np.ndarray:
        """(n,) current controller zero offsets (rad): q_reported = encoder + offset."""
        return self._offsets.copy()

    def current_zero_errors(self) -> np.ndarray:
        """(n,) rad: constant part of q_phys - q_reported with the CURRENT offsets."""
        errors: np.ndarray = self._zero_error_initial + self._offsets_initial - self._offsets
        return errors

    def set_zero_offsets(self, offsets: Any) -> np.ndarray:
        """Write new zero offsets (n,) rad; returns the previous ones.

        The encoders do not move, so the reported angles shift by (new - old) and the same
        reported command afterwards reaches a different physical pose. Refused with
        "offset_limit" if any joint would differ from the ORIGINAL offsets by more than
        server.offset_limit_rad, "invalid_argument" for a wrong shape or non-finite values,
        "busy" while a motion from begin_move is not finished.
        """
        if self.busy:
            raise SimulationRefused("busy", "cannot change the zero offsets while moving")
        new = self.check_vector(offsets, "offsets")
        limit = self.scenario.server.offset_limit_rad
        change = np.abs(new - self._offsets_initial)
        if np.any(change > limit):
            i = int(np.argmax(change))
            raise SimulationRefused(
                "offset_limit",
                f"joint {i + 1}: offset change {math.degrees(change[i]):.3f} deg from the "
                f"original exceeds the limit {math.degrees(limit):.3f} deg",
            )
        previous = self._offsets.copy()
        self._q = self._q + (new - self._offsets)
        self._offsets = new
        self._history.append((self._next_history_id, new.copy()))
        self._next_history_id += 1
        return previous

    def offset_history(self) -> list[tuple[int, np.ndarray]]:
        """Every offset set the controller has held, oldest first: (id, (n,) offsets).

        id 0 is the original set; every successful set_zero_offsets / rollback appends one.
        This is the controller's one rollback history: the server's rollback ids name its
        entries (`undo_write`).
        """
        return [(i, o.copy()) for i, o in self._history]

    @property
    def last_history_id(self) -> int:
        """The id of the offset set held now (the newest history entry)."""
        return self._history[-1][0]

    def rollback(self, history_id: int) -> np.ndarray:
        """Restore the offsets recorded under `history_id`; returns the previous offsets.

        Raises SimulationRefused("unknown_history_id") for an id never recorded.
        """
        return self.set_zero_offsets(self._history[self._history_index(history_id)][1])

    def undo_write(self, history_id: int) -> np.ndarray:
        """Restore the offsets held just before the write recorded as `history_id`; returns
        the offsets replaced. Raises SimulationRefused("unknown_history_id") for an id never
        recorded or for the original set (id 0: no write before it)."""
        index = self._history_index(history_id)
        if index == 0:
            raise SimulationRefused("unknown_history_id", "the original offsets undo nothing")
        return self.set_zero_offsets(self._history[index - 1][1])

    def _history_index(self, history_id: int) -> int:
        for index, (i, _) in enumerate(self._history):
            if i == history_id:
                return index
        raise SimulationRefused("unknown_history_id", f"no offset history entry {history_id}")

    def zero_errors_initial(self) -> np.ndarray:
        """(n,) rad: the hidden zero errors with the original offsets (truth)."""
        return self._zero_error_initial.copy()

    def offsets_initial(self) -> np.ndarray:
        """(n,) rad: the offsets the controller started with."""
        return self._offsets_initial.copy()

    # ------------------------------------------------------------------ motion and clock

    def set_position(self, q: np.ndarray) -> None:
        """The robot now stands at reported angles `q` (n,) rad (end of a motion)."""
        self._q = np.asarray(q, dtype=float).copy()

    def advance_clock(self, dt: float) -> None:
        """Advance the simulated clock by `dt` s (motion, capture)."""
        self._time += dt

    def end_motion(self) -> None:
        """A motion that went somewhere ended now, completed or aborted (an abort
        decelerates the arm): the robot is at rest but still vibrating; a measurement waits
        until it has stood still `motion.settle_s`."""
        self._settled_at = self._time + float(self.scenario.motion.settle_s)

    def stand_still(self, seconds: float) -> None:
        """The robot stood still `seconds` s that the simulated clock does not count (a UR
        controller's idle wall time, `controller_stub.ur.uptime`): they count toward its
        settling."""
        self._settled_at -= seconds

    def settle_for_measurement(self) -> float:
        """Settle before a measurement: the clock waits max(0, settle_s - the time the robot
        has stood still since its last motion ended, `end_motion`); returns that wait (s).
        Called by every measuring request (a stereo capture, a target measurement, a
        tracker or sensor reading, the start of a guarded move): settling is charged
        where a measurement needs it, not after every move."""
        wait = max(0.0, self._settled_at - self._time)
        self._time = max(self._time, self._settled_at)
        return wait

    def hold_plan(self, plan: MotionPlan) -> None:
        """`plan` is the motion in progress (begun, not finished); busy until released."""
        self._active_plan = plan

    def release_plan(self, plan: MotionPlan) -> None:
        """End the motion in progress, which must be `plan`, else
        SimulationRefused("invalid_argument")."""
        if plan is not self._active_plan:
            raise SimulationRefused("invalid_argument", "finish_move: not the motion in progress")
        self._active_plan = None

    # ------------------------------------------------------------------ IO

    def digital_inputs(self) -> list[bool]:
        return list(self._inputs)

    def digital_outputs(self) -> list[bool]:
        return list(self._outputs)

    def set_digital_output(self, index: int, value: bool) -> None:
        if not 0 <= int(index) < self._n_io:
            raise SimulationRefused(
                "invalid_argument", f"digital output {index} out of range 0..{self._n_io - 1}"
            )
        self._outputs[int(index)] = bool(value)

    @property
    def n_io(self) -> int:
        """Number of digital input (and output) lines."""
        return self._n_io

    def drive_input(self, line: int, value: bool, t: float, q: np.ndarray, emit: bool) -> None:
        """Set digital input `line` to `value` (a sensor's line, e.g. the probe's). A change
        is reported through `on_io_edge(line, value, t, q)` unless `emit` is False (an edge
        the controller does not see); no change, no report."""
        if self._inputs[line] == value:
            return
        self._inputs[line] = value
        if emit and self.on_io_edge is not None:
            self.on_io_edge(line, value, t, q.copy())

    def latch_input(self, line: int, t: float, q_latched: np.ndarray) -> None:
        """A trigger latched on input `line`: it is high, and the edge is reported with the
        latch time `t` and the latched angles `q_latched` (n,)."""
        self._inputs[line] = True
        if self.on_io_edge is not None:
            self.on_io_edge(line, True, t, q_latched.copy())

    # ------------------------------------------------------------------ argument checks

    def check_vector(self, values: Any, name: str) -> np.ndarray:
        """(n,) finite float vector from `values`, or SimulationRefused("invalid_argument")."""
        try:
            v = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise SimulationRefused("invalid_argument", f"{name}: not a numeric vector") from None
        if v.shape != (self._n,):
            raise SimulationRefused(
                "invalid_argument", f"{name}: expected {self._n} values, got {v.size}"
            )
        if not np.all(np.isfinite(v)):
            raise SimulationRefused("invalid_argument", f"{name}: non-finite value")
        return v

    def check_joint_limits(self, target: np.ndarray) -> None:
        """SimulationRefused("joint_limit") if `target` (n,) is outside the joint limits."""
        outside = (target < self._q_min) | (target > self._q_max)
        if np.any(outside):
            i = int(np.argmax(outside))
            raise SimulationRefused(
                "joint_limit",
                f"joint {i + 1}: target {target[i]:.6f} rad outside "
                f"[{self._q_min[i]:.6f}, {self._q_max[i]:.6f}]",
            )

    def refuse_if_busy(self) -> None:
        """SimulationRefused("busy") while a motion from begin_move is not finished."""
        if self.busy:
            raise SimulationRefused("busy", "another motion is in progress")

