"""The file face of a measurement model: what a method's dataset file holds.

A measurement kind (``stereo_target``, ``sphere_probe``, ``dual_loop``, a user's own) says
which frames its file carries and of what kind, which sample fields it accepts, how one
sample is read and checked, and how it is written back. The dataset layer never branches on
a method's name: it asks the kind. ``hostpc.model.measurements.MeasurementModel`` extends
this class with the prediction; a plugin writes one class that does both.

A kind with only plain numeric sample fields is declarative: list them in
``sample_fields`` (name -> unit kind: ``"length"``, ``"angle"``, ``"area"``, ``"time"`` or
``"1"``), name the optional ones in ``optional_fields``, and the defaults read, check and
write them into ``Samples.fields`` (each (N,) or (N, k), NaN where an optional one is absent).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.model import (
    Dataset,
    FloatArray,
    Frame,
    IntArray,
    KindBlock,
    Samples,
    StrArray,
)
from hostpc.dataset.schema import FieldError, Loc, show
from hostpc.json_object import JsonObject

#: per-sample context fields every kind accepts (read and written by the dataset layer)
CONTEXT_FIELDS = frozenset({"t", "approach", "temperature", "speed", "extra"})
#: frame kinds the dataset layer reads: a pose (xyz + rpy), a tip (xyz, rpy optional), a
#: point, a sphere (centre + radius), named points ({"NAME": [x, y, z]}), or a plain JSON
#: object kept as given (the stereo camera model)
FRAME_KINDS = ("pose", "tip", "point", "sphere", "points", "camera_model")
_SYMMETRY_TOLERANCE = 1e-6  # relative to the largest entry of the matrix


class Columns:
    """Per-sample values gathered into arrays (NaN / -1 where absent)."""

    def __init__(self, n_samples: int) -> None:
        self.n_samples = n_samples
        self.values: dict[str, list[Any]] = {}
        self._widths: dict[str, tuple[int, int]] = {}

    def first_width(self, key: str, width: int, index: int) -> tuple[int, int]:
        """The row width of group ``key`` and the sample that set it: the first sample to
        ask (``width`` and ``index`` if none did). A kind checks with it that the rows of one
        group (dual_loop: the head, each arm) have one length."""
        return self._widths.setdefault(key, (width, index))

    def put(self, name: str, index: int, value: Any) -> None:
        column = self.values.get(name)
        if column is None:  # not setdefault: that would build an N-list on every call
            column = self.values[name] = [None] * self.n_samples
        column[index] = value

    def given(self, name: str) -> bool:
        return name in self.values

    def floats(self, name: str, convert: Callable[[Any], FloatArray]) -> FloatArray:
        column = self.values.get(name, [None] * self.n_samples)
        return convert([np.nan if v is None else v for v in column])

    def rows(self, name: str, width: int) -> FloatArray:
        """Rows of possibly different length, NaN-padded to ``width``."""
        out = np.full((self.n_samples, width), np.nan)
        for i, row in enumerate(self.values.get(name, [])):
            if row is not None:
                out[i, : len(row)] = row
        return out


@dataclass(frozen=True)
class KindArrays:
    """A kind's own arrays of every sample, SI (the ``Samples`` fields besides ``q`` and the
    context the dataset layer reads): what ``samples_arguments`` and ``read_columns`` give.

    q: the joint angles where the kind reads them itself (a kinematic tree's arms,
    NaN-padded rows), else None; group: the probe groups where the kind's column reader read
    them, else None (the dataset layer reads them); the others as in ``Samples``."""

    p: FloatArray | None = None
    cov: FloatArray | None = None
    sigma: FloatArray | None = None
    uv: FloatArray | None = None
    chain: StrArray | None = None
    q_head: FloatArray | None = None
    fields: Mapping[str, NDArray[Any]] = field(default_factory=dict)
    q: FloatArray | None = None
    group: IntArray | None = None

    def samples(self, q: FloatArray, *, t: FloatArray, temperature: FloatArray,
                speed: FloatArray, approach: FloatArray, group: IntArray,
                extra: Mapping[str, FloatArray]) -> Samples:
        """The ``Samples`` of these arrays with the joint angles and the shared context."""
        return Samples(q=q, p=self.p, cov=self.cov, sigma=self.sigma, t=t,
                       temperature=temperature, speed=speed, approach=approach, group=group,
                       extra=extra, uv=self.uv, chain=self.chain, q_head=self.q_head,
                       fields=self.fields)


def require(sample: schema.SampleSchema, loc: Loc, name: str, hint: str = "") -> Any:
    """The value of a sample field, or FieldError "required field missing"."""
    value = sample_value(sample, name)
    if value is None:
        raise FieldError((*loc, name), "required field missing" + hint)
    return value


def sample_value(sample: schema.SampleSchema, name: str) -> Any:
    """A sample field by name: a declared schema field or a plugin's (extra) field."""
    if name in schema.SAMPLE_FIELDS:
        return getattr(sample, name)
    return (sample.model_extra or {}).get(name)


def check_joint_count(loc: Loc, values: list[float], n: int, label: str) -> None:
    if len(values) != n:
        raise FieldError(loc, f"expected {n} joint angles for {label}, got {len(values)}")


def check_covariance(loc: Loc, cov: FloatArray) -> None:
    """Square covariance in SI: finite, symmetric, positive definite."""
    if not np.all(np.isfinite(cov)):
        raise FieldError(loc, "out of range after unit conversion")
    scale = float(np.max(np.abs(cov)))
    if float(np.max(np.abs(cov - cov.T))) > _SYMMETRY_TOLERANCE * scale:
        raise FieldError(loc, "not symmetric")
    try:
        lower = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise FieldError(loc, "not positive definite") from None
    if not (np.all(np.isfinite(lower)) and np.all(np.diag(lower) > 0)):
        raise FieldError(loc, "not positive definite")


def positive(loc: Loc, value: float) -> float:
    if not value > 0:
        raise FieldError(loc, f"must be positive, got {show(value)}")
    return value


def read_point_covariance(sample: schema.SampleSchema, loc: Loc, units: Units) -> FloatArray:
    """A 3-D point's covariance from ``cov`` (length^2) or ``sigma`` (length), checked, m^2."""
    if sample.cov is not None and sample.sigma is not None:
        raise FieldError((*loc, "sigma"), "give either 'cov' or 'sigma', not both")
    if sample.cov is not None:
        if len(sample.cov) != 3:
            raise FieldError((*loc, "cov"), "expected a 3x3 matrix (3 lists of 3 numbers), "
                             f"got a {len(sample.cov)}x{len(sample.cov)} matrix")
        cov = units.area(sample.cov)
    elif sample.sigma is not None:
        sigma_m = float(units.length(positive((*loc, "sigma"), sample.sigma)))
        variance = sigma_m * sigma_m  # float product: inf on overflow, no exception
        if not 0 < variance < np.inf:
            raise FieldError((*loc, "sigma"), f"out of range, got {show(sample.sigma)}")
        cov = variance * np.eye(3)
    else:
        raise FieldError((*loc, "cov"), "required field missing (or give 'sigma')")
    check_covariance((*loc, "cov" if sample.cov is not None else "sigma"), cov)
    return np.asarray(cov, dtype=float)


def convert(units: Units, unit: str, value: Any) -> FloatArray:
    """A file value in the unit kind ``unit`` -> SI."""
    converters: dict[str, Callable[[Any], FloatArray]] = {
        "length": units.length, "angle": units.angle, "area": units.area,
        "time": units.time, "speed": units.speed, "1": np.asarray,
    }
    return np.asarray(converters[unit](value), dtype=np.float64)


class MeasurementKind:
    """Base class of a measurement kind's file face (see the module docstring).

    Class attributes a kind sets: ``name``; ``frames`` (frame name -> kind, one of
    ``FRAME_KINDS``); ``optional_frames``; ``sample_fields`` (name -> unit kind; ``q`` is
    implied); ``optional_fields``; ``sample_hints`` (field -> hint appended to "not a
    field of method"); ``document_blocks`` (top-level fields of the document the kind reads
    itself, ``read_block``: sphere_probe's ``probe``); ``robot_tree``
    (the robot is a built-in kinematic tree by name; samples give the joint counts).
    """

    name: ClassVar[str]
    description: ClassVar[str] = ""
    frames: ClassVar[Mapping[str, str]] = {}
    optional_frames: ClassVar[frozenset[str]] = frozenset()
    sample_fields: ClassVar[Mapping[str, str]] = {}
    optional_fields: ClassVar[frozenset[str]] = frozenset()
    sample_hints: ClassVar[Mapping[str, str]] = {}
    document_blocks: ClassVar[tuple[str, ...]] = ()
    robot_tree: ClassVar[bool] = False
    #: optional fields some samples of a regular file leave out (its column reader reads
    #: them at ``SampleTable.present``); any other field varying sends the file to the
    #: sample-by-sample reader
    columns_may_omit: ClassVar[frozenset[str]] = frozenset()

    def accepted_fields(self) -> frozenset[str]:
        """Every sample field this kind accepts (its own, ``q`` and the context fields)."""
        return frozenset(self.sample_fields) | {"q"} | CONTEXT_FIELDS

    # reading ------------------------------------------------------------------------
    def read_sample(self, sample: schema.SampleSchema, loc: Loc, columns: Columns,
                    n_joints: int | None, robot_label: str, units: Units) -> list[float]:
        """Check one sample's own fields, put them in ``columns``; return its joint angles
        (file units). The default reads ``q`` and every field of ``sample_fields``."""
        q = require(sample, loc, "q")
        assert n_joints is not None
        check_joint_count((*loc, "q"), q, n_joints, robot_label)
        for name, unit in self.sample_fields.items():
            value = sample_value(sample, name)
            if value is None:
                if name in self.optional_fields:
                    continue
                raise FieldError((*loc, name), "required field missing")
            kind: Any = float | list[float] | list[list[float]]
            number = convert(units, unit, schema.validate(kind, value, (*loc, name)))
            if not np.all(np.isfinite(number)):
                raise FieldError((*loc, name), "out of range after unit conversion")
            columns.put(f"field.{name}", sample_index(loc), number)
        return list(q)

    def read_columns(self, table: Any, units: Units) -> KindArrays | None:
        """The fast path (``hostpc.dataset.reading_columns``): ``samples_arguments`` for
        every sample at once from ``table`` (a ``SampleTable``: one list per field), or None
        to have the samples read one by one. Raise ``reading_columns.NotColumnar`` where a
        check fails (the slow path then names the sample). Default: None."""
        return None

    def samples_arguments(self, columns: Columns, units: Units) -> KindArrays:
        """This kind's arrays of every sample (besides q and the context), SI. The default
        gives ``fields``: each declared field stacked, NaN where absent."""
        fields: dict[str, FloatArray] = {}
        for name in self.sample_fields:
            column = columns.values.get(f"field.{name}")
            if column is None:
                continue
            shape = next(np.shape(v) for v in column if v is not None)
            for i, v in enumerate(column):
                if v is not None and np.shape(v) != shape:
                    raise FieldError(("samples", i, name),
                                     f"expected shape {shape} as the other samples")
            fields[name] = np.stack([np.full(shape, np.nan) if v is None else v
                                     for v in column])
        return KindArrays(fields=fields)

    def check_samples(self, samples: Samples, frames: Mapping[str, Frame]) -> None:
        """Checks across samples and against the frames (after reading); raise FieldError.
        Default: none."""

    def read_block(self, name: str, value: Any, units: Units) -> KindBlock | None:
        """The kind's top-level block ``name`` (one of ``document_blocks``) from the file's
        JSON ``value`` (None: absent), SI; None to leave it out; raise FieldError."""
        return None

    def check_loaded(self, dataset: Dataset, source: str) -> None:
        """Checks of the kind's own top-level blocks (``dataset.extra_fields``) once the
        dataset is read, e.g. the stereo kinds' ``rig_uncertainty``; raise DatasetError
        ``source: field: ...``. Default: none."""

    # writing ------------------------------------------------------------------------
    def write_columns(self, samples: Samples) -> WrittenColumns | None:
        """The fast path of writing: what ``write_sample`` gives, for every sample at once
        (``WrittenColumns``), or None to write sample by sample. Used only where the class
        that defines it also defines ``write_sample``. The default does what the default
        ``write_sample`` does."""
        q = samples.q.tolist()
        fields: list[tuple[str, list[Any], list[bool] | None]] = [("q", q, None)]
        for name in self.sample_fields:
            if name not in samples.fields:
                continue
            values = np.asarray(samples.fields[name])
            finite = np.isfinite(values).reshape(values.shape[0], -1).all(axis=1)
            fields.append((name, values.tolist(), finite.tolist()))
        return WrittenColumns(fields, [samples.q.shape[1]] * samples.n)

    def write_sample(self, samples: Samples, index: int) -> tuple[JsonObject, int]:
        """This kind's fields of sample ``index`` as JSON (SI), and its joint count. The
        context fields (t, approach, ...) are written by the dataset layer after these."""
        q = samples.q[index]
        out: JsonObject = {"q": q.tolist()}
        for name in self.sample_fields:
            if name not in samples.fields:
                continue
            value = np.asarray(samples.fields[name][index])
            if np.all(np.isfinite(value)):
                out[name] = value.tolist()
        return out, len(q)


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

    def point_arguments(self, columns: Columns, units: Units) -> KindArrays:
        uv = None
        if columns.given("uv"):
            uv = np.full((columns.n_samples, 2, 2), np.nan)
            for i, value in enumerate(columns.values["uv"]):
                if value is not None:
                    uv[i] = value
        return KindArrays(p=units.length(columns.values["p"]),
                          cov=np.asarray(columns.values["cov"]), uv=uv)

    def write_point(self, samples: Samples, index: int, out: JsonObject) -> None:
        if samples.p is not None:
            out["p"] = samples.p[index].tolist()
        if samples.cov is not None:
            out["cov"] = samples.cov[index].tolist()


class WrittenColumns:
    """A kind's fields of every sample as JSON columns, in the order ``write_sample`` writes
    them: (name, values (an N-list), written (an N-list of bool) or None: every sample);
    and each sample's joint count (an N-list)."""

    def __init__(self, fields: list[tuple[str, list[Any], list[bool] | None]],
                 n_joints: list[int]) -> None:
        self.fields = fields
        self.n_joints = n_joints

    def sample(self, index: int) -> JsonObject:
        """Sample ``index`` as ``write_sample`` gives it."""
        return {name: values[index] for name, values, written in self.fields
                if written is None or written[index]}


def point_columns_out(samples: Samples) -> list[tuple[str, list[Any], list[bool] | None]]:
    """``p`` and ``cov`` of every sample (as ``PointSampleKind.write_point``)."""
    out: list[tuple[str, list[Any], list[bool] | None]] = []
    if samples.p is not None:
        out.append(("p", samples.p.tolist(), None))
    if samples.cov is not None:
        out.append(("cov", samples.cov.tolist(), None))
    return out


def sample_index(loc: Loc) -> int:
    """The sample index of a location ``("samples", i, ...)``."""
    index = loc[1]
    assert isinstance(index, int)
    return index


def kinds_by_name(classes: Iterable[type[MeasurementKind]]) -> dict[str, type[MeasurementKind]]:
    return {cls.name: cls for cls in classes}
