"""world_pose: a frame fixed to the flange measured in full in a fixed world frame (m = 6).

A tracker's 6-DoF probe or a motion-capture rigid body. The prediction of a sample is::

    p_world = R_world_base (R_base_flange t_flange_tool + t_base_flange) + t_world_base
                                                                     (position, m)
    phi     = log(R_world_base R_base_flange R_flange_tool R_meas^T)  (orientation, rad)

``phi`` is the predicted orientation's difference from the measured one as a rotation
vector in the world frame; its measured value is 0, so the residual's rotation part is the
orientation error ``log(R_meas R_pred^T)``, whose covariance the 6x6 ``cov`` states (x, y,
z, then the world-frame rotation vector). Frames: ``world`` (robot base in the world frame)
and ``tool`` (the measured frame in the flange frame), pose deltas ``T_nom @ [exp(r), t]``.

What the data cannot tell apart, in words (the fit names each held combination): joint 1's
zero and the rotation of ``world`` about the base z axis, unless ``world`` is known; the
last joint's zero and the rotation of ``tool`` about the flange axis, unless ``tool`` is
known. Orientation makes far more identifiable than a point: the tool's position along
the last axis, for instance, which a single marker on that axis leaves open.
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.kinds.world_point.model import world_variables
from hostpc.kinds.world_pose.file_face import WorldPoseFile
from hostpc.kinematics import Chain, forward, get_robot, point_jacobian, screws
from hostpc.kinematics.jacobians import rotation_jacobian
from hostpc.kinematics.rotations import (
    matrix_to_rotvec,
    matrix_to_rpy,
    pose_to_transform,
    rpy_to_matrix,
    skew,
)
from hostpc.model.context import serial_context
from hostpc.model.effect import ModelContext
from hostpc.model.layout import Problem
from hostpc.model.measurements.base import POSE, UR5E_HOME, MeasurementModel, example_poses
from hostpc.model.measurements.terms import apply_sensor_effects, flange, frame_pose

__all__ = ["WorldPose", "so3_left_jacobian_inverse"]


def so3_left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """J_l^-1 (N, 3, 3) at rotation vectors phi (N, 3): log(exp(d) exp(phi)) ~ phi +
    J_l^-1(phi) d for a small world-frame rotation d."""
    theta = np.linalg.norm(phi, axis=1)
    K = skew(phi)
    small = theta < 1e-5
    safe = np.where(small, 1.0, theta)
    coefficient = np.where(
        small, 1.0 / 12.0,
        1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)))
    return np.eye(3) - 0.5 * K + coefficient[:, None, None] * (K @ K)


class WorldPose(WorldPoseFile, MeasurementModel):
    """A flange-fixed frame measured in position and orientation in the world frame."""

    description = "a frame on the flange measured in full in a fixed instrument's frame"
    frame_effects = {"world": POSE, "tool": POSE}
    default_frames = ("world", "tool")
    measurement_size = 6
    residual_units = ("m", "m", "m", "rad", "rad", "rad")

    def context(self, dataset: Dataset, chain: Chain) -> ModelContext:
        return serial_context(dataset, chain, self.frame_parameters(dataset),
                              world_variables(dataset))

    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        samples = dataset.samples
        n = samples.n
        measured = np.concatenate([np.asarray(samples.p, dtype=float), np.zeros((n, 3))], 1)
        cov = np.asarray(samples.fields["pose_cov"], dtype=float)
        L = np.linalg.cholesky(cov)
        return measured, np.linalg.solve(L, np.broadcast_to(np.eye(6), cov.shape))

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        R_world_base, t_world_base, J_r_world = frame_pose(problem, "world", x)
        R_flange_tool, t_flange_tool, J_r_tool = frame_pose(problem, "tool", x)
        p_b = np.einsum("nij,j->ni", R_base_flange, t_flange_tool) + t_base_flange
        position = p_b @ R_world_base.T + t_world_base
        R_pred = R_world_base @ R_base_flange @ R_flange_tool
        R_meas = rpy_to_matrix(problem.dataset.samples.fields["rpy"])
        phi = matrix_to_rotvec(R_pred @ np.swapaxes(R_meas, 1, 2))
        y = np.concatenate([position, phi], axis=1)
        if not jacobian:
            return apply_sensor_effects(problem, x, y, None)
        assert d_delta is not None
        n = y.shape[0]
        J = np.zeros((n, 6, x.size))
        S = screws(problem.chain, poses)
        J_inv = so3_left_jacobian_inverse(phi)
        J[:, :3] += np.einsum("ij,njk->nik", R_world_base,
                              point_jacobian(S, p_b)[:, :, rows]) @ d_delta
        w_world = np.einsum("ij,njk->nik", R_world_base, rotation_jacobian(S)[:, :, rows])
        J[:, 3:] += (J_inv @ w_world) @ d_delta
        world = problem.term("world")
        if world is not None:
            start = world.slice.start
            J[:, :3, start:start + 3] += np.eye(3)
            J[:, :3, start + 3:start + 6] += -np.einsum("ij,njk,kl->nil", R_world_base, skew(p_b),
                                                         J_r_world)
            J[:, 3:, start + 3:start + 6] += J_inv @ (R_world_base @ J_r_world)
        tool = problem.term("tool")
        if tool is not None:
            start = tool.slice.start
            J[:, :3, start:start + 3] += np.einsum("ij,njk->nik", R_world_base, R_base_flange)
            J[:, 3:, start + 3:start + 6] += J_inv @ (R_pred @ J_r_tool)
        return apply_sensor_effects(problem, x, y, J)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        """Measured at the nominal model (so orientation errors stay small)."""
        chain = get_robot("ur5e")
        q = example_poses(chain, UR5E_HOME, 24, rng, spread=0.6)
        n = q.shape[0]
        world = FramePose(xyz=np.array([1.5, -0.4, 0.2]), rpy=np.array([0.0, 0.0, 2.5]))
        tool = FramePose(xyz=np.array([0.01, 0.02, 0.08]), rpy=np.array([0.1, -0.2, 0.3]))
        T = (pose_to_transform(world.xyz, world.rpy) @ forward(chain, q).T_base_flange
             @ pose_to_transform(tool.xyz, tool.rpy))
        cov = np.diag([1e-10] * 3 + [1e-8] * 3)
        samples = Samples(q=q, p=T[:, :3, 3],
                          fields={"rpy": matrix_to_rpy(T[:, :3, :3]),
                                  "pose_cov": np.broadcast_to(cov, (n, 6, 6))})
        return Dataset(method=cls.name, robot=RobotDescription(name="ur5e"),
                       frames={"world": world, "tool": tool}, samples=samples)
