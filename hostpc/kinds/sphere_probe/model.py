"""sphere_probe: touch contacts on a reference sphere (m = 1).

The distance from the stylus tip centre to the sphere centre, ``|R_base_flange t_flange_tool
+ t_base_flange - c_b|``, measured as ``R + r`` (sphere radius plus stylus radius) with the
sample's ``sigma``. Frames: ``tool`` (the tip centre in the flange frame: a point, x y z),
``sphere`` (the centre in the base frame), ``base`` (robot base in the sphere's frame).
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples, SphereFrame
from hostpc.kinds.sphere_probe.file_face import (
    SphereProbeFile,
    probe_blocks,
    reference_sphere,
    stylus_radius,
)
from hostpc.kinds.sphere_probe.frames import SphereCentreFrame
from hostpc.kinematics import Chain, get_robot, point_jacobian
from hostpc.model.context import group_variable, sample_variables, serial_context
from hostpc.model.effect import ModelContext
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


class SphereProbe(SphereProbeFile, MeasurementModel):
    """A touch probe on the flange contacts a reference sphere of known radius."""

    description = "touch contacts on a reference sphere"
    frame_effects = {"tool": POINT, "sphere": POINT, "base": POSE}
    default_frames = ("tool", "sphere")
    measurement_size = 1
    own_frame_effects = (SphereCentreFrame,)
    sensor_effects = ("trigger_latency",)

    def context(self, dataset: Dataset, chain: Chain) -> ModelContext:
        """The serial context plus ``probe_group``, each contact's probe orientation as a
        group label (a touch probe's pretravel differs by direction: lobing)."""
        variables = sample_variables(dataset.samples)
        group = np.asarray(dataset.samples.group)
        categorical = {}
        if group.size == dataset.samples.n and np.any(group >= 0):
            codes, levels = group_variable([str(g) if g >= 0 else None for g in group])
            variables["probe_group"] = codes
            categorical["probe_group"] = levels
        return serial_context(dataset, chain, self.frame_parameters(dataset), variables,
                              categorical)

    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        """Every contact measures R + r; W = 1 / sigma."""
        sphere = reference_sphere(dataset)
        stylus = stylus_radius(dataset) or 0.0
        n = dataset.samples.n
        measured = np.full((n, 1), float(sphere.radius) + float(stylus))
        W = (1.0 / np.asarray(dataset.samples.sigma, dtype=float)).reshape(n, 1, 1)
        return measured, W

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        """Predicted tip-to-centre distance (N, 1) and d/dx (N, 1, P)."""
        chain = problem.chain
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        _, t_flange_tool, _ = frame_pose(problem, "tool", x)
        tip = np.einsum("nij,j->ni", R_base_flange, t_flange_tool) + t_base_flange
        sphere = reference_sphere(problem.dataset)
        c_b, d_cb = world_point_in_base(problem, x, "sphere", np.asarray(sphere.center, float))
        diff = tip - c_b[None, :]
        distance = np.linalg.norm(diff, axis=1)
        prediction = distance[:, None]
        if not jacobian:
            return apply_sensor_effects(problem, x, prediction, None)
        assert d_delta is not None
        u = diff / distance[:, None]
        n_samples = tip.shape[0]
        J = np.zeros((n_samples, 1, x.size))
        d_tip_dkin = point_jacobian(row_screws(chain, poses, rows), tip)
        d_dist_dkin = (u[:, None, :] @ d_tip_dkin)  # (N, 1, k)
        J += d_dist_dkin @ d_delta
        tool = problem.term("tool")
        if tool is not None:
            J[:, 0, tool.slice] += np.einsum("ni,nij->nj", u, R_base_flange)
        for name, d_cb_term in d_cb.items():
            span = problem.term(name).slice  # type: ignore[union-attr]
            J[:, 0, span] -= u @ d_cb_term
        return apply_sensor_effects(problem, x, prediction, J)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        chain = get_robot("ur5e")
        q = example_poses(chain, UR5E_HOME, 30, rng, spread=0.3)
        centre = point_ahead(chain, UR5E_HOME, EXAMPLE_TOOL_XYZ, EXAMPLE_TOOL_RPY, 0.0)
        samples = Samples(q=q, sigma=np.full(q.shape[0], 5e-6), group=np.arange(30) // 5,
                          speed=rng.uniform(0.005, 0.02, 30),
                          approach=rng.choice([-1.0, 1.0], q.shape))
        tool = FramePose(xyz=EXAMPLE_TOOL_XYZ, rpy=np.zeros(3))
        return Dataset(method=cls.name, robot=RobotDescription(name="ur5e"),
                       frames={"tool": tool, "sphere": SphereFrame(centre, 0.0125)},
                       samples=samples, blocks=probe_blocks(0.0015))
