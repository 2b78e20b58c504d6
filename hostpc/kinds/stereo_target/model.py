"""stereo_target: a sensor on the flange measures a fixed target point (m = 3).

The target point in the sensor frame,
``y = R_flange_tool^T (R_base_flange^T (p_b - t_base_flange) - t_flange_tool)``, then the
sensor effects in order. Frames: ``tool`` (sensor frame in the flange frame, pose),
``target`` (the point in the base frame, or in the world frame of ``base``), ``base``
(robot base in the target's frame, pose; nominal identity).
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.kinds.stereo_target.file_face import StereoTargetFile
from hostpc.kinds.stereo_target.frames import TargetFrame
from hostpc.kinds.stereo_target.shared_error import rig_shared_error
from hostpc.kinematics import get_robot, point_jacobian
from hostpc.model.frame_math import inverse_point_derivatives
from hostpc.model.layout import Problem
from hostpc.model.measurements.base import (
    EXAMPLE_TOOL_RPY,
    EXAMPLE_TOOL_XYZ,
    POINT,
    POSE,
    UR5E_HOME,
    MeasurementModel,
    example_poses,
    point_ahead,
)
from hostpc.model.measurements.terms import (
    apply_sensor_effects,
    flange,
    frame_pose,
    row_screws,
    world_point_in_base,
)


class StereoTarget(StereoTargetFile, MeasurementModel):
    """A stereo camera on the flange measures a fixed target point in its own frame."""

    description = "a sensor on the flange measures a fixed target point"
    frame_effects = {"tool": POSE, "target": POINT, "base": POSE}
    default_frames = ("tool", "target")
    measurement_size = 3
    own_frame_effects = (TargetFrame,)
    sensor_effects = ("depth_scale",)
    # the stereo rig's shared error (hostpc.kinds.stereo_target.shared_error)
    shared_error = staticmethod(rig_shared_error)

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        """Predicted target point in the sensor frame (N, 3) and d/dx (N, 3, P)."""
        chain = problem.chain
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        p_b, d_pb = world_point_in_base(
            problem, x, "target", np.asarray(problem.dataset.frames["target"], dtype=float)
        )
        R_flange_tool, t_flange_tool, J_r_tool = frame_pose(problem, "tool", x)
        R_flange_base = np.swapaxes(R_base_flange, 1, 2)
        p_f = np.einsum("nij,nj->ni", R_flange_base, p_b[None, :] - t_base_flange)
        y = (p_f - t_flange_tool) @ R_flange_tool  # rows: R_flange_tool^T (p_f - t_flange_tool)
        if not jacobian:
            return apply_sensor_effects(problem, x, y, None)
        assert d_delta is not None
        n_samples = y.shape[0]
        J = np.zeros((n_samples, 3, x.size))
        # kinematic parameters: moving the flange by a screw moves the fixed target point the
        # opposite way in the flange frame:
        # dp_f = -R_base_flange^T (w x (p_b - c)) or -R_base_flange^T v
        d_pb_world_dkin = point_jacobian(row_screws(chain, poses, rows),
                                         np.broadcast_to(p_b, (n_samples, 3)))
        # (N, 3, 3): d y / d p_b  (and -d y / d (flange motion))
        A = R_flange_tool.T @ R_flange_base
        J -= (A @ d_pb_world_dkin) @ d_delta
        for name, d_pb_term in d_pb.items():
            span = problem.term(name).slice  # type: ignore[union-attr]
            J[:, :, span] += A @ d_pb_term
        tool = problem.term("tool")
        if tool is not None:
            dy_dt, dy_dr = inverse_point_derivatives(y, R_flange_tool, J_r_tool)
            J[:, :, tool.slice.start:tool.slice.start + 3] += dy_dt
            J[:, :, tool.slice.start + 3:tool.slice.stop] += dy_dr
        return apply_sensor_effects(problem, x, y, J)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        chain = get_robot("ur5e")
        q = example_poses(chain, UR5E_HOME, 24, rng, spread=0.2)
        target = point_ahead(chain, UR5E_HOME, EXAMPLE_TOOL_XYZ, EXAMPLE_TOOL_RPY, 0.45)
        cov = np.broadcast_to(np.diag([1e-8, 1e-8, 4e-8]), (q.shape[0], 3, 3))
        tool = FramePose(xyz=EXAMPLE_TOOL_XYZ, rpy=EXAMPLE_TOOL_RPY)
        return Dataset(method=cls.name, robot=RobotDescription(name="ur5e"),
                       frames={"tool": tool, "target": target},
                       samples=Samples(q=q, p=np.zeros((q.shape[0], 3)), cov=cov,
                                       t=np.arange(q.shape[0], dtype=float),
                                       approach=rng.choice([-1.0, 1.0], q.shape)))
