"""Joint moves of the arm simulation: planning a motion, and executing it to its end or
part-way.

A motion is planned (`begin_move`: checks, counters, faults and the IO edges along the path,
nothing moves yet) and then executed (`finish_move`), so the server can pace it in wall time
and an abort stops the robot where it was. The path is a straight line in reported joint
space, q(s) = q_start + s * (q_target - q_start), s in [0, 1], s(t) the move's trapezoidal
velocity profile (`motion.PathProfile`: every joint ramps at the scenario's
motion.max_joint_acceleration; `motion.py` has the values and the law).
Guarded moves are planned by `guarded.GuardedMoves`; finishing one (the latch, the stop
past it) happens here. Angles radians (reported frame), times seconds of the simulated clock.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import Scenario
from controller_stub.world.arm import ArmBody
from controller_stub.world.controller_state import ControllerState
from controller_stub.world.guarded import GuardedMoves
from controller_stub.world.motion import (
    GuardedMoveResult,
    MotionPlan,
    MoveResult,
    PathEdge,
    PathProfile,
)


class JointMotion:
    """The arm's motions: begin_move / finish_move, move_joints and guarded_move.

    state: the controller state (reported angles, clock, limits, e-stop, the motion in
    progress); body: the arm (backlash approach); guarded: the probe input along paths and
    the guarded-move planner. Owns the move counters behind the injected faults
    (`faults.refuse_move_indices`, `faults.estop_after_moves`).
    """

    def __init__(self, scenario: Scenario, state: ControllerState, body: ArmBody,
                 guarded: GuardedMoves) -> None:
        self.scenario = scenario
        self.state = state
        self.body = body
        self.guarded = guarded
        self._move_count = 0
        self._completed_moves = 0
        self._estop_fault_fired = False

    def _begin_motion(self, q_target: Any, speed: float, acceleration: float | None
                      ) -> tuple[np.ndarray, PathProfile]:
        """Common checks; returns (target (n,), its time law). Counts the move."""
        state = self.state
        target = state.check_vector(q_target, "q_target")
        if not (isinstance(speed, int | float) and 0.0 < float(speed) <= 1.0):
            raise SimulationRefused("invalid_argument", f"speed {speed!r} not in (0, 1]")
        if state.estopped:
            raise SimulationRefused("estop", "emergency stop active; reset it before moving")
        index = self._move_count
        self._move_count += 1
        if index in self.scenario.faults.refuse_move_indices:
            raise SimulationRefused("refused_fault", f"move {index} refused (injected fault)")
        state.check_joint_limits(target)
        return target, state.move_profile(state.joint_positions(), target, float(speed),
                                          acceleration)

    def motion_duration(self, q_from: np.ndarray, q_to: np.ndarray, speed: float) -> float:
        """Simulated time (s) of a joint move q_from -> q_to at `speed` (the ramped law of
        `motion.PathProfile`)."""
        return self.state.move_profile(q_from, q_to, speed).duration_s

    def arrive(self, q_start: np.ndarray, q_end: np.ndarray, duration: float) -> None:
        """A motion from q_start ended at q_end (n,) after `duration` s (to its end or cut
        short, an abort): the body's approach, the reported angles and the clock follow;
        counts the move (estop fault). A motion that went somewhere, completed or aborted
        (an abort decelerates the arm), leaves the robot to settle before its next
        measurement (`ControllerState.end_motion`); the move itself charges no settling."""
        self.body.note_motion(q_start, q_end)
        self.state.set_position(q_end)
        self.state.advance_clock(duration)
        if duration > 0.0:
            self.state.end_motion()
        self._completed_moves += 1
        after = self.scenario.faults.estop_after_moves
        if after is not None and not self._estop_fault_fired and self._completed_moves >= after:
            self._estop_fault_fired = True
            self.state.estop()

    def move_joints(self, q_target: Any, speed: float) -> MoveResult:
        """Move to q_target (n,) reported rad at `speed` (fraction of max joint speed).

        Raises SimulationRefused: "estop", "joint_limit", "refused_fault", "invalid_argument".
        The probe IO line follows contact along the path (rising/falling edges reported).
        """
        result = self.finish_move(self.begin_move(q_target, speed))
        assert isinstance(result, MoveResult)
        return result

    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None,
                   acceleration: float | None = None) -> MotionPlan:
        """Plan a motion without executing it: a joint move (io_line None, see move_joints)
        or a guarded move until a rising edge on `io_line` (see guarded_move); acceleration:
        rad/s^2 the caller commands (a UR movej's), capped by the scenario's.

        The checks, move counters, faults and the probe noise draw happen here, exactly as
        in the immediate calls; the robot does not move (joint_positions() still reports
        the start) until `finish_move(plan, fraction)`. One plan at a time: another
        begin_move before finish_move is refused with "busy".
        """
        state = self.state
        state.refuse_if_busy()
        if io_line is not None and not 0 <= int(io_line) < state.n_io:
            raise SimulationRefused(
                "invalid_argument", f"io_line {io_line} out of range 0..{state.n_io - 1}"
            )
        target, profile = self._begin_motion(q_target, speed, acceleration)
        if io_line is None:
            plan = self._plan_move(target, profile)
        else:  # a guarded move measures: it starts settled
            state.settle_for_measurement()
            plan = self.guarded.plan(target, profile, int(io_line))
        state.hold_plan(plan)
        return plan

    def finish_move(
        self, plan: MotionPlan, fraction: float = 1.0
    ) -> MoveResult | GuardedMoveResult:
        """Execute `plan` up to `fraction` (clipped to [0, 1]) of it; 1 = to its end.

        The robot stops where the profile is after fraction x duration_s (the clock advances
        by that), s = plan.s_at(fraction); only the IO edges with s_edge <= s happen. A
        move stopped early (fraction < 1, e.g. an abort) reports completed=False /
        reason "aborted"; a stopped guarded move reports a contact only if the trigger
        latched before the stop (a touch after the latch point is not reported; a touch
        before it but not yet latched sets the input without an IO edge event). Raises
        SimulationRefused("invalid_argument") if `plan` is not the motion in progress.
        """
        self.state.release_plan(plan)
        fraction = min(max(float(fraction), 0.0), 1.0)
        stopped = fraction < 1.0
        s = plan.s_at(fraction)
        duration = fraction * plan.duration_s
        for edge in plan.edges:
            if edge.s <= s:
                self.guarded.set_input(edge.value, edge.time, edge.q, emit=edge.emit)
        if plan.io_line is not None:
            return self._finish_guarded(plan, s, duration, stopped)
        q_end = plan.q_start + s * (plan.q_target - plan.q_start) if stopped else plan.q_target
        self.arrive(plan.q_start, q_end, duration)
        return MoveResult(
            completed=not stopped,
            q=q_end.copy(),
            duration_s=duration,
            reason="aborted" if stopped else None,
        )

    def _plan_move(self, target: np.ndarray, profile: PathProfile) -> MotionPlan:
        """A joint move: the probe IO line follows contact along the path."""
        q_start = self.state.joint_positions()
        t_start = self.state.time
        edges = tuple(
            PathEdge(c.s, c.rising, t_start + float(profile.time_at(c.s)),
                     q_start + c.s * (target - q_start))
            for c in self.guarded.path_crossings(q_start, target, profile, t_start)
        )
        return MotionPlan(q_start, target, t_start, profile, 1.0, None, edges)

    def guarded_move(self, q_target: Any, speed: float, io_line: int) -> GuardedMoveResult:
        """Move toward q_target until a rising edge on `io_line` (the probe trigger).

        The contact is the first time the stylus tip sphere touches the reference sphere
        (contact distance R + r plus the probe's repeatability noise). The joints are latched
        `probe_trigger_latency_s` after the true contact; the robot stops `probe.stop_time_s`
        after the latch (it keeps moving along the path until then). A lost-edge fault or no
        contact runs to the end of travel and returns contact=False. The IO edge callback
        gets (line, True, latch time, latched q). Equivalent to
        finish_move(begin_move(q_target, speed, io_line)).
        """
        result = self.finish_move(self.begin_move(q_target, speed, int(io_line)))
        assert isinstance(result, GuardedMoveResult)
        return result

    def _finish_guarded(self, plan: MotionPlan, s: float, duration: float, stopped: bool
                        ) -> GuardedMoveResult:
        """The end of a guarded move stopped at path parameter s after `duration` s (edges
        already applied)."""
        assert plan.io_line is not None
        contact = plan.contact
        q_end = plan.q_start + s * (plan.q_target - plan.q_start)
        if contact is not None and contact.s_latch <= s:
            self.guarded.latch(contact)
            self.arrive(plan.q_start, q_end, duration)
            self.guarded.update_input(emit=True)
            return GuardedMoveResult(
                contact=True,
                q_latched=contact.q_latched.copy(),
                q=q_end,
                duration_s=duration,
                io_line=plan.io_line,
                speed_mps=contact.speed_mps,
                reason="aborted" if stopped else None,
            )
        if contact is not None and contact.s_contact <= s:
            # touched, but stopped before the trigger latched: no contact reported
            q_touch = plan.q_start + contact.s_contact * (plan.q_target - plan.q_start)
            t_touch = plan.t_start + float(plan.profile.time_at(contact.s_contact))
            self.guarded.set_input(True, t_touch, q_touch, emit=False)
        if not stopped:
            q_end = plan.q_target.copy()
        self.arrive(plan.q_start, q_end, duration)
        return GuardedMoveResult(
            contact=False,
            q_latched=None,
            q=q_end.copy(),
            duration_s=duration,
            io_line=plan.io_line,
            reason="aborted" if stopped else "no_contact",
        )
