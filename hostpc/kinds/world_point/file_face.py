"""world_point's file face (shared/spec/dataset-format.md, extension A): an instrument fixed
in the cell (laser tracker, motion capture, CMM) measures a point fixed to the flange in its
own frame, ``world`` (world_pose, the same instrument measuring a whole frame, has its own
file face in hostpc/kinds/world_pose/file_face.py and reads its joints with ``read_q``).

world_point samples: ``q``, ``marker`` (a name of ``frames.markers``; may be omitted when
there is one marker), ``p`` (world frame), ``cov`` or ``sigma``, optional ``mask`` (which
world axes were measured). In ``Samples``: ``p``, ``cov`` and ``fields["marker"]`` (N,)
names, ``fields["mask"]`` (N, 3) of 0/1.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

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
    sample_value,
)
from hostpc.dataset.model import Frame, Samples
from hostpc.dataset.schema import FieldError, Loc, show
from hostpc.json_object import JsonObject


def read_q(sample: schema.SampleSchema, loc: Loc, n_joints: int | None, label: str
            ) -> list[float]:
    q = require(sample, loc, "q")
    assert n_joints is not None
    check_joint_count((*loc, "q"), q, n_joints, label)
    return list(q)


class WorldPointFile(PointSampleKind):
    """A point fixed to the flange (reflector, marker) measured in the instrument's frame."""

    name = "world_point"
    frames = {"world": "pose", "markers": "points"}
    sample_fields = {"p": "length", "cov": "area", "sigma": "length", "marker": "1",
                     "mask": "1"}
    optional_fields = frozenset({"cov", "sigma", "marker", "mask"})
    columns_may_omit = frozenset({"mask"})
    sample_hints = {"q_arm": " (use 'q')", "uv": " (a world-frame point has no pixels)"}

    def accepted_fields(self) -> frozenset[str]:
        return super().accepted_fields() - {"uv"}

    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        q = read_q(sample, loc, n_joints, robot_label)
        self.read_point(sample, loc, columns, units)
        index = int(loc[1])
        marker = sample_value(sample, "marker")
        if marker is not None:
            columns.put("marker", index, schema.validate(str, marker, (*loc, "marker")))
        mask = sample_value(sample, "mask")
        if mask is not None:
            values = schema.validate(schema.Vec3, mask, (*loc, "mask"))
            for j, flag in enumerate(values):
                if flag not in (0.0, 1.0):
                    raise FieldError((*loc, "mask", j), f"expected 0 or 1, got {show(flag)}")
            if not any(values):
                raise FieldError((*loc, "mask"), "no axis measured (at least one 1)")
            columns.put("mask", index, values)
        return q

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        markers = columns.values.get("marker", [None] * columns.n_samples)
        masks = columns.values.get("mask", [None] * columns.n_samples)
        return replace(self.point_arguments(columns, units), uv=None, fields={
            "marker": np.asarray(["" if m is None else m for m in markers], dtype=np.str_),
            "mask": np.asarray([[1.0, 1.0, 1.0] if m is None else m for m in masks]),
        })

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        """Every sample at once (``reading_columns``): p, cov or sigma, marker, mask."""
        from hostpc.dataset.reading_columns import NotColumnar, point_columns

        points = point_columns(table, units)
        n = table.n_samples
        markers = table.strings("marker") if "marker" in table.names else [""] * n
        mask = np.ones((n, 3))
        rows = table.present("mask")  # written only where an axis was not measured
        if rows.size:
            given = table.numbers("mask", list[list[float]], (3,), rows)
            if not (np.all((given == 0.0) | (given == 1.0)) and np.all(given.any(axis=1))):
                raise NotColumnar
            mask[rows] = given
        return replace(points, uv=None,
                       fields={"marker": np.asarray(markers, dtype=np.str_), "mask": mask})

    def check_samples(self, samples: Samples, frames: Mapping[str, Frame]) -> None:
        """Every sample names a marker of ``frames.markers`` (or there is only one)."""
        markers = frames.get("markers")
        names = list(markers) if isinstance(markers, Mapping) else []
        for i, marker in enumerate(samples.fields["marker"]):
            if not marker and len(names) != 1:
                raise FieldError(("samples", i, "marker"), "required field missing (there "
                                 f"are {len(names)} markers: {', '.join(names)})")
            if marker and marker not in names:
                raise FieldError(("samples", i, "marker"),
                                 f"no marker {show(str(marker))} in frames.markers "
                                 f"(markers: {', '.join(names)})")

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        out: JsonObject = {"q": samples.q[index].tolist()}
        marker = str(samples.fields["marker"][index]) if "marker" in samples.fields else ""
        if marker:
            out["marker"] = marker
        self.write_point(samples, index, out)
        if "mask" in samples.fields and not np.all(samples.fields["mask"][index] == 1.0):
            out["mask"] = [int(v) for v in samples.fields["mask"][index]]
        return out, samples.q.shape[1]

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        fields: list[tuple[str, list[Any], list[bool] | None]] = [
            ("q", samples.q.tolist(), None)]
        if "marker" in samples.fields:
            markers = [str(m) for m in samples.fields["marker"].tolist()]
            fields.append(("marker", markers, [bool(m) for m in markers]))
        fields += point_columns_out(samples)
        if "mask" in samples.fields:
            mask = np.asarray(samples.fields["mask"])
            fields.append(("mask", mask.astype(np.int64).tolist(),
                           (~np.all(mask == 1.0, axis=1)).tolist()))
        return WrittenColumns(fields, [samples.q.shape[1]] * samples.n)
