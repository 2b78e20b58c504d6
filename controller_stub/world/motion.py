"""Motions of the simulated robot as values: plans and results (`joint_motion.py` moves).

A motion is planned (`begin_move`: checks, counters, faults and the IO edges along the path,
nothing moves yet) and then executed to its end or part-way (`finish_move`), so the server can
pace it in wall time and an abort stops the robot where it was. The path is a straight line in
reported joint space, q(s) = q_start + s * (q_target - q_start), s in [0, 1]. Angles are
radians (reported frame), times seconds of the simulated clock. Guarded moves (the probe) are
planned in `guarded.py`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
