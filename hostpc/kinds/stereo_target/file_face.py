"""The file faces of the built-in measurement kinds (shared/spec/dataset-format.md).

Each is extended by its model in ``hostpc.model.measurements`` (the prediction); they live
here so that a dataset file loads without the fitting layer.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.kind import (
    Columns,
    MeasurementKind,
    WrittenColumns,
    check_joint_count,
    point_columns_out,
    positive,
    read_point_covariance,
    require,
)
from hostpc.dataset.model import Samples
from hostpc.dataset.schema import FieldError, Loc
from hostpc.dataset.units import Units


class PointSampleKind(MeasurementKind):
    """Samples that measure a 3-D point ``p`` with its covariance ``cov`` (or ``sigma``)."""

    def read_point(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                   units: Units) -> None:
        index = int(loc[1])
        columns.put("p", index, require(sample, loc, "p"))
        columns.put("cov", index, read_point_covariance(sample, loc, units))

    def read_uv(self, sample: schema.SampleSchema, loc: Loc, columns: Columns) -> None:
        if sample.uv is not None:
            columns.put("uv", int(loc[1]), sample.uv)

    def point_arguments(self, columns: Columns, units: Units) -> dict[str, Any]:
        uv = None
        if columns.given("uv"):
            uv = np.full((columns.n_samples, 2, 2), np.nan)
            for i, value in enumerate(columns.values["uv"]):
                if value is not None:
                    uv[i] = value
        return {"p": units.length(columns.values["p"]),
                "cov": np.asarray(columns.values["cov"]), "uv": uv}

    def write_point(self, samples: Samples, index: int, out: dict[str, Any]) -> None:
        if samples.p is not None:
            out["p"] = samples.p[index].tolist()
        if samples.cov is not None:
            out["cov"] = samples.cov[index].tolist()


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

    def samples_arguments(self, columns: Columns, units: Units) -> dict[str, Any]:
        return self.point_arguments(columns, units)

    def read_columns(self, table: Any, units: Units) -> dict[str, Any] | None:
        from hostpc.dataset.reading_columns import point_columns

        return dict(point_columns(table, units))

    def write_sample(self, samples: Samples, index: int) -> tuple[dict[str, Any], int]:
        out: dict[str, Any] = {"q": samples.q[index].tolist()}
        self.write_point(samples, index, out)
        return out, samples.q.shape[1]

    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        return WrittenColumns([("q", samples.q.tolist(), None), *point_columns_out(samples)],
                              [samples.q.shape[1]] * samples.n)


class SphereProbeFile(MeasurementKind):
    """Touch contacts on a reference sphere: ``|tip(q) - centre| = R + r``."""

    name = "sphere_probe"
    frames = {"tool": "tip", "sphere": "sphere"}
    sample_fields = {"sigma": "length", "group": "1"}
    columns_may_omit = frozenset({"group"})
    sample_hints = {"q_arm": " (use 'q')", "cov": " (give the contact-distance 'sigma')",
                    "p": " (a contact has no measured point)"}
    uses_probe = True

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

    def samples_arguments(self, columns: Columns, units: Units) -> dict[str, Any]:
        return {"sigma": units.length(columns.values["sigma"])}

    def read_columns(self, table: Any, units: Units) -> dict[str, Any] | None:
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
        return {"sigma": units.length(sigma), "group": group}

    def write_sample(self, samples: Samples, index: int) -> tuple[dict[str, Any], int]:
        out: dict[str, Any] = {"q": samples.q[index].tolist()}
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
        widths: dict[str, tuple[int, int]] = columns.state.setdefault("widths", {})
        head_width, head_first = widths.setdefault("head", (len(q_head), index))
        check_joint_count((*loc, "q_head"), q_head, head_width,
                          f"the head (as in samples[{head_first}].q_head)")
        width, first = widths.setdefault(chain, (len(q), index))
        check_joint_count((*loc, "q_arm"), q, width,
                          f"chain '{chain}' (as in samples[{first}].q_arm)")
        columns.put("chain", index, chain)
        columns.put("q_head", index, q_head)
        self.read_point(sample, loc, columns, units)
        self.read_uv(sample, loc, columns)
        return list(q)

    def samples_arguments(self, columns: Columns, units: Units) -> dict[str, Any]:
        return {**self.point_arguments(columns, units),
                "chain": np.asarray(columns.values["chain"], dtype=np.str_),
                "q_head": units.angle(columns.values["q_head"])}

    def read_columns(self, table: Any, units: Units) -> dict[str, Any] | None:
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
        return {**point_columns(table, units), "chain": chain,
                "q_head": units.angle(q_head), "q": units.angle(q)}

    def write_sample(self, samples: Samples, index: int) -> tuple[dict[str, Any], int]:
        assert samples.chain is not None and samples.q_head is not None
        q_row = samples.q[index]
        q = q_row[~np.isnan(q_row)]
        out: dict[str, Any] = {"chain": str(samples.chain[index]),
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
