"""Motions of the simulated robot: plans, results, and the joint move.

A motion is planned (`begin_move`: checks, counters, faults and the IO edges along the path,
nothing moves yet) and then executed to its end or part-way (`finish_move`), so the server can
pace it in wall time and an abort stops the robot where it was. The path is a straight line in
reported joint space, q(s) = q_start + s * (q_target - q_start), s in [0, 1]. Angles are
radians (reported frame), times seconds of the simulated clock. Guarded moves (the probe) are
planned and finished in `guarded.py`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import Scenario

if TYPE_CHECKING:
    from controller_stub.sensors import sphere_probe as probe_mod


@dataclass(frozen=True)
class MoveResult:
    """Outcome of a joint move.

    completed: True if the target was reached; False with `reason` (code) if aborted.
    q: (n,) reported joint angles where the robot stopped.
    duration_s: simulated motion time (the server sleeps duration_s * time_scale).
    settle_s: simulated settling time charged after the motion (scenario motion.settle_s
    for a completed move that went somewhere, else 0); the clock advanced by
    duration_s + settle_s.
    """

    completed: bool
    q: np.ndarray
    duration_s: float
    reason: str | None = None
    settle_s: float = 0.0


@dataclass(frozen=True)
class GuardedMoveResult:
    """Outcome of a guarded move toward q_target that stops at a rising IO edge.

    contact: True if the edge came before the end of travel.
    q_latched: (n,) reported angles latched at the edge (late by the trigger latency), or None.
    q: (n,) reported angles where the robot stopped.
    speed_mps: Cartesian speed of the probe tip at the contact (m/s), or None.
    """

    contact: bool
    q_latched: np.ndarray | None
    q: np.ndarray
    duration_s: float
    io_line: int
    speed_mps: float | None = None
    reason: str | None = None


@dataclass(frozen=True)
class PathEdge:
    """A change of the probe's digital input at path parameter s (0..1 of the whole path).

    time: sim time of the change (s); q: (n,) reported angles there; emit: False for an edge
    the controller does not see (lost-edge fault): the input changes silently.
    """

    s: float
    value: bool
    time: float
    q: np.ndarray
    emit: bool = True


@dataclass(frozen=True)
class GuardedContact:
    """The contact a guarded move will latch: touch at path parameter s_contact, latch at
    s_latch (trigger latency later), stop at s_stop. q_latched: (n,) reported angles at the
    latch; time_latch: sim time of the latch (s); speed_mps: tip speed at the touch (m/s)."""

    s_contact: float
    s_latch: float
    s_stop: float
    q_latched: np.ndarray
    time_latch: float
    speed_mps: float


@dataclass(frozen=True)
class MotionPlan:
    """A motion computed by `Simulation.begin_move` and not yet executed (`finish_move`).

    The path is q(s) = q_start + s * (q_target - q_start), s in [0, 1], reported rad, over
    path_duration_s of simulated time. Unless stopped early the motion ends at s = s_end (1,
    or the stop after a guarded contact) after duration_s = s_end * path_duration_s; a
    `fraction` of the motion means s = fraction * s_end. io_line: None for move_joints, the
    guarded line otherwise. edges: input changes along the path in order; contact: the
    guarded contact, or None.
    """

    q_start: np.ndarray
    q_target: np.ndarray
    t_start: float
    path_duration_s: float
    s_end: float
    io_line: int | None
    edges: tuple[PathEdge, ...]
    contact: GuardedContact | None = None

    @property
    def duration_s(self) -> float:
        """Simulated time of the motion if it is not stopped early (s)."""
        return self.s_end * self.path_duration_s

    def q_at(self, fraction: float) -> np.ndarray:
        """(n,) reported angles after `fraction` (clipped to [0, 1]) of the motion."""
        s = min(max(float(fraction), 0.0), 1.0) * self.s_end
        return self.q_start + s * (self.q_target - self.q_start)


class MotionMixin:
    """Joint moves of `Simulation`: begin_move / finish_move and the immediate move_joints.

    Part of `controller_stub.world.simulation.Simulation` (its module docstring has the contract);
    the state below is created by `Simulation.__init__`.
    """

    scenario: Scenario
    _q: np.ndarray
    _max_speed: np.ndarray
    _approach: np.ndarray
    _time: float
    _n_io: int
    _estopped: bool
    _estop_fault_fired: bool
    _move_count: int
    _completed_moves: int
    _active_plan: MotionPlan | None

    if TYPE_CHECKING:  # provided by Simulation and GuardedMoveMixin

        def _check_vector(self, values: Any, name: str) -> np.ndarray: ...
        def _check_joint_limits(self, target: np.ndarray) -> None: ...
        def _path_crossings(
            self,
            q_start: np.ndarray,
            target: np.ndarray,
            duration: float,
            t_start: float,
            extra: float = 0.0,
        ) -> list[probe_mod.Crossing]: ...
        def _set_probe_input(self, value: bool, t: float, q: np.ndarray, emit: bool) -> None: ...
        def _plan_guarded_move(
            self, target: np.ndarray, duration: float, io_line: int
        ) -> MotionPlan: ...
        def _finish_guarded(
            self, plan: MotionPlan, s: float, stopped: bool
        ) -> GuardedMoveResult: ...

    def _begin_motion(self, q_target: Any, speed: float) -> tuple[np.ndarray, float]:
        """Common checks; returns (target (n,), duration (s)). Counts the move."""
        target = self._check_vector(q_target, "q_target")
        if not (isinstance(speed, int | float) and 0.0 < float(speed) <= 1.0):
            raise SimulationRefused("invalid_argument", f"speed {speed!r} not in (0, 1]")
        if self._estopped:
            raise SimulationRefused("estop", "emergency stop active; reset it before moving")
        index = self._move_count
        self._move_count += 1
        if index in self.scenario.faults.refuse_move_indices:
            raise SimulationRefused("refused_fault", f"move {index} refused (injected fault)")
        self._check_joint_limits(target)
        return target, self.motion_duration(self._q, target, float(speed))

    def motion_duration(self, q_from: np.ndarray, q_to: np.ndarray, speed: float) -> float:
        """Simulated time (s) of a joint move: max_i |dq_i| / (speed * max_speed_i)."""
        return float(np.max(np.abs(np.asarray(q_to) - q_from) / (speed * self._max_speed)))

    def _finish_motion(self, q_start: np.ndarray, q_end: np.ndarray, duration: float) -> None:
        moved = np.sign(q_end - q_start)
        self._approach = np.where(moved != 0, moved, self._approach)
        self._q = q_end.copy()
        self._time += duration
        self._completed_moves += 1
        after = self.scenario.faults.estop_after_moves
        if after is not None and not self._estop_fault_fired and self._completed_moves >= after:
            self._estop_fault_fired = True
            self._estopped = True

    def move_joints(self, q_target: Any, speed: float) -> MoveResult:
        """Move to q_target (n,) reported rad at `speed` (fraction of max joint speed).

        Raises SimulationRefused: "estop", "joint_limit", "refused_fault", "invalid_argument".
        The probe IO line follows contact along the path (rising/falling edges reported).
        """
        result = self.finish_move(self.begin_move(q_target, speed))
        assert isinstance(result, MoveResult)
        return result

    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None) -> MotionPlan:
        """Plan a motion without executing it: a joint move (io_line None, see move_joints)
        or a guarded move until a rising edge on `io_line` (see guarded_move).

        The checks, move counters, faults and the probe noise draw happen here, exactly as
        in the immediate calls; the robot does not move (joint_positions() still reports
        the start) until `finish_move(plan, fraction)`. One plan at a time: another
        begin_move before finish_move is refused with "busy".
        """
        if self._active_plan is not None:
            raise SimulationRefused("busy", "another motion is in progress")
        if io_line is not None and not 0 <= int(io_line) < self._n_io:
            raise SimulationRefused(
                "invalid_argument", f"io_line {io_line} out of range 0..{self._n_io - 1}"
            )
        target, duration = self._begin_motion(q_target, speed)
        if io_line is None:
            plan = self._plan_move(target, duration)
        else:
            plan = self._plan_guarded_move(target, duration, int(io_line))
        self._active_plan = plan
        return plan

    def finish_move(
        self, plan: MotionPlan, fraction: float = 1.0
    ) -> MoveResult | GuardedMoveResult:
        """Execute `plan` up to `fraction` (clipped to [0, 1]) of it; 1 = to its end.

        The robot stops at q = q_start + s * (q_target - q_start), s = fraction * s_end; the
        clock advances by s * path_duration_s; only the IO edges with s_edge <= s happen. A
        move stopped early (fraction < 1, e.g. an abort) reports completed=False /
        reason "aborted"; a stopped guarded move reports a contact only if the trigger
        latched before the stop (a touch after the latch point is not reported; a touch
        before it but not yet latched sets the input without an IO edge event). Raises
        SimulationRefused("invalid_argument") if `plan` is not the motion in progress.
        """
        if plan is not self._active_plan:
            raise SimulationRefused("invalid_argument", "finish_move: not the motion in progress")
        self._active_plan = None
        fraction = min(max(float(fraction), 0.0), 1.0)
        stopped = fraction < 1.0
        s = fraction * plan.s_end
        for edge in plan.edges:
            if edge.s <= s:
                self._set_probe_input(edge.value, edge.time, edge.q, emit=edge.emit)
        if plan.io_line is not None:
            return self._finish_guarded(plan, s, stopped)
        q_end = plan.q_start + s * (plan.q_target - plan.q_start) if stopped else plan.q_target
        duration = s * plan.path_duration_s
        self._finish_motion(plan.q_start, q_end, duration)
        settle = self.settle_time(duration, stopped)
        self._time += settle
        return MoveResult(
            completed=not stopped,
            q=q_end.copy(),
            duration_s=duration,
            reason="aborted" if stopped else None,
            settle_s=settle,
        )

    def settle_time(self, duration: float, stopped: bool) -> float:
        """Settling time (s) after a joint move: the scenario's `motion.settle_s` once the
        robot arrived somewhere new; none for an aborted or a zero-length move."""
        if stopped or duration <= 0.0:
            return 0.0
        return float(self.scenario.motion.settle_s)

    def _plan_move(self, target: np.ndarray, duration: float) -> MotionPlan:
        """A joint move: the probe IO line follows contact along the path."""
        q_start = self._q.copy()
        t_start = self._time
        edges = tuple(
            PathEdge(c.s, c.rising, t_start + c.s * duration, q_start + c.s * (target - q_start))
            for c in self._path_crossings(q_start, target, duration, t_start)
        )
        return MotionPlan(q_start, target, t_start, duration, 1.0, None, edges)
