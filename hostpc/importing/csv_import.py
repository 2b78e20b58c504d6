"""Turn a metrology CSV export into a ``zerocal-dataset/1`` document (world_point, world_pose).

Pure (no file writing): :func:`parse_column_map` reads the ``--columns`` mapping against the
header (:func:`hostpc.importing.csv_table.read_csv`) and :func:`read_samples` reads the rows,
one at a time, into columns of SI values (m, rad), an
:class:`~hostpc.importing.imported.ImportedSamples`; memory grows by the numbers a row holds,
not by its text. Every bad input raises :class:`~hostpc.errors.InputError` with one line that
names the file, the row (the file's line number; the header is row 1) and the column.

Column mapping (``--columns``), comma-separated ``KEY=COLUMN`` pairs:

- joints: ``q1=COL, q2=COL, ...`` or a header range ``q=FIRST:LAST`` (consecutive columns);
- position in the world frame: ``x=COL, y=COL, z=COL``;
- world_pose orientation: ``roll=, pitch=, yaw=`` (R = Rz(yaw) Ry(pitch) Rx(roll)), or a
  quaternion ``qw=, qx=, qy=, qz=``, or a rotation vector ``rx=, ry=, rz=``;
- optional: ``marker=COL`` (world_point marker id), ``t=COL`` (time, s), ``sigma=COL``
  (per-row position sigma in the length unit).

A header may carry its unit in brackets or parentheses, ``x [mm]`` or ``q1 (deg)``; the
mapping names the column without it, and the header's unit overrides the default.
"""

from __future__ import annotations

import math
import re
from array import array
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.importing.csv_table import CsvHeader, CsvRows
from hostpc.importing.imported import FloatArray, ImportedSamples
from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix

__all__ = [
    "LENGTH_UNITS", "ANGLE_UNITS", "ColumnMap", "ImportOptions", "document_head",
    "parse_column_map", "read_samples",
]


LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "in": 0.0254}
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3}
_ORIENTATIONS = {"rpy": ("roll", "pitch", "yaw"), "quat": ("qw", "qx", "qy", "qz"),
                 "rotvec": ("rx", "ry", "rz")}
_SINGLE_KEYS = {"x", "y", "z", "marker", "t", "sigma"} | {
    k for keys in _ORIENTATIONS.values() for k in keys}


@dataclass(frozen=True)
class ColumnMap:
    """Which CSV column holds what: ``joints`` in joint order, ``fields`` by key."""

    joints: tuple[str, ...]
    fields: Mapping[str, str]
    orientation: str | None  # "rpy", "quat", "rotvec" or None


@dataclass(frozen=True)
class ImportOptions:
    """Everything of the output document that the CSV does not give.

    method: "world_point" or "world_pose"; robot: the dataset's ``robot`` object;
    prismatic: per joint, True where the joint variable is a length;
    length_unit, angle_unit, joint_unit: defaults for columns whose header names no unit;
    sigma (length unit) and sigma_angle (angle unit): measurement noise; frames and known
    as in the dataset contract (SI)."""

    method: str
    robot: Mapping[str, Any]
    prismatic: tuple[bool, ...]
    length_unit: str = "m"
    angle_unit: str = "rad"
    joint_unit: str = "rad"
    sigma: float = 1e-4
    sigma_angle: float | None = None
    frames: Mapping[str, Any] = field(default_factory=dict)
    known: tuple[str, ...] = ()


def _unit_factor(unit: str, table: Mapping[str, float], what: str) -> float:
    try:
        return table[unit]
    except KeyError:
        raise InputError(f"unknown {what} unit {unit!r} (expected one of "
                         f"{', '.join(table)})") from None


def parse_column_map(spec: str, header: Sequence[str], n_joints: int, method: str,
                     source: str = "CSV") -> ColumnMap:
    """Parse ``--columns`` against the CSV header; InputError naming the offending pair."""
    joints: dict[int, str] = {}
    fields: dict[str, str] = {}
    given: dict[str, str] = {}  # key -> the pair that gave it (q=A:B gives q1..qN)

    def claim(key: str, raw: str) -> None:
        if key in given:
            raise InputError(f"--columns: {key} is given twice ({given[key]!r} and {raw!r})")
        given[key] = raw

    for raw in (part.strip() for part in spec.split(",")):
        if not raw:
            continue
        key, sep, column = (s.strip() for s in raw.partition("="))
        if not sep or not column:
            raise InputError(f"--columns: {raw!r} is not KEY=COLUMN")
        if key == "q":
            first, colon, last = column.partition(":")
            if not colon or first not in header or last not in header:
                raise InputError(f"--columns: q={column} must be FIRST:LAST of two header "
                                 f"columns (columns: {', '.join(header)})")
            start, stop = header.index(first), header.index(last)
            if stop < start:
                raise InputError(f"--columns: q={column}: the range is reversed ({first!r} "
                                 f"comes after {last!r} in the header); write q={last}:{first} "
                                 "or list q1=..,qN=.. to map joints out of header order")
            for k, name in enumerate(header[start:stop + 1]):
                claim(f"q{k + 1}", raw)
                joints[k + 1] = name
            continue
        joint = re.fullmatch(r"q(\d+)", key)
        if joint or key in _SINGLE_KEYS:
            claim(f"q{int(joint.group(1))}" if joint else key, raw)
        if joint:
            joints[int(joint.group(1))] = column
        elif key in _SINGLE_KEYS:
            fields[key] = column
        else:
            raise InputError(f"--columns: unknown key {key!r} (expected q1..qN, q=FIRST:LAST, "
                             f"{', '.join(sorted(_SINGLE_KEYS))})")
    for key, column in [*((f"q{k}", c) for k, c in joints.items()), *fields.items()]:
        if column not in header:
            raise InputError(f"{source}: row 1 (header): no column {column!r} for --columns "
                             f"{key}={column} (columns: {', '.join(header)})")
    missing = [f"q{k}" for k in range(1, n_joints + 1) if k not in joints]
    extra = [f"q{k}" for k in joints if not 1 <= k <= n_joints]
    if missing or extra:
        problem = f"missing {', '.join(missing)}" if missing else f"extra {', '.join(extra)}"
        raise InputError(f"--columns: the robot has {n_joints} joints; mapping {problem}")
    for key in ("x", "y", "z"):
        if key not in fields:
            raise InputError(f"--columns: no column for {key} (the measured position)")
    present = [name for name, keys in _ORIENTATIONS.items() if any(k in fields for k in keys)]
    if len(present) > 1:
        raise InputError(f"--columns: give one orientation ({' or '.join(present)}), not both")
    orientation = present[0] if present else None
    if orientation is not None:
        lacking = [k for k in _ORIENTATIONS[orientation] if k not in fields]
        if lacking:
            raise InputError(f"--columns: orientation {orientation} lacks {', '.join(lacking)}")
    if method == "world_pose" and orientation is None:
        raise InputError("--columns: world_pose needs an orientation (roll,pitch,yaw or "
                         "qw,qx,qy,qz or rx,ry,rz)")
    if method == "world_point" and orientation is not None:
        raise InputError("--columns: world_point measures points; drop the orientation "
                         "columns or use --method world_pose")
    return ColumnMap(joints=tuple(joints[k] for k in range(1, n_joints + 1)), fields=fields,
                     orientation=orientation)


class _Cells:
    """Reads typed values out of one CSV's rows, naming row and column in every error."""

    def __init__(self, header: CsvHeader, options: ImportOptions) -> None:
        self.header = header
        self.options = options
        self.index = {name: k for k, name in enumerate(header.columns)}

    def unit_of(self, column: str, kind: str) -> float:
        """SI factor of ``column``: its header unit, else the option's default."""
        default = {"length": self.options.length_unit, "angle": self.options.angle_unit,
                   "joint": self.options.joint_unit}[kind]
        unit = self.header.units.get(column, default)
        units = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
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
        try:
            value = float(raw)
        except ValueError:
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not a number") from None
        if not math.isfinite(value):
            raise InputError(f"{self.header.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not finite")
        return value

    def numbers(self, line: int, cells: tuple[str, ...], columns: Sequence[str],
                indices: Sequence[int]) -> list[float]:
        """The values of ``columns`` (at ``indices``) in one row: the plain conversion,
        and the checking one (which names the first bad cell) only when that fails."""
        try:
            values = [float(cells[k]) for k in indices]
            if all(map(math.isfinite, values)):
                return values
        except (ValueError, IndexError):
            pass
        return [self.number(line, cells, column) for column in columns]


def _rotations_to_rpy(values: FloatArray, orientation: str | None,
                      factors: FloatArray) -> FloatArray:
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
    return angles


def read_samples(csv_rows: CsvRows, mapping: ColumnMap, options: ImportOptions
                 ) -> ImportedSamples:
    """The rows of ``csv_rows`` read through ``mapping`` into SI columns, one row at a
    time (the numbers kept in a flat float64 buffer: about 8 bytes per mapped cell)."""
    header = csv_rows.header
    cells = _Cells(header, options)
    fields = mapping.fields
    ndof = len(mapping.joints)
    orientation = _ORIENTATIONS[mapping.orientation] if mapping.orientation else ()
    optional = [k for k in ("sigma", "t") if k in fields]
    columns = [*mapping.joints, *(fields[k] for k in ("x", "y", "z")),
               *(fields[k] for k in optional),
               *(fields[k] for k in orientation if options.method == "world_pose")]
    factors = np.array(
        [cells.unit_of(c, "length" if prismatic else "joint")
         for c, prismatic in zip(mapping.joints, options.prismatic, strict=True)]
        + [cells.unit_of(fields[k], "length") for k in ("x", "y", "z")]
        + [cells.unit_of(fields[k], "length") if k == "sigma" else 1.0 for k in optional]
        + [1.0 if mapping.orientation == "quat" else cells.unit_of(fields[k], "angle")
           for k in orientation if options.method == "world_pose"])
    indices = [cells.index[c] for c in columns]
    sigma_at = ndof + 3 + optional.index("sigma") if "sigma" in optional else None
    quat_at = ndof + 3 + len(optional) if mapping.orientation == "quat" else None
    marker_column = fields.get("marker") if options.method == "world_point" else None
    width = len(header.columns)
    values = array("d")
    marker_index = array("q")
    marker_ids: dict[str, int] = {}
    for line, row in csv_rows.rows:
        if len(row) > width:
            raise InputError(f"{header.source}: row {line}: {len(row)} cells but the header "
                             f"has {width} columns")
        numbers = cells.numbers(line, row, columns, indices)
        if sigma_at is not None and numbers[sigma_at] <= 0:
            raise InputError(f"{header.source}: row {line}, column {fields['sigma']!r}: "
                             "sigma must be positive")
        if quat_at is not None and math.sqrt(sum(v * v for v in numbers[quat_at:])) < 1e-9:
            raise InputError(f"{header.source}: row {line}, column {fields['qw']!r}: "
                             "the quaternion is zero")
        values.extend(numbers)
        if marker_column is not None:
            name = cells.text(line, row, marker_column)
            marker_index.append(marker_ids.setdefault(name, len(marker_ids)))
    if not values:
        raise InputError(f"{header.source}: no data rows below the header")
    table = np.frombuffer(values, dtype=np.float64).reshape(-1, len(columns))
    at = ndof + 3 + len(optional)
    scaled = table[:, :at] * factors[:at]
    sigma = (scaled[:, sigma_at] if sigma_at is not None else np.full(
        len(table), options.sigma * _unit_factor(options.length_unit, LENGTH_UNITS, "length")))
    world_pose = options.method == "world_pose"
    return ImportedSamples(
        method=options.method, source=header.source,
        q=scaled[:, :ndof], p=scaled[:, ndof:ndof + 3], sigma=sigma,
        t=scaled[:, ndof + 3 + optional.index("t")] if "t" in optional else None,
        rpy=(_rotations_to_rpy(table[:, at:], mapping.orientation, factors[at:])
             if world_pose else None),
        sigma_angle=((1e-3 if options.sigma_angle is None else options.sigma_angle
                      * _unit_factor(options.angle_unit, ANGLE_UNITS, "angle"))
                     if world_pose else None),
        marker_index=(np.frombuffer(marker_index, dtype=np.int64)
                      if marker_column is not None else None),
        marker_names=tuple(marker_ids),
    )


def document_head(samples: ImportedSamples, options: ImportOptions) -> dict[str, Any]:
    """The dataset document of ``samples`` without them (``"samples": []``, written by
    :func:`~hostpc.importing.imported.write_document`): format, method, units, robot,
    frames (``options.frames``; zero where it gives none), known."""
    all_frames = dict(options.frames)
    zero_pose = {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}
    all_frames.setdefault("world", zero_pose)
    if samples.method == "world_pose":
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
