"""world_pose's file face (shared/spec/dataset-format.md, extension A): a frame fixed to the
flange measured in full by an instrument fixed in the cell.

world_pose samples: ``q``, ``p``, ``rpy`` (orientation of the measured frame in the world
frame), ``cov`` (6x6 over x, y, z and the world-frame rotation vector of the orientation
error; file units) or ``sigma`` and ``sigma_angle``. In ``Samples``: ``p``,
``fields["rpy"]`` (N, 3) rad and ``fields["pose_cov"]`` (N, 6, 6) SI (m^2, m rad, rad^2).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.measurement_kind import (
    Columns,
    KindArrays,
    PointSampleKind,
    WrittenColumns,
    check_covariance,
    positive,
    require,
    sample_value,
)
from hostpc.dataset.model import Samples
from hostpc.dataset.schema import FieldError, Loc
from hostpc.json_object import JsonObject
from hostpc.kinds.world_point.file_face import read_q


class WorldPoseFile(PointSampleKind):
    """A frame fixed to the flange measured in full (position and orientation)."""

    name = "world_pose"
    frames = {"world": "pose", "tool": "pose"}
    sample_fields = {"p": "length", "rpy": "angle", "cov": "area", "sigma": "length",
                     "sigma_angle": "angle"}
    optional_fields = frozenset({"cov", "sigma", "sigma_angle"})
    sample_hints = {"q_arm": " (use 'q')", "uv": " (a world-frame pose has no pixels)"}

    def accepted_fields(self) -> frozenset[str]:
        return super().accepted_fields() - {"uv"}

    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        q = read_q(sample, loc, n_joints, robot_label)
        index = int(loc[1])
        columns.put("p", index, require(sample, loc, "p"))
        rpy = schema.validate(schema.Vec3, require(sample, loc, "rpy"), (*loc, "rpy"))
        columns.put("rpy", index, units.angle(rpy))
        columns.put("pose_cov", index, self._covariance(sample, loc, units))
        return q

    @staticmethod
    def _covariance(sample: schema.SampleSchema, loc: Loc, units: Units) -> np.ndarray:
        """The 6x6 pose covariance in SI from ``cov`` or ``sigma`` + ``sigma_angle``."""
        sigma_angle = sample_value(sample, "sigma_angle")
        given_sigma = sample.sigma is not None or sigma_angle is not None
        if sample.cov is not None and given_sigma:
            raise FieldError((*loc, "sigma"), "give either 'cov' or 'sigma' and 'sigma_angle', "
                             "not both")
        if sample.cov is not None:
            if len(sample.cov) != 6:
                raise FieldError((*loc, "cov"), "expected a 6x6 matrix (x, y, z, rx, ry, rz), "
                                 f"got a {len(sample.cov)}x{len(sample.cov)} matrix")
            scale = np.array([float(units.length(1.0))] * 3 + [float(units.angle(1.0))] * 3)
            cov = np.asarray(sample.cov, dtype=float) * np.outer(scale, scale)
            check_covariance((*loc, "cov"), cov)
            return cov
        if sample.sigma is None or sigma_angle is None:
            missing = "sigma" if sample.sigma is None else "sigma_angle"
            if not given_sigma:
                missing = "cov"
            raise FieldError((*loc, missing),
                             "required field missing (or give 'sigma' and 'sigma_angle')"
                             if missing == "cov" else "required field missing")
        sigma = float(units.length(positive((*loc, "sigma"), sample.sigma)))
        angle = schema.validate(float, sigma_angle, (*loc, "sigma_angle"))
        sigma_a = float(units.angle(positive((*loc, "sigma_angle"), angle)))
        cov = np.diag([sigma**2] * 3 + [sigma_a**2] * 3)
        check_covariance((*loc, "sigma"), cov)
        return cov

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        """Every sample at once (``reading_columns``): p, rpy, and cov (6x6, file units)
        or sigma and sigma_angle."""
        from hostpc.dataset.reading_columns import NotColumnar, checked_covariances

        if not {"p", "rpy"} <= table.names:
            return None
        p = table.numbers("p", list[list[float]], (3,))
        rpy = table.numbers("rpy", list[list[float]], (3,))
        given = {"cov", "sigma", "sigma_angle"} & table.names
        if given == {"cov"}:
            scale = np.array([float(units.length(1.0))] * 3 + [float(units.angle(1.0))] * 3)
            cov = table.numbers("cov", list[list[list[float]]], (6, 6)) * np.outer(scale, scale)
        elif given == {"sigma", "sigma_angle"}:
            sigma_file = table.numbers("sigma", list[float], ())
            angle_file = table.numbers("sigma_angle", list[float], ())
            if not (np.all(sigma_file > 0) and np.all(angle_file > 0)):
                raise NotColumnar
            sigma = np.asarray(units.length(sigma_file), dtype=np.float64)
            sigma_a = np.asarray(units.angle(angle_file), dtype=np.float64)
            variances = np.repeat(np.stack([sigma**2, sigma_a**2], axis=1), 3, axis=1)
            cov = np.zeros((table.n_samples, 6, 6))
            cov[:, np.arange(6), np.arange(6)] = variances
        else:
            raise NotColumnar
        return KindArrays(p=units.length(p),
                          fields={"rpy": np.asarray(units.angle(rpy), dtype=float),
                                  "pose_cov": checked_covariances(cov)})

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        return KindArrays(p=units.length(columns.values["p"]),
                          fields={"rpy": np.asarray(columns.values["rpy"], dtype=float),
                                  "pose_cov": np.asarray(columns.values["pose_cov"],
                                                         dtype=float)})

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        assert samples.p is not None
        return ({"q": samples.q[index].tolist(), "p": samples.p[index].tolist(),
                 "rpy": samples.fields["rpy"][index].tolist(),
                 "cov": samples.fields["pose_cov"][index].tolist()}, samples.q.shape[1])

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        assert samples.p is not None
        return WrittenColumns(
            [("q", samples.q.tolist(), None), ("p", samples.p.tolist(), None),
             ("rpy", np.asarray(samples.fields["rpy"]).tolist(), None),
             ("cov", np.asarray(samples.fields["pose_cov"]).tolist(), None)],
            [samples.q.shape[1]] * samples.n)
