"""The dual_loop measurement model: a pan-tilt head camera observes a target on each arm.

Frames (docs/conventions.md; the tree is ``hostpc.kinematics.humanoid``):

- ``head base`` (hb): the root, the base of the head chain (pan-tilt unit);
- ``head end`` (he): the head chain's flange; ``camera`` is ``T_he_camera`` (the left
  optical frame of the stereo camera: x right, y down, z along the optical axis);
- ``left_base`` / ``right_base``: ``T_hb_armbase``, each arm's DH base in the head base;
- ``left_target`` / ``right_target``: the target point in that arm's flange frame (m).

For a sample that observed arm ``s`` (``samples.chain``) the prediction is the target point
in the camera frame, m, shape ``(3,)``::

    p_hb = T_hb_sbase @ T_sbase_sflange(q_arm + dq_arm) @ p_target
    y    = (T_hb_he(q_head + dq_head) @ T_he_camera)^-1 @ p_hb

then the sensor effects (``depth_scale``) in order. Both loops share the head and the camera;
all unknowns of both loops are one parameter vector, and the fit's whitening by each
triangulated point's covariance makes its objective the Mahalanobis distance.

The combined joint vector is ``head (2), left (7), right (7)`` with labels ``head.q1`` ..
``right.q7`` (so the offsets are ``joint_offsets.left.q3``, ...). ``ModelContext.q_cmd`` holds
the observed arm's angles in its columns and 0 in the other arm's (never used: the other
arm's columns have zero derivative). ``ModelContext.chain`` is the tree's stacked
bookkeeping chain (``KinematicTree.stacked_chain``).

Non-identifiable combinations with this measurement (the fit's gauge holds the first of each
at nominal and lets the frames absorb it): the pan offset ``head.q1`` (a rotation of both arm
bases about the pan axis), the tilt offset ``head.q2`` (a rotation of the camera frame about
the tilt axis), each arm's ``q1`` (a rotation of its base about its first axis) and each
arm's ``q7`` (a rotation of its target point about the last axis).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.errors import InputError
from hostpc.kinds.dual_loop.file_face import DualLoopFile
from hostpc.kinds.dual_loop.frames import DUAL_LOOP_FRAME_EFFECTS
from hostpc.kinds.stereo_target.shared_error import rig_shared_error
from hostpc.kinematics import Chain, forward, point_jacobian, screws
from hostpc.kinematics.humanoid import HUMANOID_FRAMES, HUMANOID_HOME, get_tree
from hostpc.kinematics.rotations import pose_to_transform, skew
from hostpc.kinematics.tree import KinematicTree, tree_gravity_torque
from hostpc.model.context import group_variable, sample_variables
from hostpc.model.effect import ModelContext
from hostpc.model.frame_math import inverse_point_derivatives, perturbed_pose
from hostpc.model.layout import Problem
from hostpc.model.measurements.base import POINT, POSE, MeasurementModel
from hostpc.model.measurements.terms import apply_sensor_effects, kinematic_deltas

__all__ = [
    "ARMS",
    "DualLoop",
    "DUAL_LOOP_FRAMES",
    "check_dual_loop",
    "combined_q",
    "dual_loop_context",
    "predict_dual_loop",
    "problem_tree",
    "tree_of",
]

DUAL_LOOP_FRAMES = ("camera", "left_base", "right_base", "left_target", "right_target")
ARMS = ("left", "right")


def tree_of(dataset: Dataset) -> KinematicTree:
    """The kinematic tree of a dual_loop dataset (built-in by name; InputError otherwise),
    built anew (about half a millisecond: a problem's build asks for it a few times; its
    prediction asks ``problem_tree``)."""
    name = dataset.robot.name
    if name is None:
        raise InputError("robot: dual_loop needs a built-in kinematic tree by name "
                         "(e.g. humanoid_upper)")
    return get_tree(name)


def problem_tree(problem: Problem) -> KinematicTree:
    """The problem's kinematic tree, built once for its dataset's robot and kept in
    ``problem.shared`` (every evaluation of the prediction asks for it)."""
    dataset = problem.dataset
    return problem.shared.value(dataset.robot, ("dual_loop_tree",), lambda: tree_of(dataset))


def check_dual_loop(dataset: Dataset, tree: KinematicTree) -> None:
    """Validate the samples against the tree: joint counts of the head and of each arm.

    Raises InputError naming the field and the first offending sample."""
    samples = dataset.samples
    if samples.q_head is None or samples.chain is None:
        raise InputError("samples: dual_loop samples need chain, q_head and q_arm")
    head = tree.branch("head").chain
    if samples.q_head.shape[1] != head.n:
        raise InputError(f"samples[0].q_head: {samples.q_head.shape[1]} angles, but the head "
                         f"of {tree.name!r} has {head.n} joints")
    for i, side in enumerate(samples.chain):
        if side not in ARMS:
            raise InputError(f"samples[{i}].chain: expected 'left' or 'right', got {side!r}")
        n_arm = tree.branch(str(side)).chain.n
        row = samples.q[i]
        given = int(np.count_nonzero(~np.isnan(row)))
        if given != n_arm or np.any(np.isnan(row[:n_arm])):
            raise InputError(f"samples[{i}].q_arm: {given} angles, but arm {side!r} of "
                             f"{tree.name!r} has {n_arm} joints")


def combined_q(dataset: Dataset, tree: KinematicTree) -> tuple[np.ndarray, np.ndarray]:
    """The combined joint vector of every sample and which columns were observed.

    Returns:
        ``q`` (rad), shape ``(N, n_tree)``: head angles, the observed arm's angles, 0 in the
        other arm's columns; ``observed``, shape ``(N, n_tree)`` bool.
    """
    samples = dataset.samples
    assert samples.q_head is not None and samples.chain is not None
    N = samples.n
    q = np.zeros((N, tree.n))
    observed = np.zeros((N, tree.n), dtype=bool)
    head = tree.joint_slice("head")
    q[:, head] = samples.q_head
    observed[:, head] = True
    for side in ARMS:
        rows = np.flatnonzero(samples.chain == side)
        span = tree.joint_slice(side)
        n_arm = span.stop - span.start
        q[np.ix_(rows, np.arange(span.start, span.stop))] = samples.q[rows, :n_arm]
        observed[rows, span] = True
    return q, observed


def dual_loop_context(dataset: Dataset, chain: Chain,
                      frame_parameters: Mapping[str, tuple[str, ...]] | None = None
                      ) -> ModelContext:
    """The ModelContext of a dual_loop dataset (see the module docstring).

    ``tau``: gravity torque of each chain with gravity along ``-z`` of the head base (the
    torso upright); ``approach``: the recorded signs in the observed arm's columns, 0
    elsewhere. Variables are named by chain: ``head.q1``, ``left.q3``, ``left.tau3``,
    ``left.approach3`` (NaN in samples of the other arm), plus ``t``, ``temperature``,
    ``depth``, ``extra.NAME`` and the group label ``chain`` (categorical: left / right).
    """
    tree = tree_of(dataset)
    samples = dataset.samples
    q_cmd, observed = combined_q(dataset, tree)
    try:
        tau = tree_gravity_torque(tree, q_cmd)
    except InputError:
        tau = np.full_like(q_cmd, np.nan)
    approach = np.zeros_like(q_cmd)
    recorded = np.nan_to_num(np.asarray(samples.approach, dtype=float), nan=0.0)
    assert samples.chain is not None
    for side in ARMS:
        rows = np.flatnonzero(samples.chain == side)
        span = tree.joint_slice(side)
        approach[np.ix_(rows, np.arange(span.start, span.stop))] = \
            recorded[rows, :span.stop - span.start]
    variables: dict[str, np.ndarray] = {}
    labels = tree.joint_labels
    for j, label in enumerate(labels):
        prefix, _, joint = label.rpartition(".")
        number = joint[1:]
        variables[label] = np.where(observed[:, j], q_cmd[:, j], np.nan)
        if np.all(np.isfinite(tau)):
            variables[f"{prefix}.tau{number}"] = np.where(observed[:, j], tau[:, j], np.nan)
        if prefix != "head" and np.any(np.isfinite(samples.approach)):
            variables[f"{prefix}.approach{number}"] = np.where(observed[:, j],
                                                              approach[:, j], np.nan)
    variables.update(sample_variables(samples, ("t", "temperature")))
    variables["chain"], arms = group_variable(list(samples.chain))
    return ModelContext(chain=chain, method=dataset.method, q_cmd=q_cmd, tau=tau,
                        approach=approach, variables=variables, joint_labels=labels,
                        frame_parameters=dict(frame_parameters or {}),
                        categorical={"chain": arms})


def _pose(problem: Problem, name: str, x: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R (3,3), t (3,), J_r (3,3)) of a pose frame with its delta applied if estimated."""
    frame = problem.dataset.frames[name]
    if not isinstance(frame, FramePose):
        raise InputError(f"frames.{name}: expected a pose (xyz, rpy)")
    T = pose_to_transform(np.asarray(frame.xyz, float), np.asarray(frame.rpy, float))
    term = problem.term(name)
    return perturbed_pose(T[:3, :3], T[:3, 3], None if term is None else x[term.slice])


def predict_dual_loop(problem: Problem, x: np.ndarray, jacobian: bool = True
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted target points in the camera frame and their derivatives.

    Args:
        problem: a dual_loop problem (``build_problem``).
        x: parameter vector, shape ``(P,)`` (deltas from nominal, SI).
        jacobian: also return the derivative.

    Returns:
        ``y`` (m), shape ``(N, 3)``, and ``dy_dx``, shape ``(N, 3, P)`` (or None). Columns
        of the arm a sample did not observe are zero.
    """
    tree = problem_tree(problem)
    ctx = problem.context
    chain_of = problem.dataset.samples.chain
    assert chain_of is not None
    q = ctx.q_cmd
    N = q.shape[0]
    deltas = kinematic_deltas(problem, x, jacobian)
    delta, d_delta = deltas[0], deltas[1]
    # d_delta may cover only the first rows of the stacked kinematic vector (the theta
    # rows, when no geometry effect): the kinematic columns beyond carry no parameter
    covered = delta.shape[1] if d_delta is None else d_delta.shape[1]
    head_chain = tree.branch("head").chain
    head_kin = tree.kin_indices("head")
    head_poses = forward(head_chain, q[:, tree.joint_slice("head")], delta[:, head_kin])
    T_hb_he = head_poses.T_base_flange
    R_ec, t_ec, J_r_camera = _pose(problem, "camera", x)
    R_hc = T_hb_he[:, :3, :3] @ R_ec  # camera orientation in the head base, (N, 3, 3)
    t_hc = T_hb_he[:, :3, :3] @ t_ec + T_hb_he[:, :3, 3]
    p_hb = np.zeros((N, 3))
    dp_hb = np.zeros((N, 3, x.size)) if jacobian else None
    for side in ARMS:
        rows = np.flatnonzero(chain_of == side)
        if rows.size == 0:
            continue
        arm = tree.branch(side).chain
        arm_kin = tree.kin_indices(side)
        poses = forward(arm, q[rows][:, tree.joint_slice(side)], delta[np.ix_(rows, arm_kin)])
        T_ab_af = poses.T_base_flange
        target_term = problem.term(f"{side}_target")
        p_f = np.asarray(problem.dataset.frames[f"{side}_target"], dtype=float)
        if target_term is not None:
            p_f = p_f + x[target_term.slice]
        p_ab = T_ab_af[:, :3, :3] @ p_f + T_ab_af[:, :3, 3]  # (r, 3) target in arm base
        R_hb_ab, t_hb_ab, J_r_base = _pose(problem, f"{side}_base", x)
        p_hb[rows] = p_ab @ R_hb_ab.T + t_hb_ab
        if dp_hb is None:
            continue
        assert d_delta is not None
        used = np.flatnonzero(arm_kin < covered)
        d_pab_dkin = point_jacobian(screws(arm, poses), p_ab)[:, :, used]  # (r, 3, k)
        d_phb_dkin = np.einsum("ij,rjk->rik", R_hb_ab, d_pab_dkin)
        dp_hb[rows] += d_phb_dkin @ d_delta[np.ix_(rows, arm_kin[used])]
        base_term = problem.term(f"{side}_base")
        if base_term is not None:
            start = base_term.slice.start
            dp_hb[rows, :, start:start + 3] += np.eye(3)
            # d(R exp(r) p)/dr = -R skew(p) J_r
            dp_hb[rows, :, start + 3:start + 6] += -np.einsum(
                "ij,rjk,kl->ril", R_hb_ab, skew(p_ab), J_r_base)
        if target_term is not None:
            dp_hb[rows, :, target_term.slice] += R_hb_ab @ T_ab_af[:, :3, :3]
    R_ch = np.swapaxes(R_hc, 1, 2)
    y = np.einsum("nij,nj->ni", R_ch, p_hb - t_hc)
    if dp_hb is None:
        return apply_sensor_effects(problem, x, y, None)
    assert d_delta is not None
    J = np.einsum("nij,njp->nip", R_ch, dp_hb)
    # head parameters move the camera: the fixed point p_hb moves the opposite way in it
    used = np.flatnonzero(head_kin < covered)
    d_phb_dhead = point_jacobian(screws(head_chain, head_poses), p_hb)[:, :, used]
    J -= (R_ch @ d_phb_dhead) @ d_delta[:, head_kin[used]]
    camera_term = problem.term("camera")
    if camera_term is not None:
        dy_dt, dy_dr = inverse_point_derivatives(y, R_ec, J_r_camera)
        start = camera_term.slice.start
        J[:, :, start:start + 3] += dy_dt
        J[:, :, start + 3:start + 6] += dy_dr
    return apply_sensor_effects(problem, x, y, J)



def humanoid_frames() -> dict[str, FramePose | np.ndarray]:
    """The nominal dual_loop frames of the built-in humanoid_upper, as Dataset frames
    (targets as points, the others as poses)."""
    frames: dict[str, FramePose | np.ndarray] = {}
    for key, value in HUMANOID_FRAMES.items():
        if key.endswith("_target"):
            frames[key] = np.asarray(value, dtype=float)
        else:
            xyz, rpy = value  # type: ignore[misc]
            frames[key] = FramePose(xyz=np.asarray(xyz, float), rpy=np.asarray(rpy, float))
    return frames


class DualLoop(DualLoopFile, MeasurementModel):
    """A pan-tilt head camera observes a target on each arm (see the module docstring)."""

    description = "a head camera observes targets on two arms"
    frame_effects = {"camera": POSE, "left_base": POSE, "right_base": POSE,
                     "left_target": POINT, "right_target": POINT}
    default_frames = DUAL_LOOP_FRAMES
    measurement_size = 3
    own_frame_effects = DUAL_LOOP_FRAME_EFFECTS
    sensor_effects = ("depth_scale",)
    # the stereo rig's shared error (hostpc.kinds.stereo_target.shared_error)
    shared_error = staticmethod(rig_shared_error)

    def chain(self, dataset: Dataset) -> Chain:
        """The tree's stacked bookkeeping chain (``KinematicTree.stacked_chain``)."""
        return tree_of(dataset).stacked_chain()

    def check(self, dataset: Dataset, chain: Chain) -> None:
        check_dual_loop(dataset, tree_of(dataset))

    def context(self, dataset: Dataset, chain: Chain) -> ModelContext:
        return dual_loop_context(dataset, chain, self.frame_parameters(dataset))

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        return predict_dual_loop(problem, x, jacobian)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        tree = get_tree("humanoid_upper")
        n = 24
        chain = np.array(["left", "right"] * (n // 2))
        q_head = np.asarray(HUMANOID_HOME["head"]) + rng.uniform(-0.1, 0.1, (n, 2))
        q_arm = np.empty((n, tree.branch("left").chain.n))
        for side in ARMS:
            rows = chain == side
            q_arm[rows] = np.asarray(HUMANOID_HOME[side]) + rng.uniform(
                -0.3, 0.3, (int(rows.sum()), q_arm.shape[1]))
        frames = humanoid_frames()
        cov = np.broadcast_to(np.diag([1e-8, 1e-8, 4e-8]), (n, 3, 3))
        samples = Samples(q=q_arm, p=np.zeros((n, 3)), cov=cov, chain=chain, q_head=q_head)
        return Dataset(method=cls.name, robot=RobotDescription(name="humanoid_upper"),
                       frames=frames, samples=samples)
