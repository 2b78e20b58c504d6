"""The humanoid's dual_loop poses, pure numerics: arm poses around
:data:`~hostpc.kinematics.humanoid.HUMANOID_HOME` whose target is in front of the robot,
each with head angles that aim the camera near the target (nominal model), alternating left
and right (:func:`plan_poses`, the synthesis of test datasets); poses that move BOTH arms
with the head aimed between their targets, so one settle and one capture measure both
(:func:`plan_paired_poses`, the acquisition method's candidates); and the nominal frames of
the cell (:func:`nominal_frames`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.dataset import FramePose
from hostpc.kinds.dual_loop.model import humanoid_frames
from hostpc.kinematics.humanoid import HUMANOID_HOME, get_tree
from hostpc.kinematics.tree import KinematicTree
from hostpc.planning.design import sine_swings

__all__ = ["PlannedPoses", "head_look_at", "nominal_frames", "plan_paired_poses", "plan_poses"]

ARM_SPREAD = np.array([0.35, 0.35, 0.5, 0.35, 0.6, 0.5, 0.9])
"""Half-width (rad) of the uniform arm-joint spread around the home pose."""
HEAD_JITTER = 0.12
"""Half-width (rad) of the random pan/tilt offset from aiming exactly at the target."""


@dataclass(frozen=True)
class PlannedPoses:
    """Poses to visit: ``chain`` (N,) "left"/"right", ``q_head`` (N, 2) rad, ``q_arm``
    (N, 7) rad (the observed arm's angles)."""

    chain: np.ndarray
    q_head: np.ndarray
    q_arm: np.ndarray

    @property
    def n(self) -> int:
        return int(self.chain.shape[0])

    def subset(self, rows: np.ndarray) -> PlannedPoses:
        return PlannedPoses(self.chain[rows], self.q_head[rows], self.q_arm[rows])


def nominal_frames(name: str = "humanoid_upper") -> dict[str, FramePose | np.ndarray]:
    """The nominal dual_loop frames of a built-in tree, as Dataset frames."""
    if name != "humanoid_upper":
        raise ValueError(f"no nominal frames for {name!r}")
    return humanoid_frames()


def _camera_points(tree: KinematicTree, q: np.ndarray, side: str) -> np.ndarray:
    """(N, 3) nominal target of arm ``side`` in the nominal camera frame, q combined;
    ``side`` ``"both"``: the midpoint of the two arms' targets."""
    if side == "both":
        both: np.ndarray = 0.5 * (_camera_points(tree, q, "left")
                                  + _camera_points(tree, q, "right"))
        return both
    frames = tree.root_transforms(q)
    T_hb_cam = frames["head"][1] @ tree.frames["camera"]
    p = frames[side][1][:, :3, :3] @ tree.frames[f"{side}_target"] + frames[side][1][:, :3, 3]
    R = T_hb_cam[:, :3, :3]
    points: np.ndarray = np.einsum("nji,nj->ni", R, p - T_hb_cam[:, :3, 3])
    return points


def head_look_at(tree: KinematicTree, q: np.ndarray, side: str, iterations: int = 20
                 ) -> np.ndarray:
    """Head angles (N, 2) that put the nominal target of arm ``side`` on the optical axis.

    Args:
        tree: the tree (nominal model).
        q: combined joint angles (N, n); the head columns are the starting guess.
        side: ``"left"``, ``"right"`` or ``"both"`` (the midpoint of the two targets).

    Newton iterations on the normalised image coordinates ``(x/z, y/z)``.
    """
    q = np.array(q, dtype=float)
    head = tree.joint_slice("head")
    for _ in range(iterations):
        p = _camera_points(tree, q, side)
        f = p[:, :2] / p[:, 2:3]
        J = np.empty((q.shape[0], 2, 2))
        for k in range(2):
            dq = np.zeros_like(q)
            dq[:, head.start + k] = 1e-6
            fp = _camera_points(tree, q + dq, side)
            fm = _camera_points(tree, q - dq, side)
            J[:, :, k] = (fp[:, :2] / fp[:, 2:3] - fm[:, :2] / fm[:, 2:3]) / 2e-6
        step = np.linalg.solve(J, -f[:, :, None])[:, :, 0]
        q[:, head] += np.clip(step, -0.3, 0.3)
        if np.max(np.abs(f)) < 1e-10:
            break
    return q[:, head]


def plan_poses(n_per_arm: int, rng: np.random.Generator, *, tree: KinematicTree | None = None,
               depth: tuple[float, float] = (0.3, 0.75), max_tan: float = 0.3
               ) -> PlannedPoses:
    """``2 n_per_arm`` poses alternating left and right (nominal model).

    Each arm pose is drawn uniformly within :data:`ARM_SPREAD` of the home pose; the head
    aims the camera at the target, then moves by up to :data:`HEAD_JITTER`. Kept when all
    joints are inside their limits, the target's depth is in ``depth`` (m) and its
    normalised image coordinates are within ``max_tan``.
    """
    tree = get_tree("humanoid_upper") if tree is None else tree
    home = np.concatenate([HUMANOID_HOME[b] for b in ("head", "left", "right")])
    q_min = np.concatenate([b.chain.q_min for b in tree.branches])
    q_max = np.concatenate([b.chain.q_max for b in tree.branches])
    head = tree.joint_slice("head")
    accepted: dict[str, list[np.ndarray]] = {"left": [], "right": []}
    for side in ("left", "right"):
        span = tree.joint_slice(side)
        for _ in range(100):
            if sum(len(a) for a in accepted[side]) >= n_per_arm:
                break
            m = 2 * n_per_arm
            q = np.broadcast_to(home, (m, tree.n)).copy()
            q[:, span] += rng.uniform(-1.0, 1.0, (m, span.stop - span.start)) * ARM_SPREAD
            q[:, head] = head_look_at(tree, q, side)
            q[:, head] += rng.uniform(-HEAD_JITTER, HEAD_JITTER, (m, 2))
            p = _camera_points(tree, q, side)
            ok = np.all((q >= q_min) & (q <= q_max), axis=1)
            ok &= (p[:, 2] > depth[0]) & (p[:, 2] < depth[1])
            ok &= np.all(np.abs(p[:, :2] / p[:, 2:3]) < max_tan, axis=1)
            accepted[side].append(q[ok])
        found = np.concatenate(accepted[side])[:n_per_arm]
        if found.shape[0] < n_per_arm:
            raise ValueError(f"only {found.shape[0]} of {n_per_arm} {side} poses found")
        accepted[side] = [found]
    left, right = accepted["left"][0], accepted["right"][0]
    chain = np.array(["left", "right"] * n_per_arm)
    q_head = np.empty((2 * n_per_arm, 2))
    q_arm = np.empty((2 * n_per_arm, 7))
    q_head[0::2], q_head[1::2] = left[:, head], right[:, head]
    q_arm[0::2] = left[:, tree.joint_slice("left")]
    q_arm[1::2] = right[:, tree.joint_slice("right")]
    return PlannedPoses(chain=chain, q_head=q_head, q_arm=q_arm)


PAIRED_FREQUENCIES = {"left": (3.0, 2.5, 2.0, 4.0, 1.5, 3.5, 1.0),
                      "right": (2.7, 2.2, 1.7, 3.7, 1.2, 3.2, 0.7)}
"""Swings per cycle of each arm joint along the paired poses' path: all different (so the
joints' angles are not correlated over the path), the widest (joints 5 and 7 of
:data:`ARM_SPREAD`) among the slowest."""
PAIRED_CYCLES = 2.0
"""Cycles of the path (see :func:`plan_paired_poses`)."""


def plan_paired_poses(n: int, rng: np.random.Generator, *, tree: KinematicTree | None = None,
                      spread: np.ndarray = ARM_SPREAD, cycles: float = PAIRED_CYCLES,
                      depth: tuple[float, float] = (0.3, 0.75), max_tan: float = 0.42
                      ) -> np.ndarray:
    """(N, tree.n) combined poses, N <= n, that measure both arms at once (nominal model),
    in order along one smooth path.

    Each arm joint j swings about the home pose by ``spread_j`` as a sine of ``cycles f_j``
    periods over the path (``f_j`` :data:`PAIRED_FREQUENCIES`, random phases:
    :func:`hostpc.planning.design.sine_swings`), the head aimed at the midpoint of the two
    targets. Neighbours on the path differ by little in every joint, so the planner's
    selection from these poses makes a tour of short moves (between two random poses some
    joint always swings far), while over the path every joint reaches both ends of its
    swing in ever different combinations with the others. Kept when all joints are inside
    their limits and each target's depth is in ``depth`` (m) and its normalised image
    coordinates within ``max_tan`` (the acquisition checks both images with their margin).
    """
    tree = get_tree("humanoid_upper") if tree is None else tree
    home = np.concatenate([HUMANOID_HOME[b] for b in ("head", "left", "right")])
    q_min = np.concatenate([b.chain.q_min for b in tree.branches])
    q_max = np.concatenate([b.chain.q_max for b in tree.branches])
    q = np.broadcast_to(home, (n, tree.n)).copy()
    for side in ("left", "right"):
        q[:, tree.joint_slice(side)] += spread * sine_swings(
            n, cycles * np.asarray(PAIRED_FREQUENCIES[side]), rng)
    q[:, tree.joint_slice("head")] = head_look_at(tree, q, "both")
    ok = np.all((q >= q_min) & (q <= q_max), axis=1)
    for side in ("left", "right"):
        p = _camera_points(tree, q, side)
        ok &= (p[:, 2] > depth[0]) & (p[:, 2] < depth[1])
        ok &= np.all(np.abs(p[:, :2] / p[:, 2:3]) < max_tan, axis=1)
    return q[ok]
