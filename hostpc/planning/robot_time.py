"""The plan's robot time, predicted before anything moves, and its physical floor.

Pure numerics. A plan keeps the robot busy for its moves, the settling before each
measurement and the captures at each pose (docs/simulator.md charges exactly these):

- motion: each joint move ramps every joint up to speed x v_i (v_i the joint's top speed,
  rad/s; speed the run's fraction of it, `--speed`) at a_i (its acceleration, rad/s^2) and
  down to rest, all joints finishing together (`hostpc.planning.tour.move_times`, the
  trapezoidal law the simulator moves by), from the robot's pose along the fit poses, then
  along the verification poses;
- settle: `settle_s` before a measurement that follows motion (a capture, a tracker or
  sensor reading, the start of a guarded approach), where a real arm waits for its
  vibration to die out: once per measured pose, none after a move that another move
  follows (a via point, a retract, a move to a hover: a move ends at rest), none before a
  second measurement at the same pose;
- capture: `capture_s` per measurement (`Waypoints`: a method's moves per pose).

The controller's limits come from its state when it reports them (`RobotState.extra`:
`max_joint_speed` (n,) rad/s, `max_joint_acceleration` (n,) rad/s^2, `settle_s`,
`capture_s`), else a UR's: 180 deg/s and 1.4 rad/s^2 (UR's default movej acceleration) on
every joint, 0.3 s settling, 0.1 s a capture (the simulator's defaults but its
acceleration, 4.0 rad/s^2, which it reports). The floor is what no
tour can save, by the same rule per measurement type as the prediction: the fewest poses
that reach the target sigma and the verification poses (the planner picks them:
hostpc.calibrate.run_plan) each settle once and take their captures, no motion but the
moves that are the measurement itself (`path_floor`: a plain pose settles and captures
once; a sphere_probe contact settles at its start and its guarded approach runs, from the
start pose to the contact at the contact's speed, `measuring_motion`; no capture: the
contact is latched in motion).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hostpc.planning.tour import JointRates, move_times

DEFAULT_JOINT_SPEED = math.pi
"""rad/s of a joint at speed fraction 1 when the controller does not report it (a UR's)."""
DEFAULT_JOINT_ACCELERATION = 1.4
"""rad/s^2 of a joint when the controller does not report it: a UR's default movej
acceleration, which the UR driver commands (hostpc.robots.ur_link.JOINT_ACCELERATION is
this)."""
DEFAULT_SETTLE_S = 0.3
DEFAULT_CAPTURE_S = 0.1


@dataclass(frozen=True)
class TimeLimits:
    """joint_speed: (n,) rad/s at speed fraction 1; joint_acceleration: (n,) rad/s^2;
    settle_s before a measurement after motion; capture_s per capture."""

    joint_speed: np.ndarray
    joint_acceleration: np.ndarray
    settle_s: float = DEFAULT_SETTLE_S
    capture_s: float = DEFAULT_CAPTURE_S

    @classmethod
    def from_extra(cls, extra: Mapping[str, Any], n_joints: int) -> TimeLimits:
        """The controller's reported limits (`RobotState.extra`), defaults for the rest."""
        def per_joint(key: str, default: float) -> np.ndarray:
            value = extra.get(key)
            return np.broadcast_to(np.asarray(default if value is None else value, float),
                                   (n_joints,)).copy()

        return cls(per_joint("max_joint_speed", DEFAULT_JOINT_SPEED),
                   per_joint("max_joint_acceleration", DEFAULT_JOINT_ACCELERATION),
                   float(extra.get("settle_s", DEFAULT_SETTLE_S)),
                   float(extra.get("capture_s", DEFAULT_CAPTURE_S)))

    def rates(self, speed: float | np.ndarray) -> JointRates:
        """The joints' limits of moves at speed fraction(s) `speed` (scalar, or (M,): one
        per move, giving (M, n) speeds)."""
        fraction = np.maximum(np.asarray(speed, float), 1e-9)
        return JointRates(self.joint_speed * fraction[..., None], self.joint_acceleration)


@dataclass(frozen=True)
class Waypoints:
    """The robot's moves that measure some planned poses, in order: q (M, n) the joint
    targets; speed (M,) the speed fraction of the move into each (NaN: the run's --speed);
    settle (M,) bool: a measurement starts at that waypoint (a capture there, a guarded
    approach from it), so the robot settles there if it moved since it last settled;
    measuring (M,) bool: the move into that waypoint is itself the measurement (a guarded
    approach, which latches in motion); captures: measurements taken (each `capture_s`).
    A plain pose is one waypoint at the run's speed, measured there (settled, one
    capture); sphere_probe's free moves to a contact's start measure nothing, the start
    settles, the approach measures in motion, and its retract measures nothing."""

    q: np.ndarray
    speed: np.ndarray
    settle: np.ndarray
    measuring: np.ndarray
    captures: int

    @classmethod
    def plain(cls, q: np.ndarray) -> Waypoints:
        """Each pose of q (N, n) visited at the run's speed, settled and captured once."""
        q = np.asarray(q, float)
        n = q.shape[0]
        return cls(q, np.full(n, np.nan), np.ones(n, bool), np.zeros(n, bool), n)

    def then(self, other: Waypoints) -> Waypoints:
        """These waypoints, then `other`'s."""
        n = max(np.shape(self.q)[-1], np.shape(other.q)[-1])
        return Waypoints(np.vstack([self.q.reshape(-1, n), other.q.reshape(-1, n)]),
                         np.concatenate([self.speed, other.speed]),
                         np.concatenate([self.settle, other.settle]),
                         np.concatenate([self.measuring, other.measuring]),
                         self.captures + other.captures)


@runtime_checkable
class RobotPath(Protocol):
    """A method whose measurement of a pose is more than one plain move (sphere_probe: hover,
    start, guarded approach, back)."""

    def robot_path(self, q: np.ndarray) -> Waypoints:
        """The waypoints that measure the poses q (N, n), in order."""


def _move_times(q_start: np.ndarray, path: Waypoints, speed: float, limits: TimeLimits
                ) -> np.ndarray:
    """(M,) s: the move into each waypoint of `path` from q_start (n,), each at its own
    speed fraction (NaN: the run's `speed`)."""
    q = np.vstack([np.asarray(q_start, float)[None, :], path.q])
    fraction = np.where(np.isnan(path.speed), speed, path.speed)
    return move_times(q[:-1], q[1:], limits.rates(fraction))


def settles(moves: np.ndarray, settle: np.ndarray) -> int:
    """How many times a robot settles along a path whose moves take `moves` (M,) s: at each
    measuring waypoint (`settle` (M,) bool) it reached by motion since it last settled
    (the simulator's `settle_for_measurement`; the robot starts at rest, settled)."""
    count, moved = 0, False
    for moving, measures in zip(np.asarray(moves) > 0.0, settle, strict=True):
        moved = moved or bool(moving)
        if measures and moved:
            count, moved = count + 1, False
    return count


def waypoints_time(q_start: np.ndarray, path: Waypoints, speed: float, limits: TimeLimits
                   ) -> tuple[float, float, float]:
    """(motion, settle, capture) in s of `path` from q_start (n,); speed: the run's."""
    moves = _move_times(q_start, path, speed, limits)
    settle = limits.settle_s * settles(moves, path.settle)
    return float(np.sum(moves)), settle, limits.capture_s * path.captures


def predicted_robot_time(q_start: np.ndarray, fit: Waypoints, verify: Waypoints,
                         speed: float, limits: TimeLimits, floor: float) -> dict[str, float]:
    """{"motion", "settle", "capture", "total", "floor"} in s of the fit's waypoints then
    the verification's from q_start (n,) at the run's speed fraction `speed`; `floor` (s):
    the planner's (`robot_time_floor` or `path_floor` of the fewest poses that reach the
    target sigma and the verification poses)."""
    motion, settle, capture = waypoints_time(np.asarray(q_start, float), fit.then(verify),
                                             speed, limits)
    return {"motion": motion, "settle": settle, "capture": capture,
            "total": motion + settle + capture,
            "floor": floor}


def measuring_motion(path: Waypoints, speed: float, limits: TimeLimits) -> float:
    """Time (s) of the moves of `path` that measure in motion (`Waypoints.measuring`:
    sphere_probe's guarded approach from the start pose to the contact, at the contact's
    speed): the measurement itself, which no tour saves."""
    if path.q.shape[0] < 2:
        return 0.0
    moves = _move_times(path.q[0], path, speed, limits)  # the first: none (from itself)
    return float(np.sum(moves[path.measuring]))


def robot_time_floor(n_poses: int, limits: TimeLimits) -> float:
    """The physical floor (s) of a plan of n_poses plain poses (`Waypoints.plain`, as
    `path_floor`): settle + capture each (every measured pose settles once, as the
    simulator charges), no motion."""
    return n_poses * (limits.settle_s + limits.capture_s)


def path_floor(path: Waypoints, speed: float, limits: TimeLimits) -> float:
    """The physical floor (s) of the measurements of `path` with no travel between them,
    charged as the prediction charges them: each measurement settles once (a `settle`
    waypoint), takes its captures, and the moves that are themselves the measurement run
    (`measuring_motion`; a sphere_probe contact: its guarded approach, no capture)."""
    return (limits.settle_s * int(np.count_nonzero(path.settle))
            + limits.capture_s * path.captures + measuring_motion(path, speed, limits))


def largest_joint_moves(q_start: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n,) rad: each joint's largest move between consecutive poses of q (N, n) visited
    from q_start (n,) (a joint that unwinds shows here)."""
    path = np.vstack([np.asarray(q_start, float)[None, :], np.asarray(q, float)])
    if path.shape[0] < 2:
        return np.zeros(path.shape[1])
    return np.asarray(np.max(np.abs(np.diff(path, axis=0)), axis=0))
