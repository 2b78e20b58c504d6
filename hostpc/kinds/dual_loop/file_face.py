"""dual_loop's file face (shared/spec/dataset-format.md): a pan-tilt head camera observes a
target on each arm; extended by its model (``model.py``) with the prediction."""

from __future__ import annotations

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
)
from hostpc.dataset.model import Dataset, Samples
from hostpc.dataset.schema import FieldError, Loc
from hostpc.json_object import JsonObject
from hostpc.kinds.stereo_target.rig_block import check_rig_block


class DualLoopFile(PointSampleKind):
    """A pan-tilt head camera observes a target on each arm of a kinematic tree."""

    name = "dual_loop"
    frames = {"camera": "pose", "left_base": "pose", "right_base": "pose",
              "left_target": "point", "right_target": "point"}
    sample_fields = {"chain": "1", "q_head": "angle", "q_arm": "angle", "p": "length",
                     "cov": "area", "sigma": "length", "uv": "1"}
    sample_hints = {"q": " (dual_loop uses 'q_arm' and 'q_head')"}
    robot_tree = True

    def accepted_fields(self) -> frozenset[str]:
        return super().accepted_fields() - {"q"}

    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        chain = require(sample, loc, "chain", " ('left' or 'right')")
        q_head = require(sample, loc, "q_head")
        q = require(sample, loc, "q_arm")
        for name, values in (("q_head", q_head), ("q_arm", q)):
            if not values:
                raise FieldError((*loc, name), "expected at least one joint angle")
        index = int(loc[1])
        head_width, head_first = columns.first_width("head", len(q_head), index)
        check_joint_count((*loc, "q_head"), q_head, head_width,
                          f"the head (as in samples[{head_first}].q_head)")
        width, first = columns.first_width(chain, len(q), index)
        check_joint_count((*loc, "q_arm"), q, width,
                          f"chain '{chain}' (as in samples[{first}].q_arm)")
        columns.put("chain", index, chain)
        columns.put("q_head", index, q_head)
        self.read_point(sample, loc, columns, units)
        self.read_uv(sample, loc, columns)
        return list(q)

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        return replace(self.point_arguments(columns, units),
                       chain=np.asarray(columns.values["chain"], dtype=np.str_),
                       q_head=units.angle(columns.values["q_head"]))

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        """Every sample at once: one head width, one arm width per chain (else the samples
        are read one by one, which names the first that differs)."""
        from hostpc.dataset.reading_columns import point_columns

        if not {"chain", "q_head", "q_arm"} <= table.names:
            return None
        chain = np.asarray(table.strings("chain", ("left", "right")), dtype=np.str_)
        q_head = table.numbers("q_head", list[list[float]], (table.width("q_head"),))
        arms: list[tuple[np.ndarray, np.ndarray]] = []
        for name in ("left", "right"):
            rows = np.flatnonzero(chain == name)
            if rows.size:
                first = table.columns["q_arm"][rows[0]]
                width = len(first) if type(first) is list else -1  # -1: never the shape
                arms.append((rows, table.numbers("q_arm", list[list[float]], (width,), rows)))
        q = np.full((table.n_samples, max(arm.shape[1] for _, arm in arms)), np.nan)
        for rows, arm in arms:
            if arm.shape[1] == 0:
                return None
            q[rows, :arm.shape[1]] = arm
        return replace(point_columns(table, units), chain=chain, q_head=units.angle(q_head),
                       q=units.angle(q))

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        assert samples.chain is not None and samples.q_head is not None
        q_row = samples.q[index]
        q = q_row[~np.isnan(q_row)]
        out: JsonObject = {"chain": str(samples.chain[index]),
                           "q_head": samples.q_head[index].tolist(), "q_arm": q.tolist()}
        self.write_point(samples, index, out)
        return out, len(q)

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        assert samples.chain is not None and samples.q_head is not None
        measured = ~np.isnan(samples.q)
        q_arm = [[v for v, keep in zip(row, keeps, strict=True) if keep]
                 for row, keeps in zip(samples.q.tolist(), measured.tolist(), strict=True)]
        chain = [str(c) for c in samples.chain.tolist()]
        return WrittenColumns([("chain", chain, None), ("q_head", samples.q_head.tolist(), None),
                               ("q_arm", q_arm, None), *point_columns_out(samples)],
                              measured.sum(axis=1).tolist())

    def check_loaded(self, dataset: Dataset, source: str) -> None:
        check_rig_block(dataset, source)
