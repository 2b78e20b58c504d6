"""tracker_range's file face and measurement model (pure: no I/O).

The distance (m = 1) from the tracker's origin (``anchor``, a point in the robot base
frame) to the reflector (``tool``, a point in the flange frame)::

    d = |R_base_flange t_flange_tool + t_base_flange - anchor|

with the sample's ``sigma`` (m). Samples: ``q``, ``distance``, ``sigma`` (file length unit).
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, RobotDescription, Samples
from hostpc.kinematics import get_robot, point_jacobian, screws
from hostpc.model.layout import Problem
from hostpc.model.measurements import POINT, MeasurementModel
from hostpc.model.measurements.terms import apply_sensor_effects, flange


class TrackerRange(MeasurementModel):
    """The distance from a fixed tracker to a reflector on the flange."""

    name = "tracker_range"
    description = "laser tracker distance (absolute distance meter) to a flange reflector"
    frames = {"tool": "point", "anchor": "point"}
    sample_fields = {"distance": "length", "sigma": "length"}
    frame_effects = {"tool": POINT, "anchor": POINT}
    default_frames = ("tool", "anchor")
    measurement_size = 1

    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        fields = dataset.samples.fields
        return (np.asarray(fields["distance"], float)[:, None],
                (1.0 / np.asarray(fields["sigma"], float))[:, None, None])

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        frames = problem.dataset.frames
        tool, anchor = problem.term("tool"), problem.term("anchor")
        t_flange_tool = np.asarray(frames["tool"], float) + (0 if tool is None else x[tool.slice])
        c_b = np.asarray(frames["anchor"], float) + (0 if anchor is None else x[anchor.slice])
        tip = np.einsum("nij,j->ni", R_base_flange, t_flange_tool) + t_base_flange
        diff = tip - c_b
        distance = np.linalg.norm(diff, axis=1)[:, None]
        if not jacobian:
            return apply_sensor_effects(problem, x, distance, None)
        assert d_delta is not None
        u = diff / distance
        J = np.zeros((tip.shape[0], 1, x.size))
        d_tip = point_jacobian(screws(problem.chain, poses), tip)[:, :, rows]
        J += (u[:, None, :] @ d_tip) @ d_delta
        if tool is not None:
            J[:, 0, tool.slice] += np.einsum("ni,nij->nj", u, R_base_flange)
        if anchor is not None:
            J[:, 0, anchor.slice] -= u
        return apply_sensor_effects(problem, x, distance, J)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        """40 poses of a UR5e seen from a tracker 2.4 m away (distances to be predicted)."""
        chain = get_robot("ur5e")
        q = np.array([0.0, -1.9, 1.9, -1.6, -1.5708, 0.0]) + rng.uniform(-0.8, 0.8, (40, 6))
        samples = Samples(q=q, fields={"distance": np.ones(40), "sigma": np.full(40, 8e-6)})
        return Dataset(method=cls.name, robot=RobotDescription(name=chain.name),
                       frames={"tool": np.array([0.03, -0.02, 0.06]),
                               "anchor": np.array([-1.6, 1.6, 0.35])},
                       samples=samples)
