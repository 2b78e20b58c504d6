"""string_pot's file face and measurement model (pure: no I/O).

The cable length (m = 1) from the drum (``anchor``, a point in the robot base frame) to the
hook (``tool``, a point in the flange frame)::

    length = |R_base_flange t_flange_tool + t_base_flange - anchor|

with the sample's ``sigma`` (m). Samples: ``q``, ``length``, ``sigma`` (file length unit).
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, RobotDescription, Samples
from hostpc.kinematics import get_robot, point_jacobian, screws
from hostpc.model.layout import Problem
from hostpc.model.measurements import POINT, MeasurementModel
from hostpc.model.measurements.terms import apply_sensor_effects, flange


class StringPot(MeasurementModel):
    """A draw-wire sensor's cable length from a drum in the cell to a hook on the flange."""

    name = "string_pot"
    description = "draw-wire (string pot) cable length from a drum in the cell to the flange"
    frames = {"tool": "point", "anchor": "point"}
    sample_fields = {"length": "length", "sigma": "length"}
    frame_effects = {"tool": POINT, "anchor": POINT}
    default_frames = ("tool", "anchor")
    measurement_size = 1

    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        fields = dataset.samples.fields
        weight = 1.0 / np.asarray(fields["sigma"], float)
        return np.asarray(fields["length"], float).reshape(-1, 1), weight.reshape(-1, 1, 1)

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        hook_term, drum_term = problem.term("tool"), problem.term("anchor")
        hook = np.asarray(problem.dataset.frames["tool"], float)
        drum = np.asarray(problem.dataset.frames["anchor"], float)
        if hook_term is not None:
            hook = hook + x[hook_term.slice]
        if drum_term is not None:
            drum = drum + x[drum_term.slice]
        cable = R_base_flange @ hook + t_base_flange - drum  # (N, 3) drum -> hook
        length = np.sqrt(np.sum(cable**2, axis=1, keepdims=True))
        if not jacobian:
            return apply_sensor_effects(problem, x, length, None)
        assert d_delta is not None
        direction = cable / length  # d length / d hook position in base
        hook_in_base = cable + drum
        J = np.zeros((cable.shape[0], 1, x.size))
        moved = point_jacobian(screws(problem.chain, poses), hook_in_base)[:, :, rows]
        J[:, 0, :] = np.einsum("ni,nij->nj", direction, moved @ d_delta)
        if hook_term is not None:
            J[:, 0, hook_term.slice] += np.einsum("ni,nij->nj", direction, R_base_flange)
        if drum_term is not None:
            J[:, 0, drum_term.slice] -= direction
        return apply_sensor_effects(problem, x, length, J)

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        """40 poses of a UR5e hooked to a drum on the floor beside it (lengths to be
        predicted)."""
        chain = get_robot("ur5e")
        q = np.array([0.0, -1.9, 1.9, -1.6, -1.5708, 0.0]) + rng.uniform(-0.9, 0.9, (40, 6))
        samples = Samples(q=q, fields={"length": np.ones(40), "sigma": np.full(40, 1e-5)})
        return Dataset(method=cls.name, robot=RobotDescription(name=chain.name),
                       frames={"tool": np.array([0.0, 0.04, 0.05]),
                               "anchor": np.array([0.55, 0.45, -0.15])},
                       samples=samples)
