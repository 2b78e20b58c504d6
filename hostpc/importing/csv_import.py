"""Turn a metrology CSV export into a ``zerocal-dataset/1`` document (world_point, world_pose).

Pure (no file writing): :func:`parse_column_map` reads the ``--columns`` mapping,
:func:`read_csv_rows` checks the table and :func:`build_document` returns the JSON document
(SI units: m, rad). Every bad input raises :class:`~hostpc.errors.InputError` with one line
that names the file, the row (the file's line number; the header is row 1) and the column.

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

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix

__all__ = [
    "LENGTH_UNITS", "ANGLE_UNITS", "ColumnMap", "CsvTable", "ImportOptions",
    "build_document", "parse_column_map", "read_csv_rows",
]

LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "in": 0.0254}
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3}
_ORIENTATIONS = {"rpy": ("roll", "pitch", "yaw"), "quat": ("qw", "qx", "qy", "qz"),
                 "rotvec": ("rx", "ry", "rz")}
_SINGLE_KEYS = {"x", "y", "z", "marker", "t", "sigma"} | {
    k for keys in _ORIENTATIONS.values() for k in keys}
_UNIT_SUFFIX = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")


@dataclass(frozen=True)
class ColumnMap:
    """Which CSV column holds what: ``joints`` in joint order, ``fields`` by key."""

    joints: tuple[str, ...]
    fields: Mapping[str, str]
    orientation: str | None  # "rpy", "quat", "rotvec" or None


@dataclass(frozen=True)
class CsvTable:
    """A CSV file's header (unit suffixes removed), header units and data rows."""

    source: str
    columns: tuple[str, ...]
    units: Mapping[str, str]  # column -> unit named in its header
    rows: tuple[tuple[int, tuple[str, ...]], ...]  # (file line number, cells)


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


def read_csv_rows(text: str, source: str) -> CsvTable:
    """Split CSV text into header, header units and rows (comma, semicolon or tab)."""
    if not text.strip():
        raise InputError(f"{source}: empty file")
    try:
        dialect: Any = csv.Sniffer().sniff(text.splitlines()[0], delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    reader = csv.reader(io.StringIO(text), dialect)
    try:
        header = next(reader)
    except (StopIteration, csv.Error) as exc:
        raise InputError(f"{source}: row 1: cannot read the header ({exc})") from None
    columns: list[str] = []
    units: dict[str, str] = {}
    for k, cell in enumerate(header):
        name = cell.strip().lstrip("\ufeff")
        match = _UNIT_SUFFIX.match(name)
        if match:
            name = match.group(1)
            units[name] = match.group(2)
        if not name:
            raise InputError(f"{source}: row 1, column {k + 1}: empty column name")
        if name in columns:
            raise InputError(f"{source}: row 1, column {k + 1}: {name!r} appears twice")
        columns.append(name)
    rows: list[tuple[int, tuple[str, ...]]] = []
    try:
        for cells in reader:
            if not any(c.strip() for c in cells):
                continue
            rows.append((reader.line_num, tuple(c.strip() for c in cells)))
    except csv.Error as exc:
        raise InputError(f"{source}: row {reader.line_num}: {exc}") from None
    if not rows:
        raise InputError(f"{source}: no data rows below the header")
    return CsvTable(source=source, columns=tuple(columns), units=units, rows=tuple(rows))


class _Cells:
    """Reads typed values out of one table, naming row and column in every error."""

    def __init__(self, table: CsvTable, options: ImportOptions) -> None:
        self.table = table
        self.options = options
        self.index = {name: k for k, name in enumerate(table.columns)}

    def unit_of(self, column: str, kind: str) -> float:
        """SI factor of ``column``: its header unit, else the option's default."""
        default = {"length": self.options.length_unit, "angle": self.options.angle_unit,
                   "joint": self.options.joint_unit}[kind]
        unit = self.table.units.get(column, default)
        units = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
        if unit not in units and column in self.table.units:
            raise InputError(f"{self.table.source}: row 1, column {column!r}: unknown unit "
                             f"{unit!r} (expected one of {', '.join(units)})")
        return _unit_factor(unit, units, kind)

    def text(self, line: int, cells: tuple[str, ...], column: str) -> str:
        k = self.index[column]
        if k >= len(cells) or cells[k] == "":
            raise InputError(f"{self.table.source}: row {line}, column {column!r}: "
                             "missing value")
        return cells[k]

    def number(self, line: int, cells: tuple[str, ...], column: str) -> float:
        raw = self.text(line, cells, column)
        try:
            value = float(raw)
        except ValueError:
            raise InputError(f"{self.table.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not a number") from None
        if not math.isfinite(value):
            raise InputError(f"{self.table.source}: row {line}, column {column!r}: "
                             f"{raw!r} is not finite")
        return value


def _orientation_rpy(cells: _Cells, line: int, row: tuple[str, ...], mapping: ColumnMap
                     ) -> list[float]:
    keys = _ORIENTATIONS[mapping.orientation or "rpy"]
    cols = [mapping.fields[k] for k in keys]
    if mapping.orientation == "quat":
        w, x, y, z = (cells.number(line, row, c) for c in cols)
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if norm < 1e-9:
            raise InputError(f"{cells.table.source}: row {line}, column {cols[0]!r}: "
                             "the quaternion is zero")
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        R = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ])
        return [float(v) for v in matrix_to_rpy(R)]
    values = [cells.number(line, row, c) * cells.unit_of(c, "angle") for c in cols]
    if mapping.orientation == "rotvec":
        return [float(v) for v in matrix_to_rpy(rotvec_to_matrix(np.array(values)))]
    return values


def build_document(table: CsvTable, mapping: ColumnMap, options: ImportOptions
                   ) -> dict[str, Any]:
    """The dataset document (SI units) of ``table`` read through ``mapping``."""
    cells = _Cells(table, options)
    joint_factor = [cells.unit_of(c, "length" if prismatic else "joint")
                    for c, prismatic in zip(mapping.joints, options.prismatic, strict=True)]
    xyz_cols = [mapping.fields[k] for k in ("x", "y", "z")]
    xyz_factor = [cells.unit_of(c, "length") for c in xyz_cols]
    sigma_col = mapping.fields.get("sigma")
    length_default = _unit_factor(options.length_unit, LENGTH_UNITS, "length")
    angle_default = _unit_factor(options.angle_unit, ANGLE_UNITS, "angle")
    samples: list[dict[str, Any]] = []
    markers: dict[str, None] = {}
    for line, row in table.rows:
        if len(row) > len(table.columns):
            raise InputError(f"{table.source}: row {line}: {len(row)} cells but the header "
                             f"has {len(table.columns)} columns")
        sample: dict[str, Any] = {
            "q": [cells.number(line, row, c) * f
                  for c, f in zip(mapping.joints, joint_factor, strict=True)],
            "p": [cells.number(line, row, c) * f for c, f in zip(xyz_cols, xyz_factor,
                                                                 strict=True)],
        }
        if sigma_col is not None:
            sigma = cells.number(line, row, sigma_col) * cells.unit_of(sigma_col, "length")
            if sigma <= 0:
                raise InputError(f"{table.source}: row {line}, column {sigma_col!r}: "
                                 "sigma must be positive")
            sample["sigma"] = sigma
        else:
            sample["sigma"] = options.sigma * length_default
        if "t" in mapping.fields:
            sample["t"] = cells.number(line, row, mapping.fields["t"])
        if options.method == "world_pose":
            sample["rpy"] = _orientation_rpy(cells, line, row, mapping)
            sample["sigma_angle"] = (1e-3 if options.sigma_angle is None
                                     else options.sigma_angle * angle_default)
        elif "marker" in mapping.fields:
            sample["marker"] = cells.text(line, row, mapping.fields["marker"])
            markers[sample["marker"]] = None
        samples.append(sample)
    frames = dict(options.frames)
    frames.setdefault("world", {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]})
    if options.method == "world_pose":
        frames.setdefault("tool", {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]})
    else:
        names = list(markers) or ["marker"]
        frames.setdefault("markers", {name: [0.0, 0.0, 0.0] for name in names})
    return {
        "format": "zerocal-dataset/1",
        "method": options.method,
        "units": {"length": "m", "angle": "rad", "time": "s"},
        "robot": dict(options.robot),
        "frames": frames,
        "known": list(options.known),
        "samples": samples,
        "source": {"csv": table.source, "rows": len(samples)},
    }
