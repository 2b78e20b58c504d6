"""Motions of the simulated robot as values: plans and results (`joint_motion.py` moves).

A motion is planned (`begin_move`: checks, counters, faults and the IO edges along the path,
nothing moves yet) and then executed to its end or part-way (`finish_move`), so the server can
pace it in wall time and an abort stops the robot where it was. The path is a straight line in
reported joint space, q(s) = q_start + s * (q_target - q_start), s in [0, 1], and s follows
the move's trapezoidal velocity profile in time (`PathProfile`). Angles are radians
(reported frame), times seconds of the simulated clock. Guarded moves (the probe) are
planned in `guarded.py`.

The motion law (a real arm ramps its joints; the host's prediction,
`hostpc.planning.tour.move_times`, has its own copy: the simulator imports nothing of the
host): every joint i moves |dq_i| along the straight line, at most v_i (its top speed x the
move's speed fraction) and a_i (its acceleration), all starting and ending together. The
path parameter s has speed V = min_i v_i / |dq_i| and acceleration A = min_i a_i / |dq_i|
(so no joint exceeds its own), and moves 1 in the shortest such time: accelerate at A,
cruise at V, decelerate at A; a path too short to reach V (1 <= V^2 / A) is triangular:

    duration = 2 sqrt(1 / A)        if 1 <= V^2 / A
               1 / V + V / A        otherwise

which is d / v + v / a (or 2 sqrt(d / a)) of the slowest joint when the joints share v and a.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PathProfile:
    """s(t) of one move along its path: accelerate at `acceleration` (1/s^2), cruise at
    `cruise` (1/s), decelerate to rest at s = 1 after `duration_s`; `ramp_s` each ramp's
    time (the cruise lasts duration_s - 2 ramp_s, 0 for a triangular profile). A move that
    does not move (or is instantaneous: infinite limits) has duration 0."""

    acceleration: float
    cruise: float
    ramp_s: float
    duration_s: float

    @classmethod
    def of_move(cls, dq: np.ndarray, speed: np.ndarray, acceleration: np.ndarray
                ) -> PathProfile:
        """The profile of a move of dq (n,) rad with joint speeds (n,) rad/s and joint
        accelerations (n,) rad/s^2 (the module docstring's law)."""
        d = np.abs(np.asarray(dq, float))
        t_speed = float(np.max(d / np.asarray(speed, float)))  # 1 / V
        t_accel = float(np.max(d / np.asarray(acceleration, float)))  # 1 / A (s^2)
        if t_speed <= 0.0 and t_accel <= 0.0:
            return cls(math.inf, math.inf, 0.0, 0.0)
        if t_accel <= 0.0:  # no ramp: at speed from the first instant
            return cls(math.inf, 1.0 / t_speed, 0.0, t_speed)
        if t_speed * t_speed <= t_accel:  # triangular: peak speed below V
            ramp = math.sqrt(t_accel)
            return cls(1.0 / t_accel, ramp / t_accel, ramp, 2.0 * ramp)
        return cls(1.0 / t_accel, 1.0 / t_speed, t_accel / t_speed, t_speed + t_accel / t_speed)

    def s_at(self, t: np.ndarray | float) -> np.ndarray:
        """Path parameter at time(s) t (s from the start; clipped to [0, duration_s])."""
        T, r = self.duration_s, self.ramp_s
        t = np.clip(np.asarray(t, float), 0.0, T)
        if T <= 0.0:
            return np.ones_like(t)
        if r <= 0.0:
            return np.asarray(t / T)
        a, v = self.acceleration, self.cruise
        return np.where(t < r, 0.5 * a * t * t,
                        np.where(t > T - r, 1.0 - 0.5 * a * (T - t) ** 2,
                                 0.5 * a * r * r + v * (t - r)))

    def rate_at(self, t: float) -> float:
        """ds/dt (1/s) at time t."""
        T, r = self.duration_s, self.ramp_s
        if T <= 0.0 or not 0.0 <= t <= T:
            return 0.0
        if r <= 0.0:
            return 1.0 / T
        return float(min(self.cruise, self.acceleration * t, self.acceleration * (T - t)))

    def time_at(self, s: np.ndarray | float) -> np.ndarray:
        """Time(s) (s from the start) at which the path reaches s (clipped to [0, 1])."""
        T, r = self.duration_s, self.ramp_s
        s = np.clip(np.asarray(s, float), 0.0, 1.0)
        if T <= 0.0:
            return np.zeros_like(s)
        if r <= 0.0:
            return np.asarray(s * T)
        a, v = self.acceleration, self.cruise
        s_ramp = 0.5 * a * r * r
        return np.where(s < s_ramp, np.sqrt(2.0 * s / a),
                        np.where(s > 1.0 - s_ramp, T - np.sqrt(2.0 * np.maximum(1.0 - s, 0.0) / a),
                                 r + (s - s_ramp) / v))


@dataclass(frozen=True)
class MoveResult:
    """Outcome of a joint move.

    completed: True if the target was reached; False with `reason` (code) if aborted.
    q: (n,) reported joint angles where the robot stopped.
    duration_s: simulated motion time (the server sleeps duration_s * time_scale); the
    clock advanced by it. No settling is charged after a move: the next measurement
    settles (`ControllerState.settle_for_measurement`).
    """

    completed: bool
    q: np.ndarray
    duration_s: float
    reason: str | None = None


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

    The path is q(s) = q_start + s * (q_target - q_start), s in [0, 1], reported rad, s(t)
    the move's `profile` (path_duration_s to s = 1). Unless stopped early the motion ends
    at s = s_end (1, or the stop after a guarded contact) after duration_s; a `fraction` of
    the motion is that fraction of duration_s, and s the profile's there. io_line: None for
    move_joints, the guarded line otherwise. edges: input changes along the path in order;
    contact: the guarded contact, or None.
    """

    q_start: np.ndarray
    q_target: np.ndarray
    t_start: float
    profile: PathProfile
    s_end: float
    io_line: int | None
    edges: tuple[PathEdge, ...]
    contact: GuardedContact | None = None

    @property
    def path_duration_s(self) -> float:
        """Simulated time of the whole path, to s = 1 (s)."""
        return self.profile.duration_s

    @property
    def duration_s(self) -> float:
        """Simulated time of the motion if it is not stopped early (s)."""
        if self.s_end >= 1.0:
            return self.profile.duration_s
        return float(self.profile.time_at(self.s_end))

    def s_at(self, fraction: float) -> float:
        """Path parameter after `fraction` (clipped to [0, 1]) of the motion's time."""
        fraction = min(max(float(fraction), 0.0), 1.0)
        if fraction >= 1.0:
            return self.s_end
        return min(self.s_end, float(self.profile.s_at(fraction * self.duration_s)))

    def q_at(self, fraction: float) -> np.ndarray:
        """(n,) reported angles after `fraction` (clipped to [0, 1]) of the motion."""
        return self.q_start + self.s_at(fraction) * (self.q_target - self.q_start)
