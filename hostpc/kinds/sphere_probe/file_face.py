"""sphere_probe's file face (shared/spec/dataset-format.md): touch contacts on a reference
sphere; extended by its model (``model.py``) with the prediction."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.measurement_kind import (
    Columns,
    KindArrays,
    MeasurementKind,
    WrittenColumns,
    check_joint_count,
    positive,
    require,
)
from hostpc.dataset.model import Dataset, KindBlock, Samples, SphereFrame
from hostpc.dataset.schema import FieldError, Loc, show
from hostpc.json_object import JsonObject


@dataclass(frozen=True, eq=False)
class Probe(KindBlock):
    """sphere_probe's ``probe`` block: the stylus ball radius, m."""

    stylus_radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "stylus_radius", float(self.stylus_radius))

    def to_json(self) -> JsonObject:
        return {"stylus_radius": float(self.stylus_radius)}

    def lengths(self) -> Iterable[tuple[str, float]]:
        return (("stylus_radius", self.stylus_radius),)


def probe_blocks(stylus_radius: float) -> dict[str, KindBlock]:
    """A sphere_probe dataset's ``blocks``: the probe with this stylus radius (m)."""
    return {"probe": Probe(stylus_radius)}


def stylus_radius(dataset: Dataset) -> float | None:
    """The stylus ball radius of a sphere_probe dataset, m (None: no ``probe`` block)."""
    probe = dataset.blocks.get("probe")
    return probe.stylus_radius if isinstance(probe, Probe) else None


def reference_sphere(dataset: Dataset) -> SphereFrame:
    """The reference sphere of a sphere_probe dataset (``frames.sphere``)."""
    value = dataset.frames["sphere"]
    if not isinstance(value, SphereFrame):
        raise TypeError(f"frames['sphere'] is not a sphere: {type(value).__name__}")
    return value


class SphereProbeFile(MeasurementKind):
    """Touch contacts on a reference sphere: ``|tip(q) - centre| = R + r``."""

    name = "sphere_probe"
    frames = {"tool": "tip", "sphere": "sphere"}
    sample_fields = {"sigma": "length", "group": "1"}
    columns_may_omit = frozenset({"group"})
    sample_hints = {"q_arm": " (use 'q')", "cov": " (give the contact-distance 'sigma')",
                    "p": " (a contact has no measured point)"}
    document_blocks = ("probe",)

    def read_block(self, name: str, value: Any, units: Units) -> Probe:
        """``probe``: ``{"stylus_radius": r}``, a length >= 0."""
        if value is None:
            raise FieldError((name,), 'required field missing ({"stylus_radius": r})')
        from hostpc.kinds.sphere_probe.probe_schema import ProbeSchema  # imports pydantic

        probe: ProbeSchema = schema.validate(ProbeSchema, value, (name,))
        if probe.stylus_radius < 0:
            raise FieldError((name, "stylus_radius"),
                             f"must be >= 0, got {show(probe.stylus_radius)}")
        return Probe(float(units.length(probe.stylus_radius)))

    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        q = require(sample, loc, "q")
        assert n_joints is not None
        check_joint_count((*loc, "q"), q, n_joints, robot_label)
        index = int(loc[1])
        columns.put("sigma", index, positive((*loc, "sigma"), require(sample, loc, "sigma")))
        if sample.group is not None:
            columns.put("group", index, sample.group)
        return list(q)

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        return KindArrays(sigma=units.length(columns.values["sigma"]))

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        if "sigma" not in table.names:
            return None
        sigma = table.numbers("sigma", list[float], ())
        if not np.all(sigma > 0):
            return None
        group = np.full(table.n_samples, -1, dtype=np.int64)
        rows = table.present("group")  # a group index (>= 0) where the sample has one
        values = [table.columns["group"][i] for i in rows]
        if not all(type(v) is int and 0 <= v < 2**31 for v in values):
            return None
        group[rows] = values
        return KindArrays(sigma=units.length(sigma), group=group)

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        out: JsonObject = {"q": samples.q[index].tolist()}
        if samples.sigma is not None:
            out["sigma"] = float(samples.sigma[index])
        if samples.group[index] >= 0:
            out["group"] = int(samples.group[index])
        return out, samples.q.shape[1]

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        fields: list[tuple[str, list[Any], list[bool] | None]] = [
            ("q", samples.q.tolist(), None)]
        if samples.sigma is not None:
            fields.append(("sigma", np.asarray(samples.sigma, dtype=float).tolist(), None))
        group = np.asarray(samples.group)
        fields.append(("group", group.astype(np.int64).tolist(), (group >= 0).tolist()))
        return WrittenColumns(fields, [samples.q.shape[1]] * samples.n)
