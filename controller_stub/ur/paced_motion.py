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

A stopj / stopl mid-move (`stopped`) decelerates the joints as a real UR does: from the cycle
it arrives at, the path slows at the command's joint deceleration (the leading joint, the one
moving furthest, at that many rad/s^2; the others in proportion, so the arm stays on its
path), never ahead of the plan's own profile, so a stop late in the plan's own ramp ends where
the plan does:

    s(t) = min(s_plan(t), s0 + v0 (t - t0) - D (t - t0)^2 / 2)     t0 <= t <= t0 + v0 / D

with s0, v0 the path parameter and its speed at the stop, D = deceleration / max_i |dq_i|.
The arm is at rest at s_final = min(s0 + v0^2 / 2D, s_end).

Pure arithmetic on the plan: no I/O, no clock of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from controller_stub.world.motion import MotionPlan

CYCLE_S = 0.002
"""The controller cycle (s): 500 Hz like a UR e-Series."""


@dataclass(frozen=True)
class _Stop:
    """A stopj / stopl: at simulated time `t0` (s from the start) the path was at `s0` moving
    at `v0` (1/s); it decelerates at `deceleration` (1/s^2) to rest at `s_final` at time
    `t_end`."""

    t0: float
    s0: float
    v0: float
    deceleration: float
    s_final: float
    t_end: float

    def s_at(self, t: float) -> float:
        """The ramp's own path parameter at time t (>= t0)."""
        tau = min(max(t - self.t0, 0.0), self.v0 / self.deceleration)
        return self.s0 + self.v0 * tau - 0.5 * self.deceleration * tau * tau

    def rate_at(self, t: float) -> float:
        """The ramp's own ds/dt at time t (>= t0)."""
        return max(0.0, self.v0 - self.deceleration * max(t - self.t0, 0.0))


@dataclass(frozen=True)
class PacedMotion:
    """plan: the simulation's motion; start_cycle: the controller cycle it started at;
    wall_per_sim: controller seconds per simulated second (0 = instantaneous); probe_line:
    the probe's digital input; stop: the decelerating stop commanded mid-move (`stopped`),
    or None."""

    plan: MotionPlan
    start_cycle: int
    wall_per_sim: float
    probe_line: int
    stop: _Stop | None = None

    def sim_time_at(self, cycle: int) -> float:
        """Simulated time (s) from the start to `cycle`, up to the motion's end (its plan's
        duration, or the end of a stop's ramp)."""
        end = self.plan.duration_s if self.stop is None else self.stop.t_end
        if end <= 0.0 or self.wall_per_sim <= 0.0:
            return end
        return min(end, max(0, cycle - self.start_cycle) * CYCLE_S / self.wall_per_sim)

    def s_at(self, cycle: int) -> float:
        """Path parameter at controller cycle `cycle`."""
        t = self.sim_time_at(cycle)
        s = self._plan_s(t)
        if self.stop is not None and t >= self.stop.t_end:
            return self.stop.s_final  # exactly: a ramp that reaches the target ends there
        if self.stop is not None and t > self.stop.t0:
            s = min(s, self.stop.s_at(t))
        return s

    def _plan_s(self, t: float) -> float:
        """The plan's own path parameter at simulated time t (s from the start)."""
        duration = self.plan.duration_s
        return self.plan.s_at(1.0 if duration <= 0.0 else t / duration)

    def fraction_at(self, cycle: int) -> float:
        """The fraction of the plan (for `finish_move`) whose end is where the motion is at
        `cycle`: its time fraction, or for a stopped motion the fraction at which the plan
        itself is where the ramp is (the ramp takes longer to get there: `sim_time_at`)."""
        duration = self.plan.duration_s
        if duration <= 0.0 or self.wall_per_sim <= 0.0:
            return 1.0
        if self.stop is None:
            return min(1.0, self.sim_time_at(cycle) / duration)
        s = self.s_at(cycle)
        if s >= self.plan.s_end:
            return 1.0
        return min(1.0, float(self.plan.profile.time_at(s)) / duration)

    def finished(self, cycle: int) -> bool:
        """True once the motion reached its end (the plan's, or a stop's)."""
        end = self.plan.duration_s if self.stop is None else self.stop.t_end
        return self.sim_time_at(cycle) >= end

    def stopped(self, cycle: int, deceleration: float) -> PacedMotion:
        """This motion with a stopj / stopl of `deceleration` (rad/s^2 of the leading joint,
        > 0) arriving at `cycle` (the module docstring); a motion already stopping keeps its
        first stop."""
        if self.stop is not None:
            return self
        plan = self.plan
        t0 = self.sim_time_at(cycle)
        s0 = self._plan_s(t0)
        v0 = plan.profile.rate_at(t0) if s0 < plan.s_end else 0.0
        lead = float(np.max(np.abs(plan.q_target - plan.q_start)))
        if v0 <= 0.0 or lead <= 0.0:  # at rest already
            return replace(self, stop=_Stop(t0, s0, 0.0, 1.0, s0, t0))
        path_deceleration = deceleration / lead
        s_final = min(s0 + 0.5 * v0 * v0 / path_deceleration, plan.s_end)
        # the ramp reaches s_final at tau_ramp, the plan at its own time; rest at the later
        tau_ramp = (v0 - math.sqrt(max(v0 * v0 - 2.0 * path_deceleration * (s_final - s0),
                                       0.0))) / path_deceleration
        t_plan = (plan.duration_s if s_final >= plan.s_end
                  else float(plan.profile.time_at(s_final)))
        t_end = max(t0 + tau_ramp, t_plan)
        return replace(self, stop=_Stop(t0, s0, v0, path_deceleration, s_final, t_end))

    def q_at(self, cycle: int) -> np.ndarray:
        """(n,) reported joint angles at `cycle`."""
        plan = self.plan
        return np.asarray(plan.q_start + self.s_at(cycle) * (plan.q_target - plan.q_start))

    def qd_at(self, cycle: int) -> np.ndarray:
        """(n,) joint speeds (rad per controller second) at `cycle`; zeros at the end."""
        plan = self.plan
        if self.finished(cycle):
            return np.zeros_like(plan.q_start)
        t = self.sim_time_at(cycle)
        rate = plan.profile.rate_at(t)
        stop = self.stop
        if stop is not None and t > stop.t0 and stop.s_at(t) < self._plan_s(t):
            rate = stop.rate_at(t)
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
