"""world_point: a point fixed to the flange measured in a fixed instrument's frame (m = 3).

A laser tracker following a reflector, a motion-capture system tracking markers, a CMM.
For a sample of marker k (``samples.fields["marker"]``)::

    p_world = R_world_base (R_base_flange m_k + t_base_flange) + t_world_base

with ``T_world_base = world`` (robot base in the world frame, pose delta ``T_nom @ [exp(r),
t]``) and ``m_k`` the marker in the flange frame (``markers``, deltas ``markers.NAME.x``
...). Axes a sample did not measure (``mask`` 0) carry no weight: their prediction is the
measured value itself (zero residual, zero derivative). Sensor effects act on the
world-frame point.

What the data cannot tell apart, in words (the fit names each held combination):

- joint 1's zero and the rotation of ``world`` about the base z axis (a rotation of the
  whole arm about its first axis is the same as turning the base in the world), unless
  ``world`` is known;
- the last joint's zero and the markers' rotation about the flange axis, unless ``markers``
  is known (a dowel-pinned nest); with one marker on the axis, the last joint is unseen;
- with both ``world`` and ``markers`` known, every joint's zero is identified.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.kinds.world_point.file_face import WorldPointFile
from hostpc.kinematics import Chain, get_robot, point_jacobian
from hostpc.kinematics.rotations import skew
from hostpc.model.context import sample_variables, serial_context
from hostpc.model.effect import ModelContext
from hostpc.model.layout import Problem
from hostpc.model.measurements.base import POSE, UR5E_HOME, MeasurementModel, example_poses
from hostpc.model.measurements.terms import (
    apply_sensor_effects,
    flange,
    frame_pose,
    row_screws,
)

__all__ = ["WorldPoint", "marker_index", "markers_of", "world_variables"]


def markers_of(dataset: Dataset) -> dict[str, np.ndarray]:
    """The nominal markers, name -> (3,) point in the flange frame (m)."""
    markers = dataset.frames["markers"]
    assert isinstance(markers, dict)
    return {str(k): np.asarray(v, dtype=float) for k, v in markers.items()}


def marker_index(dataset: Dataset) -> tuple[list[str], np.ndarray]:
    """The marker names (frames.markers order) and each sample's marker index (N,)."""
    names = list(markers_of(dataset))
    given = dataset.samples.fields["marker"]
    index = np.array([names.index(str(m)) if m else 0 for m in given], dtype=int)
    return names, index


def world_variables(dataset: Dataset) -> dict[str, np.ndarray]:
    """The shared per-sample variables without ``depth`` (there is no sensor axis)."""
    variables = sample_variables(dataset.samples)
    variables.pop("depth", None)
    return variables


class WorldPoint(WorldPointFile, MeasurementModel):
    """Flange-fixed markers measured as 3-D points in the instrument's frame."""

    description = "points on the flange measured in a fixed instrument's frame"
    default_frames = ("world", "markers")
    measurement_size = 3

    def frame_parameters(self, dataset: Dataset) -> Mapping[str, tuple[str, ...]]:
        names = list(markers_of(dataset))
        return {"world": POSE,
                "markers": tuple(f"{m}.{axis}" for m in names for axis in "xyz")}

    def context(self, dataset: Dataset, chain: Chain) -> ModelContext:
        variables = world_variables(dataset)
        names, index = marker_index(dataset)
        variables["marker"] = index.astype(float)  # a group label: tested per marker
        return serial_context(dataset, chain, self.frame_parameters(dataset), variables,
                              categorical={"marker": tuple(names)})

    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        measured = np.asarray(dataset.samples.p, dtype=float)
        cov = np.asarray(dataset.samples.cov, dtype=float)
        mask = np.asarray(dataset.samples.fields["mask"], dtype=bool)
        # an unmeasured axis: its residual is zero by construction (see predict); it gets
        # the mean variance of the sample's measured axes, so the stated noise stays sane
        measured_variance = np.einsum("nii->ni", cov) * mask
        fill = measured_variance.sum(axis=1) / mask.sum(axis=1)
        cov = np.where(mask[:, :, None] & mask[:, None, :], cov, 0.0)
        cov = cov + np.einsum("ni,ij->nij", (~mask) * fill[:, None], np.eye(3))
        L = np.linalg.cholesky(cov)
        W = np.linalg.solve(L, np.broadcast_to(np.eye(3), cov.shape))
        return measured, W

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        dataset = problem.dataset
        names, index = marker_index(dataset)
        markers = markers_of(dataset)
        nominal = np.array([markers[m] for m in names])
        markers_term = problem.term("markers")
        if markers_term is not None:
            nominal = nominal + x[markers_term.slice].reshape(-1, 3)
        poses, R_base_flange, t_base_flange, d_delta, rows = flange(problem, x, jacobian)
        m_f = nominal[index]  # (N, 3) each sample's marker in the flange frame
        p_b = np.einsum("nij,nj->ni", R_base_flange, m_f) + t_base_flange
        R_world_base, t_world_base, J_r = frame_pose(problem, "world", x)
        y = p_b @ R_world_base.T + t_world_base
        mask = np.asarray(dataset.samples.fields["mask"], dtype=bool)
        if not jacobian:
            y, _ = apply_sensor_effects(problem, x, y, None)
            return np.where(mask, y, problem.measured), None
        assert d_delta is not None
        J = np.zeros((y.shape[0], 3, x.size))
        d_pb = point_jacobian(row_screws(problem.chain, poses, rows), p_b)
        J += np.einsum("ij,njk->nik", R_world_base, d_pb) @ d_delta
        world = problem.term("world")
        if world is not None:
            start = world.slice.start
            J[:, :, start:start + 3] += np.eye(3)
            J[:, :, start + 3:start + 6] += -np.einsum("ij,njk,kl->nil", R_world_base,
                                                       skew(p_b), J_r)
        if markers_term is not None:
            columns = markers_term.slice.start + 3 * index[:, None] + np.arange(3)  # (N, 3)
            block = np.einsum("ij,njk->nik", R_world_base, R_base_flange)  # (N, 3, 3)
            for axis in range(3):
                J[np.arange(y.shape[0]), :, columns[:, axis]] += block[:, :, axis]
        y, J_out = apply_sensor_effects(problem, x, y, J)
        assert J_out is not None
        J_out[~mask] = 0.0
        return np.where(mask, y, problem.measured), J_out

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        chain = get_robot("ur5e")
        q = np.repeat(example_poses(chain, UR5E_HOME, 16, rng, spread=0.6), 2, axis=0)
        n = q.shape[0]
        markers = {"a": np.array([0.05, 0.0, 0.03]), "b": np.array([-0.02, 0.06, 0.05])}
        mask = np.ones((n, 3))
        mask[5, 2] = 0.0  # one sample lost its z axis
        samples = Samples(q=q, p=np.zeros((n, 3)),
                          cov=np.broadcast_to(np.eye(3) * 1e-10, (n, 3, 3)),
                          fields={"marker": np.array(["a", "b"] * (n // 2)), "mask": mask})
        world = FramePose(xyz=np.array([1.5, -0.4, 0.2]), rpy=np.array([0.0, 0.0, 2.5]))
        return Dataset(method=cls.name, robot=RobotDescription(name="ur5e"),
                       frames={"world": world, "markers": markers}, samples=samples)
