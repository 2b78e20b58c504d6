"""Guarded moves and the probe's digital input along a motion path.

The touch probe's input follows contact of the stylus tip sphere with the reference sphere
along every path (rising and falling edges, reported through `on_io_edge`); a guarded move
stops at the first rising edge on its IO line, latched `probe_trigger_latency_s` after the true
contact, and stops `probe.stop_time_s` after the latch, where the move's velocity profile
has carried it by then (a guarded approach is slow: mostly at cruise, its short ramp
included). Lengths are metres, angles radians (reported frame), times seconds of the simulated
clock. The contact search itself is in `sensors/sphere_probe.py`; `joint_motion.py` finishes
a guarded move (the latch and the stop) through `latch` and `update_input` here.
"""

from __future__ import annotations

import numpy as np

from controller_stub.scenario.spec import Scenario
from controller_stub.sensors import sphere_probe as probe_mod
from controller_stub.sensors.sphere_probe import TouchProbe
from controller_stub.world.arm import ArmBody
from controller_stub.world.controller_state import ControllerState
from controller_stub.world.motion import GuardedContact, MotionPlan, PathEdge, PathProfile


class GuardedMoves:
    """The probe's input along motion paths, and the planning of guarded moves.

    state: the controller state (reported angles, clock, the probe's input line); body: the
    arm (physics and backlash); probe: the touch probe sensor; rng: the probe's noise
    stream. Owns the guarded-move count (for injected lost edges).
    """

    def __init__(self, scenario: Scenario, state: ControllerState, body: ArmBody,
                 probe: TouchProbe, rng: np.random.Generator) -> None:
        self.scenario = scenario
        self.state = state
        self.body = body
        self.probe = probe
        self._rng = rng
        self._count = 0

    def _gap_function(
        self, q_start: np.ndarray, target: np.ndarray, t_start: float, profile: PathProfile,
        extra: float
    ) -> probe_mod.GapFunction:
        """Gap (m) along the path s in [0, 1]: |tip - P_b| - (R + r + extra), < 0 inside.

        Uses the backlash state of this motion (moving joints approach in their direction)
        and the clock at each path point (thermal drift)."""
        approach = self.body.approach_toward(q_start, target)
        physics = self.body.physics
        drifting = physics.drifting

        def gap(s: np.ndarray) -> np.ndarray:
            s = np.asarray(s, float)
            q_rep = q_start[None, :] + s[:, None] * (target - q_start)[None, :]
            times = t_start + profile.time_at(s) if drifting else t_start
            qp = self.body.physical_along(q_rep, approach, times)
            return self.probe.gaps(physics.flange_pose(qp, times), extra)

        return gap

    def _tip_lipschitz(self, q_start: np.ndarray, target: np.ndarray) -> float:
        """Upper bound of |d tip / d s| (m) along the path: sum_i |dq_i| * (reach to tip),
        with a margin for the joint-space effects."""
        model = self.body.model
        reach = (
            float(np.sum(np.linalg.norm(model.origin_xyz, axis=1)))
            + float(np.linalg.norm(model.flange_xyz))
            + float(np.linalg.norm(self.probe.tip_flange))
        )
        return 1.2 * reach * float(np.sum(np.abs(target - q_start))) + 1e-9

    def path_crossings(
        self,
        q_start: np.ndarray,
        target: np.ndarray,
        profile: PathProfile,
        t_start: float,
        extra: float = 0.0,
    ) -> list[probe_mod.Crossing]:
        """Where the probe's input changes along the path from q_start to target (n,)
        reported rad moved by `profile` from `t_start` (extra: contact distance noise, m)."""
        if profile.duration_s <= 0.0:
            return []
        gap = self._gap_function(q_start, target, t_start, profile, extra)
        return probe_mod.find_crossings(gap, self._tip_lipschitz(q_start, target))

    def set_input(self, value: bool, t: float, q: np.ndarray, emit: bool) -> None:
        """The probe's input becomes `value` at time t and reported angles q (n,)."""
        self.state.drive_input(self.probe.io_line, value, t, q, emit)

    def update_input(self, emit: bool) -> None:
        """The probe's input follows contact at the current pose."""
        state = self.state
        inside = self.probe.touching(self.body.flange_pose())
        self.set_input(inside, state.time, state.joint_positions(), emit)

    def latch(self, contact: GuardedContact) -> None:
        """The trigger latched `contact`: the input is high, the edge reported."""
        self.state.latch_input(self.probe.io_line, contact.time_latch, contact.q_latched)

    def plan(self, target: np.ndarray, profile: PathProfile, io_line: int) -> MotionPlan:
        """A guarded move (see `Simulation.guarded_move`): the edges up to the contact, and
        the contact."""
        index = self._count
        self._count += 1
        lose_edge = index in self.scenario.faults.lose_io_edge_indices
        probe_line = self.probe.io_line
        q_start = self.state.joint_positions()
        t_start = self.state.time
        noise = float(self._rng.normal(0.0, self.scenario.probe.repeatability_sigma))
        crossings = self.path_crossings(q_start, target, profile, t_start, extra=noise)
        latency = self.body.effects.probe_trigger_latency_s
        edges: list[PathEdge] = []
        for c in crossings:
            t_c = t_start + float(profile.time_at(c.s))
            q_c = q_start + c.s * (target - q_start)
            if not c.rising:
                edges.append(PathEdge(c.s, False, t_c, q_c))
                continue
            if io_line != probe_line or lose_edge:
                # the edge happens on the probe line, but the guarded move does not see it
                edges.append(PathEdge(c.s, True, t_c, q_c, emit=not lose_edge))
                continue
            t_latch = min(t_c - t_start + latency, profile.duration_s)
            s_latch = float(profile.s_at(t_latch))
            s_stop = float(profile.s_at(t_latch + self.scenario.probe.stop_time_s))
            contact = GuardedContact(
                s_contact=c.s,
                s_latch=s_latch,
                s_stop=s_stop,
                q_latched=q_start + s_latch * (target - q_start),
                time_latch=t_start + t_latch,
                speed_mps=self.tip_speed(q_start, target, c.s, profile),
            )
            return MotionPlan(
                q_start, target, t_start, profile, s_stop, io_line, tuple(edges), contact
            )
        return MotionPlan(q_start, target, t_start, profile, 1.0, io_line, tuple(edges))

    def tip_speed(
        self, q_start: np.ndarray, target: np.ndarray, s: float, profile: PathProfile
    ) -> float:
        """Cartesian tip speed (m/s) at path parameter s: |d tip / d s| (central
        difference) x the profile's ds/dt there."""
        h = 1e-6
        s_pair = np.array([max(0.0, s - h), min(1.0, s + h)])
        q_rep = q_start[None, :] + s_pair[:, None] * (target - q_start)[None, :]
        approach = self.body.approach_toward(q_start, target)
        t_now = self.state.time
        qp = self.body.physical_along(q_rep, approach, t_now)
        tips = self.probe.tips(self.body.physics.flange_pose(qp, t_now))
        rate = profile.rate_at(float(profile.time_at(s)))
        return float(np.linalg.norm(tips[1] - tips[0]) / (s_pair[1] - s_pair[0]) * rate)
