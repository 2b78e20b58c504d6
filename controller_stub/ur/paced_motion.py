"""A motion of the UR personality as the controller shows it, cycle by cycle.

A real UR controller runs a 2 ms control cycle (500 Hz, e-Series): each cycle it reads the
digital inputs, moves the joints one step, and the RTDE data package of that cycle carries
the joint angles and the input bits of the same cycle. The personality counts its cycles
(`UrPersonality.cycle`, one per 2 ms of wall time while the host keeps up; a loaded machine
slows the controller down rather than skipping cycles), and `PacedMotion` shows one
`Simulation` motion plan (`MotionPlan`, planned by `begin_move`, executed by `finish_move`
when the motion ends or is stopped) at a cycle k:

    controller time    t_k = k * CYCLE_S
    path parameter     s_k = the plan's velocity profile (`motion.PathProfile`: ramp,
                       cruise, ramp) at the simulated time elapsed since the start, in
                       [0, s_end]; wall_per_sim controller seconds per simulated second
    joint angles       q(s_k) = q_start + s_k (q_target - q_start)
    joint speeds       (q_target - q_start) ds/dt, per controller second
    probe input        the input line's level at s_k: the plan's edges up to s_k, and for a
                       watched (guarded) plan high from the latch point on (the probe's
                       trigger latency after the touch)

Pure arithmetic on the plan: no I/O, no clock of its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller_stub.world.motion import MotionPlan

CYCLE_S = 0.002
"""The controller cycle (s): 500 Hz like a UR e-Series."""


@dataclass(frozen=True)
class PacedMotion:
    """plan: the simulation's motion; start_cycle: the controller cycle it started at;
    wall_per_sim: controller seconds per simulated second (0 = instantaneous); probe_line:
    the probe's digital input."""

    plan: MotionPlan
    start_cycle: int
    wall_per_sim: float
    probe_line: int

    def fraction_at(self, cycle: int) -> float:
        """The fraction of the motion's time (for `finish_move`) reached at `cycle`."""
        duration = self.plan.duration_s
        if duration <= 0.0 or self.wall_per_sim <= 0.0:
            return 1.0
        sim_elapsed = max(0, cycle - self.start_cycle) * CYCLE_S / self.wall_per_sim
        return min(1.0, sim_elapsed / duration)

    def s_at(self, cycle: int) -> float:
        """Path parameter at controller cycle `cycle`."""
        return self.plan.s_at(self.fraction_at(cycle))

    def finished(self, cycle: int) -> bool:
        """True once the motion reached its end."""
        return self.fraction_at(cycle) >= 1.0

    def q_at(self, cycle: int) -> np.ndarray:
        """(n,) reported joint angles at `cycle`."""
        plan = self.plan
        return np.asarray(plan.q_start + self.s_at(cycle) * (plan.q_target - plan.q_start))

    def qd_at(self, cycle: int) -> np.ndarray:
        """(n,) joint speeds (rad per controller second) at `cycle`; zeros at the end."""
        plan = self.plan
        if self.finished(cycle):
            return np.zeros_like(plan.q_start)
        rate = plan.profile.rate_at(self.fraction_at(cycle) * plan.duration_s)
        return np.asarray((plan.q_target - plan.q_start) * rate / self.wall_per_sim)

    def probe_level(self, cycle: int, level_at_start: bool) -> bool:
        """The probe input's level at `cycle`: edges along the path (a watched plan's
        contact rises at its latch point, after the probe's trigger latency)."""
        s = self.s_at(cycle)
        level = level_at_start
        for edge in self.plan.edges:
            if edge.s <= s:
                level = edge.value
        contact = self.plan.contact
        if contact is not None and s >= contact.s_latch:
            level = True
        return level
