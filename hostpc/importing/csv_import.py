"""Turn a metrology CSV export into a ``zerocal-dataset/1`` document (world_point, world_pose).

Pure (no file writing): :func:`parse_column_map` (``hostpc.importing.column_map``, where the
``--columns`` syntax is described) reads the mapping against the header
(:func:`hostpc.importing.csv_table.read_csv`) and :func:`read_samples` reads the rows, one at
a time, into columns of SI values (m, rad), an
:class:`~hostpc.importing.imported.ImportedSamples`; memory grows by the numbers a row holds,
not by its text. Every bad input raises :class:`~hostpc.errors.InputError` with one line that
names the file, the row (the file's line number; the header is row 1) and the column: a
cell that is not a plain ASCII number (``_PLAIN_NUMBER``), or a value outside the dataset's
physical range (``hostpc.dataset.validation``, in SI). Rows that repeat an earlier row and
blank rows dropped between data rows are read, each kind said in one warning
(``ImportedSamples.warnings``).

A header may carry its unit in brackets or parentheses, ``x [mm]`` or ``q1 (deg)``; the
mapping names the column without it, and the header's unit overrides the default.

Decimal commas (``1,234`` in a file whose fields are separated by ``;`` or tabs, as European
tracker software writes): ``decimal="auto"`` reads them when the separator is not a comma
and the first data row writes a mapped number with a comma; ``","`` insists, ``"."`` never.
A file read with decimal commas must not also write decimal points.
"""

from __future__ import annotations

import math
import re
from array import array
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import chain
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hostpc.dataset.kind_registry import csv_row_shape
from hostpc.dataset.validation import (
    MAX_ABS_CONTEXT,
    MAX_ANGLE_RAD,
    MAX_POSITION_M,
    MAX_STD_M,
)
from hostpc.errors import InputError
from hostpc.fitting.folds import exact_repeats
from hostpc.importing.column_map import (
    ORIENTATIONS,
    ColumnMap,
    PointColumns,
)
from hostpc.importing.csv_table import CsvHeader, CsvRows, Row
from hostpc.importing.euler import euler_to_matrix, parse_euler
from hostpc.importing.imported import FloatArray, ImportedSamples
from hostpc.json_object import JsonObject
from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix

__all__ = [
    "LENGTH_UNITS", "ANGLE_UNITS", "DECIMALS", "ImportOptions", "document_head",
    "read_samples",
]


LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "in": 0.0254}
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3}
DECIMALS = ("auto", ".", ",")
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")
# a decimal comma becomes a point; a point becomes a character float() refuses
_FROM_DECIMAL_COMMA = str.maketrans({",": ".", ".": "!"})
_PLAIN_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
"""A number as a CSV cell may write it: ASCII digits, a sign, the decimal mark (a point
here: a decimal comma is translated first) and an exponent. Python's float() also takes
"1_000" and other scripts' digits ("٣"), which no metrology export writes."""


@dataclass(frozen=True)
class ImportOptions:
    """Everything of the output document that the CSV does not give.

    method: a kind that reads metrology CSV rows (``csv_rows``: world_point,
    world_pose); robot: the dataset's ``robot`` object;
    prismatic: per joint, True where the joint variable is a length;
    length_unit, angle_unit, joint_unit (revolute joints), prismatic_unit (prismatic joints;
    None: the length unit): defaults for columns whose header names no unit;
    sigma (length unit) and sigma_angle (angle unit): measurement noise; frames and known
    as in the dataset contract (SI); decimal: the decimal mark of the numbers ("auto",
    "." or ","); euler: the convention of the e1, e2, e3 columns (``SEQ-intrinsic`` or
    ``SEQ-extrinsic``, :mod:`hostpc.importing.euler`)."""

    method: str
    robot: Mapping[str, Any]
    prismatic: tuple[bool, ...]
    length_unit: str = "m"
    angle_unit: str = "rad"
    joint_unit: str = "rad"
    prismatic_unit: str | None = None  # None: length_unit
    sigma: float = 1e-4
    sigma_angle: float | None = None
    frames: Mapping[str, Any] = field(default_factory=dict)
    known: tuple[str, ...] = ()
    decimal: str = "."  # "auto", "." or ","
    euler: str | None = None  # "zyx-intrinsic" etc. for the e1, e2, e3 columns


def _unit_factor(unit: str, table: Mapping[str, float], what: str) -> float:
    try:
        return table[unit]
    except KeyError:
        raise InputError(f"unknown {what} unit {unit!r} (expected one of "
                         f"{', '.join(table)})") from None


class _Cells:
    """Reads typed values out of one CSV's rows, naming row and column in every error."""

    def __init__(self, header: CsvHeader, options: ImportOptions,
                 decimal_comma: bool = False) -> None:
        self.header = header
        self.options = options
        self.index = {name: k for k, name in enumerate(header.columns)}
        self.decimal_comma = decimal_comma

    def unit_of(self, column: str, kind: str) -> float:
        """SI factor of ``column``: its header unit, else the option's default."""
        default = {"length": self.options.length_unit, "angle": self.options.angle_unit,
                   "joint": self.options.joint_unit,
                   "prismatic": self.options.prismatic_unit or self.options.length_unit}[kind]
        unit = self.header.units.get(column, default)
        units = LENGTH_UNITS if kind in ("length", "prismatic") else ANGLE_UNITS
        if unit not in units and column in self.header.units:
            raise InputError(f"{self.header.source}: row 1, column {column!r}: unknown unit "
                             f"{unit!r} (expected one of {', '.join(units)})")
        return _unit_factor(unit, units, kind)

    def text(self, line: int, cells: tuple[str, ...], column: str) -> str:
        k = self.index[column]
        if k >= len(cells) or cells[k] == "":
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             "missing value")
        return cells[k]

    def number(self, line: int, cells: tuple[str, ...], column: str) -> float:
        raw = self.text(line, cells, column)
        plain = raw.translate(_FROM_DECIMAL_COMMA) if self.decimal_comma else raw
        try:
            value = float(plain)
        except ValueError:
            hint = (" (this file writes decimal commas, 1,5; a decimal point is ambiguous "
                    "here)" if self.decimal_comma and "." in raw else "")
            if (not self.decimal_comma and self.header.delimiter != ","
                    and _DECIMAL_COMMA.fullmatch(raw)):  # the first row had no decimals
                hint = (" (a decimal comma? the first row showed none, so the numbers were "
                        "read with a decimal point; give --decimal ,)")
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not a number{hint}") from None
        if not math.isfinite(value):
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not finite")
        if not _PLAIN_NUMBER.fullmatch(plain):
            mark = "," if self.decimal_comma else "."
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not a plain number (ASCII digits, a sign, "
                             f"'{mark}' and an exponent only)")
        return value

    def numbers(self, line: int, cells: tuple[str, ...], columns: Sequence[str],
                indices: Sequence[int]) -> list[float]:
        """The values of ``columns`` (at ``indices``) in one row: the plain conversion,
        and the checking one (which names the first bad cell) only when that fails. The
        fast path takes ASCII text without "_" only: then float() reads exactly the plain
        numbers and the non-finite words (``_PLAIN_NUMBER``)."""
        try:
            texts = [cells[k] for k in indices]
            joined = "".join(texts)
            if joined.isascii() and "_" not in joined:
                if self.decimal_comma:
                    values = [float(t.translate(_FROM_DECIMAL_COMMA)) for t in texts]
                else:
                    values = [float(t) for t in texts]
                if all(map(math.isfinite, values)):
                    return values
        except (ValueError, IndexError):
            pass
        return [self.number(line, cells, column) for column in columns]


def _rotations_to_rpy(values: FloatArray, orientation: str | None,
                      factors: FloatArray, euler: str | None) -> FloatArray:
    """roll/pitch/yaw (rad, (N, 3)) of the orientation columns ``values`` (N, 3 or 4)."""
    if orientation == "quat":
        w, x, y, z = values.T
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        R = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ], axis=1)
        return matrix_to_rpy(R)
    angles = values * factors
    if orientation == "rotvec":
        return matrix_to_rpy(rotvec_to_matrix(angles))
    if orientation == "euler":
        assert euler is not None  # _check_euler
        return matrix_to_rpy(euler_to_matrix(angles, parse_euler(euler)))
    return angles


def _check_euler(mapping: ColumnMap, options: ImportOptions) -> None:
    """e1, e2, e3 columns and ``--euler`` come together (the angles mean nothing alone)."""
    if options.euler is not None:
        parse_euler(options.euler)
        if mapping.orientation != "euler":
            raise InputError("--euler: its angles are the columns e1, e2, e3 in sequence "
                             "order; map them in --columns, e.g. e1=A,e2=B,e3=C")
    elif mapping.orientation == "euler":
        raise InputError("--columns: e1, e2, e3 are Euler angles; name their convention, "
                         "e.g. --euler zyx-intrinsic")


def _uses_decimal_comma(choice: str, header: CsvHeader, first: Row | None,
                        indices: Sequence[int]) -> bool:
    """Whether the numbers are written with a decimal comma (see the module docstring)."""
    if choice not in DECIMALS:
        raise InputError(f"--decimal: {choice!r} is not one of {', '.join(DECIMALS)}")
    if choice == "," and header.delimiter == ",":
        raise InputError(f"{header.source}: --decimal , but the fields are separated by "
                         "commas too; export with ';' or tabs between the fields")
    if choice != "auto":
        return choice == ","
    if header.delimiter == "," or first is None:
        return False
    cells = first[1]
    return any(k < len(cells) and _DECIMAL_COMMA.fullmatch(cells[k]) for k in indices)


def read_samples(csv_rows: CsvRows, mapping: ColumnMap, options: ImportOptions
                 ) -> ImportedSamples:
    """The rows of ``csv_rows`` read through ``mapping`` into SI columns, one row at a
    time (the numbers kept in a flat float64 buffer: about 8 bytes per mapped cell); a row
    with several reflectors (``marker.NAME=``) gives one sample per reflector it saw."""
    header = csv_rows.header
    fields = mapping.fields
    _check_euler(mapping, options)
    points = mapping.points or (PointColumns(
        xyz=(fields["x"], fields["y"], fields["z"]),
        sigma=(fields["sigma"],) if "sigma" in fields else ()),)
    several = points[0].marker is not None
    ndof = len(mapping.joints)
    world_pose = csv_row_shape(options.method) == "pose"
    orientation = ORIENTATIONS[mapping.orientation] if mapping.orientation and world_pose else ()
    optional = [k for k in ("t", "temperature") if k in fields]
    n_sigma = len(points[0].sigma)
    group_columns = [[*mapping.joints, *point.xyz, *point.sigma,
                      *(fields[k] for k in optional), *(fields[k] for k in orientation)]
                     for point in points]
    cells = _Cells(header, options)
    indices = [[cells.index[c] for c in columns] for columns in group_columns]
    rows = csv_rows.rows
    first = next(rows, None)
    cells.decimal_comma = _uses_decimal_comma(options.decimal, header, first,
                                              [k for group in indices for k in group])
    factors = np.array([
        [*(cells.unit_of(c, "prismatic" if prismatic else "joint")
           for c, prismatic in zip(mapping.joints, options.prismatic, strict=True)),
         *(cells.unit_of(c, "length") for c in (*point.xyz, *point.sigma)),
         *(1.0 for _ in optional),
         *(1.0 if mapping.orientation == "quat" else cells.unit_of(fields[k], "angle")
           for k in orientation)] for point in points])
    xyz_at = [group[ndof:ndof + 3] for group in indices]
    sigma_at = slice(ndof + 3, ndof + 3 + n_sigma)
    at = ndof + 3 + n_sigma + len(optional)  # the orientation's first value
    quat_at = at if mapping.orientation == "quat" else None
    marker_column = fields.get("marker") if csv_row_shape(options.method) == "point" else None
    width = len(header.columns)
    values = array("d")
    lines = array("q")  # the file line of each row of values
    marker_index = array("q")
    marker_ids: dict[str, int] = {p.marker: k for k, p in enumerate(points) if p.marker}
    mapped = sorted({k for group in indices for k in group}
                    | ({cells.index[marker_column]} if marker_column is not None else set()))
    for line, row in chain([first] if first is not None else [], rows):
        if len(row) > width:
            raise InputError(f"{header.source}: row {line}: {len(row)} cells but the header "
                             f"has {width} columns")
        if len(row) <= mapped[-1]:  # a line cut short: never read as a reflector not seen
            missing = [header.columns[k] for k in mapped if k >= len(row)]
            raise InputError(f"{header.source}: row {line}: {len(row)} cells but the header "
                             f"has {width} columns: no cell for {', '.join(missing)} (a line "
                             "cut short? complete it, or delete it)")
        for g, columns in enumerate(group_columns):
            if several and all(k >= len(row) or row[k] == "" for k in xyz_at[g]):
                continue  # this reflector was not seen in this pose
            numbers = cells.numbers(line, row, columns, indices[g])
            if n_sigma and min(numbers[sigma_at]) <= 0:
                bad = ndof + 3 + int(np.argmin(numbers[sigma_at]))
                raise InputError(f"{header.source}: row {line}, column {columns[bad]!r}: "
                                 "sigma must be positive")
            if quat_at is not None and math.sqrt(sum(v * v for v in numbers[quat_at:])) < 1e-9:
                raise InputError(f"{header.source}: row {line}, column {fields['qw']!r}: "
                                 "the quaternion is zero")
            values.extend(numbers)
            lines.append(line)
            if several:
                marker_index.append(g)
        if marker_column is not None:
            name = cells.text(line, row, marker_column)
            marker_index.append(marker_ids.setdefault(name, len(marker_ids)))
    if not values:
        raise InputError(f"{header.source}: no data rows below the header")
    table = np.frombuffer(values, dtype=np.float64).reshape(-1, len(group_columns[0]))
    group = (np.frombuffer(marker_index, dtype=np.int64)
             if marker_column is not None or several else None)
    if several:
        assert group is not None
        unseen = [p.marker for p, n in zip(points, np.bincount(group, minlength=len(points)),
                                           strict=True) if n == 0]
        if unseen:
            raise InputError(f"{header.source}: reflector {unseen[0]!r} is empty in every row; "
                             f"drop marker.{unseen[0]}= from --columns")
    si = table * (factors[group] if several else factors[0])
    row_lines = np.frombuffer(lines, dtype=np.int64)
    _check_ranges(header.source, table, si, row_lines, group_columns,
                  group if several else None, _ranges(options.prismatic, n_sigma, optional,
                                                      len(orientation), mapping.orientation))
    scaled = si[:, :at]
    sigmas = scaled[:, sigma_at]
    default_sigma = options.sigma * _unit_factor(options.length_unit, LENGTH_UNITS, "length")
    return ImportedSamples(
        method=options.method, source=header.source,
        q=scaled[:, :ndof], p=scaled[:, ndof:ndof + 3],
        sigma=(np.sqrt(np.mean(sigmas**2, axis=1)) if n_sigma else
               np.full(len(table), default_sigma)),
        sigma_xyz=sigmas if n_sigma == 3 else None,
        t=(_run_time(scaled[:, ndof + 3 + n_sigma + optional.index("t")])
           if "t" in optional else None),
        temperature=(scaled[:, ndof + 3 + n_sigma + optional.index("temperature")]
                     if "temperature" in optional else None),
        rpy=(_rotations_to_rpy(table[:, at:], mapping.orientation, factors[0, at:],
                               options.euler) if world_pose else None),
        sigma_angle=((1e-3 if options.sigma_angle is None else options.sigma_angle
                      * _unit_factor(options.angle_unit, ANGLE_UNITS, "angle"))
                     if world_pose else None),
        marker_index=group,
        marker_names=tuple(marker_ids),
        warnings=tuple(w for w in (_repeated_rows(header.source, table, group, row_lines),
                                   _blank_rows(header.source, csv_rows.blank,
                                               int(np.unique(row_lines).size)),
                                   _cut_last_row(header.source, csv_rows.cut))
                       if w is not None),
    )


def _ranges(prismatic: Sequence[bool], n_sigma: int, optional: Sequence[str],
            n_orientation: int, orientation: str | None) -> list[tuple[float, str]]:
    """(limit, unit) of each value of a row in SI: the dataset's physical ranges
    (hostpc.dataset.validation), so a number the fit would refuse is refused here with its
    row and column; the time (a clock time is taken from the earliest row) and a
    quaternion's components (normalised) are only bounded in size."""
    return [*((MAX_POSITION_M, "m") if p else (MAX_ANGLE_RAD, "rad") for p in prismatic),
            *[(MAX_POSITION_M, "m")] * 3, *[(MAX_STD_M, "m")] * n_sigma,
            *((math.inf, "s") if k == "t" else (MAX_ABS_CONTEXT, "") for k in optional),
            *[(MAX_ABS_CONTEXT, "") if orientation == "quat" else (MAX_ANGLE_RAD, "rad")]
            * n_orientation]


def _check_ranges(source: str, written: FloatArray, si: FloatArray,
                  lines: NDArray[np.int64], group_columns: Sequence[Sequence[str]],
                  group: NDArray[np.int64] | None, ranges: Sequence[tuple[float, str]]
                  ) -> None:
    """InputError naming the row and column of the first value outside its range.
    group_columns: the value columns' names per reflector group; group: each value row's
    group (None: the first for every row)."""
    limits = np.array([limit for limit, _ in ranges])
    bad = ~(np.abs(si) < limits)
    if not bad.any():
        return
    r, c = (int(i) for i in np.argwhere(bad)[0])
    names = group_columns[0 if group is None else int(group[r])]
    limit, unit = ranges[c]
    si_text = f"{si[r, c]:.6g} {unit}".rstrip()
    value = si_text if written[r, c] == si[r, c] else f"{written[r, c]:.6g} ({si_text})"
    raise InputError(f"{source}: row {int(lines[r])}, column {names[c]!r}: {value} is outside "
                     f"the physical range (|value| < {f'{limit:g} {unit}'.rstrip()})")


def _repeated_rows(source: str, table: FloatArray, group: NDArray[np.int64] | None,
                   lines: NDArray[np.int64]) -> str | None:
    """A warning if rows repeat an earlier row's every number (a copy, or a pose written
    twice: each counts as a measurement of its own)."""
    pairs = exact_repeats(table if group is None else np.column_stack([table, group]))
    repeats = sorted({(int(lines[k]), int(lines[e])) for k, e in pairs if lines[k] != lines[e]})
    if not repeats:
        return None
    shown = ", ".join(f"row {k} = row {e}" for k, e in repeats[:5])
    more = f", and {len(repeats) - 5} more" if len(repeats) > 5 else ""
    counted = "1 row repeats" if len(repeats) == 1 else f"{len(repeats)} rows repeat"
    return (f"{source}: {counted} an earlier row exactly ({shown}{more}): each counts as a "
            "measurement of its own; delete the copies if the pose was not measured again")


def _blank_rows(source: str, blank: Sequence[int], n_read: int) -> str | None:
    """A warning if blank rows between data rows were dropped (a pose not written?)."""
    if not blank:
        return None
    shown = ", ".join(str(k) for k in blank[:5]) + (", ..." if len(blank) > 5 else "")
    return (f"{source}: {len(blank)} blank row{'s' if len(blank) > 1 else ''} dropped "
            f"(row{'s' if len(blank) > 1 else ''} {shown}); {n_read} rows read")


def _cut_last_row(source: str, cut: Sequence[int]) -> str | None:
    """A warning if the file ends in a data row without a line end (copied while written)."""
    if not cut:
        return None
    return (f"{source}: row {cut[0]}, the last, has no line end: the file may have been cut "
            "while it was written, that row's last value with it; check it against the "
            "instrument, or delete the row")


def _run_time(t: FloatArray) -> FloatArray:
    """The `t=` column as a dataset's time (s since the start of the run): a clock time
    (Unix seconds, beyond the dataset's range of MAX_ABS_CONTEXT) is taken from the
    earliest row, any other time is kept as written."""
    return t - np.min(t) if t.size and np.max(np.abs(t)) > MAX_ABS_CONTEXT else t


def document_head(samples: ImportedSamples, options: ImportOptions) -> JsonObject:
    """The dataset document of ``samples`` without them (``"samples": []``, written by
    :func:`~hostpc.importing.imported.write_document`): format, method, units, robot,
    frames (``options.frames``; zero where it gives none), known."""
    all_frames = dict(options.frames)
    zero_pose = {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}
    all_frames.setdefault("world", zero_pose)
    if csv_row_shape(samples.method) == "pose":
        all_frames.setdefault("tool", dict(zero_pose))
    else:
        names = list(samples.marker_names) or ["marker"]
        all_frames.setdefault("markers", {name: [0.0, 0.0, 0.0] for name in names})
    return {
        "format": "zerocal-dataset/1",
        "method": samples.method,
        "units": {"length": "m", "angle": "rad", "time": "s"},
        "robot": dict(options.robot),
        "frames": all_frames,
        "known": list(options.known),
        "samples": [],
        "source": {"csv": samples.source, "rows": len(samples)},
    }
