"""stereo_target's file face (shared/spec/dataset-format.md): a sensor on the flange
measures a fixed target point; extended by its model (``model.py``) with the prediction."""

from __future__ import annotations

from typing import Any

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.measurement_kind import (
    Columns,
    KindArrays,
    PointSampleKind,
    WrittenColumns,
    check_joint_count,
    point_columns_out,
    require,
)
from hostpc.dataset.model import Dataset, Samples
from hostpc.dataset.schema import Loc
from hostpc.json_object import JsonObject
from hostpc.kinds.stereo_target.rig_block import check_rig_block


class StereoTargetFile(PointSampleKind):
    """A sensor on the flange measures a fixed target point (``p`` in the sensor frame)."""

    name = "stereo_target"
    frames = {"tool": "pose", "target": "point", "camera": "camera_model"}
    optional_frames = frozenset({"camera"})
    sample_fields = {"p": "length", "cov": "area", "sigma": "length", "uv": "1"}
    sample_hints = {"q_arm": " (use 'q')"}

    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        q = require(sample, loc, "q")
        assert n_joints is not None
        check_joint_count((*loc, "q"), q, n_joints, robot_label)
        self.read_point(sample, loc, columns, units)
        self.read_uv(sample, loc, columns)
        return list(q)

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        return self.point_arguments(columns, units)

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        from hostpc.dataset.reading_columns import point_columns

        return point_columns(table, units)

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        out: JsonObject = {"q": samples.q[index].tolist()}
        self.write_point(samples, index, out)
        return out, samples.q.shape[1]

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        return WrittenColumns([("q", samples.q.tolist(), None), *point_columns_out(samples)],
                              [samples.q.shape[1]] * samples.n)

    def check_loaded(self, dataset: Dataset, source: str) -> None:
        check_rig_block(dataset, source)
