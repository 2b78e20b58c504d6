"""The fast path of reading samples: validate whole columns, not sample dicts one by one.

A fleet's dataset holds 10^5 samples of the same shape. Checking each sample as a pydantic
model and a covariance at a time costs ~50x a bare ``json.load``; this module checks each
field as one array instead (types by pydantic on the whole column, shapes, finiteness,
symmetry and positive definiteness by numpy on the stack).

The fast path is conservative: it accepts only a file whose samples are plain JSON objects
with one and the same set of fields, all of them plain numbers, and whose every check
passes. On anything else (a missing or unknown field, a wrong shape, a non-finite number, a
covariance that fails a check, a kind without a column reader) it returns ``None``, and
``reading_samples`` reads the file sample by sample, which finds the first offending sample
and names its index and field exactly as before. Both paths give identical arrays
(tests/hostpc/test_dataset_columns.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.file_units import Units
from hostpc.dataset.measurement_kind import KindArrays, MeasurementKind
from hostpc.dataset.model import FloatArray, Samples

_SYMMETRY_TOLERANCE = 1e-6  # as hostpc.dataset.measurement_kind.check_covariance
_MAX_GROUP = 2**31


_ABSENT = object()  # a field a sample leaves out (SampleTable.partial)


class NotColumnar(Exception):
    """The samples need the sample-by-sample reader (which names the offending sample)."""


class SampleTable:
    """The samples of a document as columns of raw JSON values, one list per field."""

    def __init__(self, samples: list[Any], may_omit: frozenset[str] = frozenset()) -> None:
        """may_omit: fields that some samples may leave out (``partial``; a kind's
        ``columns_may_omit``); any other field must be in every sample or in none."""
        if not samples or not all(type(sample) is dict for sample in samples):
            raise NotColumnar
        names = frozenset(samples[0])
        self.partial: frozenset[str] = frozenset()
        if any(len(sample) != len(names) or sample.keys() != names for sample in samples):
            some = frozenset().union(*samples)
            required = some - may_omit
            if not all(sample.keys() >= required for sample in samples):
                raise NotColumnar  # fields vary between samples: read them one by one
            every = required | {name for name in some & may_omit
                                if all(name in sample for sample in samples)}
            names, self.partial = every, some - every
        self.n_samples = len(samples)
        self.names = names
        self.columns: dict[str, list[Any]] = {
            name: [sample[name] for sample in samples] for name in names}
        for name in self.partial:
            self.columns[name] = [sample.get(name, _ABSENT) for sample in samples]

    def present(self, name: str) -> np.ndarray:
        """Indices of the samples that give field ``name``."""
        if name in self.names:
            return np.arange(self.n_samples)
        if name not in self.partial:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero([v is not _ABSENT for v in self.columns[name]])

    def numbers(self, name: str, kind: Any, shape: tuple[int, ...],
                rows: np.ndarray | None = None) -> FloatArray:
        """Field ``name`` of every sample (or of the samples ``rows``) as one float array of
        shape (N, *shape); strict JSON numbers (no bools, no strings), finite."""
        column = self.columns[name]
        if rows is not None:
            column = [column[i] for i in rows]
        try:
            values = schema.validate(kind, column)
        except schema.FieldError:
            raise NotColumnar from None
        try:
            array = np.asarray(values, dtype=np.float64)
        except ValueError:  # ragged rows
            raise NotColumnar from None
        if array.shape != (len(column), *shape) or not np.all(np.isfinite(array)):
            raise NotColumnar
        return array

    def width(self, name: str) -> int:
        """The length of field ``name``'s list in the first sample (at least 1)."""
        first = self.columns[name][0]
        if type(first) is not list or not first:
            raise NotColumnar
        return len(first)

    def strings(self, name: str, allowed: tuple[str, ...] | None = None) -> list[str]:
        """Field ``name`` of every sample: JSON strings (of ``allowed``, if given)."""
        column = self.columns[name]
        if not all(type(v) is str for v in column):
            raise NotColumnar
        if allowed is not None and not set(column) <= set(allowed):
            raise NotColumnar
        return column


def finite(array: FloatArray) -> FloatArray:
    """``array`` if every value is finite (after a unit conversion), else NotColumnar."""
    if not np.all(np.isfinite(array)):
        raise NotColumnar
    return array


def checked_covariances(cov: FloatArray) -> FloatArray:
    """(N, k, k) covariances in SI: finite, symmetric and positive definite, all of them."""
    finite(cov)
    scale = np.max(np.abs(cov), axis=(1, 2))
    asymmetry = np.max(np.abs(cov - np.swapaxes(cov, 1, 2)), axis=(1, 2))
    if np.any(asymmetry > _SYMMETRY_TOLERANCE * scale):
        raise NotColumnar
    try:
        lower = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise NotColumnar from None
    if not (np.all(np.isfinite(lower)) and np.all(np.diagonal(lower, axis1=1, axis2=2) > 0)):
        raise NotColumnar
    return cov


def read_columns(samples: list[Any], kind: MeasurementKind, n_joints: int | None,
                 units: Units) -> Samples | None:
    """The samples as ``Samples`` (SI), or None when they need the sample-by-sample reader.

    Reads the context fields every kind shares (t, temperature, speed, approach; ``extra``
    sends the file to the slow path; ``group`` is the kind's) and asks the kind for its own columns
    (``MeasurementKind.read_columns``). The joint angles are ``q`` (n_joints each), or the
    kind's ``q`` (SI, NaN-padded rows: a kinematic tree's arms)."""
    if not _reads_columns(type(kind)):
        return None
    try:
        table = SampleTable(samples, kind.columns_may_omit)
        allowed = kind.accepted_fields()
        if not table.names | table.partial <= allowed or "extra" in table.names:
            raise NotColumnar
        own = kind.read_columns(table, units)
        if own is None:
            raise NotColumnar
        q = own.q
        if q is None:
            if n_joints is None or "q" not in table.names:
                raise NotColumnar
            q = units.angle(table.numbers("q", list[list[float]], (n_joints,)))
        n_joints = int(q.shape[1])
        nan = np.full(table.n_samples, np.nan)
        context: dict[str, FloatArray] = {}
        for name, convert in (("t", units.time), ("temperature", np.asarray),
                              ("speed", units.speed)):
            context[name] = (np.asarray(convert(table.numbers(name, list[float], ())),
                                        dtype=np.float64)
                             if name in table.names else nan)
        if np.any(np.isinf(context["speed"])):
            raise NotColumnar
        approach = np.full((table.n_samples, n_joints), np.nan)
        if "approach" in table.names:
            if np.any(np.isnan(q)):  # rows of different lengths: one by one
                raise NotColumnar
            approach = table.numbers("approach", list[list[float]], (n_joints,))
            if not np.all(np.abs(approach) == 1.0):
                raise NotColumnar
        group = own.group if own.group is not None else np.full(table.n_samples, -1,
                                                                     dtype=np.int64)
        return own.samples(q, t=context["t"], temperature=context["temperature"],
                           speed=context["speed"], approach=approach, group=group, extra={})
    except NotColumnar:
        return None


def _owner(cls: type, name: str) -> type:
    """The class in ``cls``'s MRO that defines attribute ``name``."""
    return next(base for base in cls.__mro__ if name in vars(base))


def _reads_columns(cls: type[MeasurementKind]) -> bool:
    """The kind's column reader is its own: defined by the class that defines its sample
    reader (a subclass overriding ``read_sample`` or ``samples_arguments`` alone goes the
    slow way, so that its own checks run)."""
    owner = _owner(cls, "read_columns")
    return (owner is not MeasurementKind and owner is _owner(cls, "read_sample")
            and issubclass(owner, _owner(cls, "samples_arguments"))
            and issubclass(owner, _owner(cls, "check_samples")))


def point_columns(table: SampleTable, units: Units) -> KindArrays:
    """``p`` (length), ``cov`` (area) or ``sigma`` (length), ``uv`` of every sample, SI."""
    if "p" not in table.names or ("cov" in table.names) == ("sigma" in table.names):
        raise NotColumnar
    p = table.numbers("p", list[list[float]], (3,))
    if "cov" in table.names:
        cov = np.asarray(units.area(table.numbers("cov", list[list[list[float]]], (3, 3))),
                         dtype=np.float64)
    else:
        sigma_file = table.numbers("sigma", list[float], ())
        if not np.all(sigma_file > 0):
            raise NotColumnar
        sigma = np.asarray(units.length(sigma_file), dtype=np.float64)
        variance = sigma * sigma
        if not np.all((variance > 0) & (variance < np.inf)):
            raise NotColumnar
        cov = variance[:, None, None] * np.eye(3)
    uv = (table.numbers("uv", list[list[list[float]]], (2, 2))
          if "uv" in table.names else None)
    return KindArrays(p=units.length(p), cov=checked_covariances(cov), uv=uv)
