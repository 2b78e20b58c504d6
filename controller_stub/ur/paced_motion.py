"""A motion of the UR personality as the controller shows it, cycle by cycle.

A real UR controller runs a 2 ms control cycle (500 Hz, e-Series): each cycle it reads the
digital inputs, moves the joints one step, and the RTDE data package of that cycle carries
the joint angles and the input bits of the same cycle. `PacedMotion` reproduces that for one
`Simulation` motion plan (`MotionPlan`, planned by `begin_move` and executed by `finish_move`
when the motion ends or is stopped):

    controller time    t_k = k * CYCLE_S (wall clock since the personality started)
    path parameter     s_k = elapsed simulated time at t_k / path duration, in [0, s_end]
    joint angles       q(s_k) = q_start + s_k (q_target - q_start)
    probe input        the input line's level at s_k: the plan's edges up to s_k, and for a
                       watched (guarded) plan high from the latch point on (the probe's
                       trigger latency after the touch)

Simulated time runs `1 / wall_per_sim` times faster than the wall clock (the scenario's
`time_scale`, or real time for a watched move, so an RTDE client sees every cycle). Pure
arithmetic on the plan: no I/O, no clock of its own (callers pass `now`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller_stub.motion import MotionPlan

CYCLE_S = 0.002
"""The controller cycle (s): 500 Hz like a UR e-Series."""


def cycle_start(now: float, t0: float) -> float:
    """Controller time (s since t0) of the cycle containing wall time `now`."""
    return math.floor(max(0.0, now - t0) / CYCLE_S) * CYCLE_S


@dataclass(frozen=True)
class PacedMotion:
    """plan: the simulation's motion; t_start: wall time it started (same clock as `now`);
    wall_per_sim: wall seconds per simulated second (0 = instantaneous); t0: the wall time
    of controller time 0 (cycle grid); probe_line: the probe's digital input."""

    plan: MotionPlan
    t_start: float
    wall_per_sim: float
    t0: float
    probe_line: int

    @property
    def wall_s(self) -> float:
        """Wall time of the whole motion if nothing stops it (s)."""
        return self.plan.duration_s * self.wall_per_sim

    def s_at(self, now: float) -> float:
        """Path parameter shown at wall time `now` (the start of its controller cycle)."""
        plan = self.plan
        if plan.path_duration_s <= 0.0 or self.wall_per_sim <= 0.0:
            return plan.s_end
        t_cycle = self.t0 + cycle_start(now, self.t0)
        sim_elapsed = max(0.0, t_cycle - self.t_start) / self.wall_per_sim
        return min(plan.s_end, sim_elapsed / plan.path_duration_s)

    def fraction_at(self, now: float) -> float:
        """The fraction of the motion (for `finish_move`) reached at `now`."""
        if self.plan.s_end <= 0.0:
            return 1.0
        return min(1.0, self.s_at(now) / self.plan.s_end)

    def finished(self, now: float) -> bool:
        """True once the motion reached its end."""
        return self.s_at(now) >= self.plan.s_end

    def q_at(self, now: float) -> np.ndarray:
        """(n,) reported joint angles of the cycle at `now`."""
        plan = self.plan
        return plan.q_start + self.s_at(now) * (plan.q_target - plan.q_start)

    def qd_at(self, now: float) -> np.ndarray:
        """(n,) joint speeds (rad/s of controller time) at `now`; zeros at the end."""
        plan = self.plan
        if self.finished(now) or self.wall_per_sim <= 0.0 or plan.path_duration_s <= 0.0:
            return np.zeros_like(plan.q_start)
        return (plan.q_target - plan.q_start) / (plan.path_duration_s * self.wall_per_sim)

    def probe_level(self, now: float, level_at_start: bool) -> bool:
        """The probe input's level at the cycle of `now`: edges along the path (a watched
        plan's contact rises at its latch point, after the probe's trigger latency)."""
        s = self.s_at(now)
        level = level_at_start
        for edge in self.plan.edges:
            if edge.s <= s:
                level = edge.value
        contact = self.plan.contact
        if contact is not None and s >= contact.s_latch:
            level = True
        return level
