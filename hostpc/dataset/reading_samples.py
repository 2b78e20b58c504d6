"""Reading the samples of a ``zerocal-dataset/1`` document into ``Samples`` (SI).

Every sample is checked against its measurement kind (the fields it may and must have, joint
counts, covariances: ``hostpc.dataset.measurement_kind``) and the context every kind shares
(approach
signs, t, temperature, speed, extra), and the values are gathered into arrays, NaN / -1
where an optional value is absent. Raises ``hostpc.dataset.schema.FieldError`` naming the
sample index and field; ``reading`` turns it into a ``DatasetError``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.measurement_kind import Columns, MeasurementKind
from hostpc.dataset.model import Frame, Samples
from hostpc.dataset.schema import FieldError, Loc, show


def _check_field_names(sample: schema.SampleSchema, loc: Loc, kind: MeasurementKind) -> None:
    allowed = kind.accepted_fields()
    for name in schema.SAMPLE_FIELDS:
        if name in sample.model_fields_set and name not in allowed:
            hint = kind.sample_hints.get(name, "")
            raise FieldError((*loc, name), f"not a field of method '{kind.name}'{hint}")
    for name in sample.model_extra or {}:
        if name not in allowed:
            raise FieldError((*loc, name), "unknown field")


def read_samples(
    samples: list[schema.SampleSchema],
    kind: MeasurementKind,
    n_joints: int | None,
    robot_label: str,
    units: Units,
    frames: Mapping[str, Frame] | None = None,
) -> Samples:
    """Check every sample against ``kind`` and build the arrays in SI."""
    columns = Columns(len(samples))
    extra_names: dict[str, None] = {}

    for i, sample in enumerate(samples):
        loc: Loc = ("samples", i)
        _check_field_names(sample, loc, kind)
        q = kind.read_sample(sample, loc, columns, n_joints, robot_label, units)
        columns.put("q", i, q)

        if sample.approach is not None:
            if len(sample.approach) != len(q):
                raise FieldError(
                    (*loc, "approach"),
                    f"expected {len(q)} values (one per joint), got {len(sample.approach)}",
                )
            for j, sign in enumerate(sample.approach):
                if sign not in (1.0, -1.0):
                    raise FieldError((*loc, "approach", j), f"expected +1 or -1, got {show(sign)}")
            columns.put("approach", i, sample.approach)
        for name in ("t", "temperature", "speed"):
            if getattr(sample, name) is not None:
                columns.put(name, i, getattr(sample, name))
        for key, value in (sample.extra or {}).items():
            extra_names[key] = None
            columns.put("extra." + key, i, value)

    speed = columns.floats("speed", units.speed)
    for index in np.flatnonzero(np.isinf(speed)):
        raise FieldError(("samples", int(index), "speed"), "out of range after unit conversion")

    width = max(len(row) for row in columns.values["q"])
    own = kind.samples_arguments(columns, units)
    result = own.samples(
        units.angle(columns.rows("q", width)),
        t=columns.floats("t", units.time),
        temperature=columns.floats("temperature", np.asarray),
        speed=speed,
        approach=columns.rows("approach", width),
        group=_groups(columns) if own.group is None else own.group,
        extra={k: columns.floats("extra." + k, np.asarray) for k in extra_names},
    )
    kind.check_samples(result, frames or {})
    return result


def _groups(columns: Columns) -> Any:
    """(N,) int group index, -1 where absent."""
    column = columns.values.get("group", [None] * columns.n_samples)
    return np.asarray([-1 if g is None else g for g in column], dtype=np.int64)
