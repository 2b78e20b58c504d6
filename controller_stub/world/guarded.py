"""Guarded moves and the probe's digital input along a motion path.

The touch probe's input follows contact of the stylus tip sphere with the reference sphere
along every path (rising and falling edges, reported through `on_io_edge`); a guarded move
stops at the first rising edge on its IO line, latched `probe_trigger_latency_s` after the true
contact. Lengths are metres, angles radians (reported frame), times seconds of the simulated
clock. The contact search itself is in `probe.py`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from controller_stub.scenario.spec import Scenario
from controller_stub.sensors import sphere_probe as probe_mod
from controller_stub.world.motion import GuardedContact, GuardedMoveResult, MotionPlan, PathEdge
from controller_stub.world.physics import HiddenEffects, Physics
from controller_stub.world.robot_model import RobotModel


class GuardedMoveMixin:
    """Guarded moves and the probe input of `Simulation`.

    Part of `controller_stub.world.simulation.Simulation` (its module docstring has the contract);
    the state below is created by `Simulation.__init__`.
    """

    scenario: Scenario
    model: RobotModel
    effects: HiddenEffects
    physics: Physics
    tip_flange: np.ndarray
    sphere_centre: np.ndarray
    _q: np.ndarray
    _approach: np.ndarray
    _time: float
    _inputs: list[bool]
    _guarded_count: int
    _rng_probe: np.random.Generator
    on_io_edge: Callable[[int, bool, float, np.ndarray], None] | None

    if TYPE_CHECKING:  # provided by Simulation and MotionMixin

        def current_zero_errors(self) -> np.ndarray: ...
        def tip_position(self) -> np.ndarray: ...
        def begin_move(
            self, q_target: Any, speed: float, io_line: int | None = None
        ) -> MotionPlan: ...
        def finish_move(self, plan: MotionPlan, fraction: float = 1.0) -> Any: ...
        def _finish_motion(
            self, q_start: np.ndarray, q_end: np.ndarray, duration: float
        ) -> None: ...

    def _gap_function(
        self, q_start: np.ndarray, target: np.ndarray, t_start: float, duration: float, extra: float
    ) -> probe_mod.GapFunction:
        """Gap (m) along the path s in [0, 1]: |tip - P_b| - (R + r + extra), < 0 inside.

        Uses the backlash state of this motion (moving joints approach in their direction)
        and the clock at each path point (thermal drift)."""
        moved = np.sign(target - q_start)
        approach = np.where(moved != 0, moved, self._approach)
        zero_error = self.current_zero_errors()
        pr = self.scenario.probe
        contact = pr.sphere_radius + pr.stylus_radius + extra
        drifting = self.physics.drifting

        def gap(s: np.ndarray) -> np.ndarray:
            s = np.asarray(s, float)
            q_rep = q_start[None, :] + s[:, None] * (target - q_start)[None, :]
            times = t_start + s * duration if drifting else t_start
            qp = self.physics.physical_angles(q_rep, zero_error, approach, times)
            tips = probe_mod.tip_positions(self.physics.flange_pose(qp, times), self.tip_flange)
            return np.linalg.norm(tips - self.sphere_centre, axis=1) - contact

        return gap

    def _tip_lipschitz(self, q_start: np.ndarray, target: np.ndarray) -> float:
        """Upper bound of |d tip / d s| (m) along the path: sum_i |dq_i| * (reach to tip),
        with a margin for the joint-space effects."""
        reach = (
            float(np.sum(np.linalg.norm(self.model.origin_xyz, axis=1)))
            + float(np.linalg.norm(self.model.flange_xyz))
            + float(np.linalg.norm(self.tip_flange))
        )
        return 1.2 * reach * float(np.sum(np.abs(target - q_start))) + 1e-9

    def _path_crossings(
        self,
        q_start: np.ndarray,
        target: np.ndarray,
        duration: float,
        t_start: float,
        extra: float = 0.0,
    ) -> list[probe_mod.Crossing]:
        if duration <= 0.0:
            return []
        gap = self._gap_function(q_start, target, t_start, duration, extra)
        return probe_mod.find_crossings(gap, self._tip_lipschitz(q_start, target))

    def _set_probe_input(self, value: bool, t: float, q: np.ndarray, emit: bool) -> None:
        line = self.scenario.probe.io_line
        if self._inputs[line] == value:
            return
        self._inputs[line] = value
        if emit and self.on_io_edge is not None:
            self.on_io_edge(line, value, t, q.copy())

    def _update_probe_input(self, emit: bool) -> None:
        tip = self.tip_position()
        pr = self.scenario.probe
        inside = np.linalg.norm(tip - self.sphere_centre) <= pr.sphere_radius + pr.stylus_radius
        self._set_probe_input(bool(inside), self._time, self._q, emit)

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

    def _plan_guarded_move(self, target: np.ndarray, duration: float, io_line: int) -> MotionPlan:
        """A guarded move (see guarded_move): the edges up to the contact, and the contact."""
        index = self._guarded_count
        self._guarded_count += 1
        lose_edge = index in self.scenario.faults.lose_io_edge_indices
        probe_line = self.scenario.probe.io_line
        q_start = self._q.copy()
        t_start = self._time
        noise = float(self._rng_probe.normal(0.0, self.scenario.probe.repeatability_sigma))
        crossings = self._path_crossings(q_start, target, duration, t_start, extra=noise)
        latency = self.effects.probe_trigger_latency_s
        edges: list[PathEdge] = []
        for c in crossings:
            t_c = t_start + c.s * duration
            q_c = q_start + c.s * (target - q_start)
            if not c.rising:
                edges.append(PathEdge(c.s, False, t_c, q_c))
                continue
            if io_line != probe_line or lose_edge:
                # the edge happens on the probe line, but the guarded move does not see it
                edges.append(PathEdge(c.s, True, t_c, q_c, emit=not lose_edge))
                continue
            s_latch = min(1.0, c.s + latency / duration)
            s_stop = min(1.0, s_latch + self.scenario.probe.stop_time_s / duration)
            contact = GuardedContact(
                s_contact=c.s,
                s_latch=s_latch,
                s_stop=s_stop,
                q_latched=q_start + s_latch * (target - q_start),
                time_latch=t_start + s_latch * duration,
                speed_mps=self._tip_speed(q_start, target, c.s, duration),
            )
            return MotionPlan(
                q_start, target, t_start, duration, s_stop, io_line, tuple(edges), contact
            )
        return MotionPlan(q_start, target, t_start, duration, 1.0, io_line, tuple(edges))

    def _finish_guarded(self, plan: MotionPlan, s: float, stopped: bool) -> GuardedMoveResult:
        """The end of a guarded move stopped at path parameter s (edges already applied)."""
        assert plan.io_line is not None
        contact = plan.contact
        duration = s * plan.path_duration_s
        q_end = plan.q_start + s * (plan.q_target - plan.q_start)
        if contact is not None and contact.s_latch <= s:
            probe_line = self.scenario.probe.io_line
            self._inputs[probe_line] = True
            if self.on_io_edge is not None:
                self.on_io_edge(probe_line, True, contact.time_latch, contact.q_latched.copy())
            self._finish_motion(plan.q_start, q_end, duration)
            self._update_probe_input(emit=True)
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
            t_touch = plan.t_start + contact.s_contact * plan.path_duration_s
            self._set_probe_input(True, t_touch, q_touch, emit=False)
        if not stopped:
            q_end = plan.q_target.copy()
        self._finish_motion(plan.q_start, q_end, duration)
        return GuardedMoveResult(
            contact=False,
            q_latched=None,
            q=q_end.copy(),
            duration_s=duration,
            io_line=plan.io_line,
            reason="aborted" if stopped else "no_contact",
        )

    def _tip_speed(
        self, q_start: np.ndarray, target: np.ndarray, s: float, duration: float
    ) -> float:
        """Cartesian tip speed (m/s) at path parameter s (central difference)."""
        h = 1e-6
        s_pair = np.array([max(0.0, s - h), min(1.0, s + h)])
        q_rep = q_start[None, :] + s_pair[:, None] * (target - q_start)[None, :]
        moved = np.sign(target - q_start)
        approach = np.where(moved != 0, moved, self._approach)
        qp = self.physics.physical_angles(q_rep, self.current_zero_errors(), approach, self._time)
        tips = probe_mod.tip_positions(self.physics.flange_pose(qp, self._time), self.tip_flange)
        return float(np.linalg.norm(tips[1] - tips[0]) / ((s_pair[1] - s_pair[0]) * duration))
