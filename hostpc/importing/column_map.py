"""The ``--columns`` mapping of ``hostpc import``: which CSV column holds what.

Comma-separated ``KEY=COLUMN`` pairs, checked against the CSV header:

- joints: ``q1=COL, q2=COL, ...`` or a header range ``q=FIRST:LAST`` (consecutive columns,
  in the robot's joint order; when every header of the range names a joint of the robot
  (a URDF's joint names), each column goes to the joint it names, and a range in another
  order than the robot's says so in one line; a range that mixes joint names and other
  headers with a joint name out of its place is refused with the mapping to write);
- position in the world frame: ``x=COL, y=COL, z=COL``; or, for several reflectors seen in
  one pose (world_point), ``marker.NAME=FIRST:LAST`` per reflector: three consecutive
  header columns x, y, z, each row giving one sample per reflector with the row's joints
  (a reflector whose three cells are all empty in a row was not seen there: no sample);
- world_pose orientation: ``roll=, pitch=, yaw=`` (R = Rz(yaw) Ry(pitch) Rx(roll)), or a
  quaternion ``qw=, qx=, qy=, qz=``, or a rotation vector ``rx=, ry=, rz=``, or Euler
  angles ``e1=, e2=, e3=`` in the order of the ``--euler`` sequence;
- optional: ``marker=COL`` (world_point marker id), ``t=COL`` (time, s),
  ``temperature=COL`` (kept as written), ``sigma=COL`` (per-row position sigma in the
  length unit) or ``sx=, sy=, sz=`` (per-axis sigmas: a diagonal covariance per sample);
  with reflector groups, ``sigma.NAME=COL`` or ``sigma.NAME=FIRST:LAST`` (sx, sy, sz) for
  one reflector.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hostpc.dataset.kind_registry import csv_row_kinds, csv_row_shape
from hostpc.errors import InputError

__all__ = ["ORIENTATIONS", "ColumnMap", "PointColumns", "parse_column_map"]

ORIENTATIONS = {"rpy": ("roll", "pitch", "yaw"), "quat": ("qw", "qx", "qy", "qz"),
                "rotvec": ("rx", "ry", "rz"), "euler": ("e1", "e2", "e3")}
_SINGLE_KEYS = {"x", "y", "z", "marker", "t", "sigma", "sx", "sy", "sz", "temperature"} | {
    k for keys in ORIENTATIONS.values() for k in keys}
_GROUP_KEYS = ("marker", "sigma")  # marker.NAME=, sigma.NAME=


@dataclass(frozen=True)
class PointColumns:
    """One measured point per row: its x, y, z columns, its sigma columns (none, one
    isotropic column, or sx, sy, sz) and the reflector's name (None: the ``marker``
    column, if any, names it)."""

    xyz: tuple[str, str, str]
    sigma: tuple[str, ...] = ()
    marker: str | None = None


@dataclass(frozen=True)
class ColumnMap:
    """Which CSV column holds what: ``joints`` in joint order, ``fields`` by key, and the
    points each row measures (one, or one per ``marker.NAME`` group)."""

    joints: tuple[str, ...]
    fields: Mapping[str, str]
    orientation: str | None  # "rpy", "quat", "rotvec", "euler" or None
    points: tuple[PointColumns, ...] = ()
    #: coupled joints (0-based) the mapping left out: read from their leader's column, to
    #: be computed from it (hostpc.cli.import_csv), never a value of their own
    derived: tuple[int, ...] = ()
    #: one line each for the user: how the mapping was read (a joint range mapped by name)
    notes: tuple[str, ...] = ()


def _header_range(key: str, column: str, header: Sequence[str]) -> list[str]:
    """The header columns FIRST..LAST of ``column`` ("FIRST:LAST")."""
    first, colon, last = column.partition(":")
    if not colon or first not in header or last not in header:
        raise InputError(f"--columns: {key}={column} must be FIRST:LAST of two header "
                         f"columns (columns: {listed_columns(header)})")
    start, stop = header.index(first), header.index(last)
    if stop < start:
        raise InputError(f"--columns: {key}={column}: the range is reversed ({first!r} "
                         f"comes after {last!r} in the header); write {key}={last}:{first} "
                         "or list the columns one by one")
    return list(header[start:stop + 1])


def _joint_range(raw: str, columns: Sequence[str], joint_names: Sequence[str],
                 header: Sequence[str]) -> tuple[dict[int, str], str | None]:
    """The joints (1-based) of the range ``q=FIRST:LAST`` whose header ``columns`` are given:
    by position, or, when every column names a joint of the robot (``joint_names``, in
    joint order), each to the joint it names, with a note when that is not the position
    (None otherwise). InputError for a range whose joint names are out of place among other
    headers: neither reading is safe; the message gives the mapping by name."""
    by_position = {k + 1: name for k, name in enumerate(columns)}
    misplaced = [name for k, name in enumerate(columns)
                 if name in joint_names and joint_names.index(name) != k]
    if not misplaced:
        return by_position, None
    if all(name in joint_names for name in columns) and len(set(columns)) == len(columns):
        by_name = {joint_names.index(name) + 1: name for name in columns}
        moved = ", ".join(f"q{joint_names.index(name) + 1}={name}" for name in misplaced)
        return by_name, (f"--columns {raw}: the header names the robot's joints in another "
                         f"order than the robot's; each column read as the joint it names "
                         f"({moved}, not by position)")
    present = [name for name in joint_names if name in header]
    fix = (",".join(f"q{k + 1}={name}" for k, name in enumerate(joint_names))
           if len(present) == len(joint_names) else "q1=COL,q2=COL,... one by one")
    raise InputError(f"--columns {raw}: the range's columns name joints of the robot at "
                     f"other places ({', '.join(misplaced)}) among other columns; map the "
                     f"joints by name: --columns \"{fix},...\" (the other keys as given)")


def _groups(groups: Mapping[str, dict[str, str]], fields: Mapping[str, str],
            header: Sequence[str]) -> tuple[PointColumns, ...]:
    """The reflector groups (``marker.NAME``, ``sigma.NAME``), or the one point of x, y, z."""
    shared = (tuple(fields[k] for k in ("sx", "sy", "sz")) if "sx" in fields
              else (fields["sigma"],) if "sigma" in fields else ())
    if not groups:
        for key in ("x", "y", "z"):
            if key not in fields:
                raise InputError(f"--columns: no column for {key} (the measured position; "
                                 "or marker.NAME=FIRST:LAST per reflector)")
        return (PointColumns(xyz=(fields["x"], fields["y"], fields["z"]), sigma=shared),)
    clash = [k for k in ("x", "y", "z", "marker") if k in fields]
    if clash:
        raise InputError(f"--columns: marker.NAME= groups give the positions; drop "
                         f"{', '.join(clash)}=")
    points = []
    for name, given in groups.items():
        if "marker" not in given:
            raise InputError(f"--columns: sigma.{name}= names no reflector (add "
                             f"marker.{name}=FIRST:LAST)")
        xyz = _header_range(f"marker.{name}", given["marker"], header)
        if len(xyz) != 3:
            raise InputError(f"--columns: marker.{name}={given['marker']} spans {len(xyz)} "
                             "columns; it must span the three columns x, y, z")
        sigma = tuple(_header_range(f"sigma.{name}", given["sigma"], header)
                      if ":" in given.get("sigma", "") else
                      [given["sigma"]] if "sigma" in given else shared)
        if len(sigma) not in (0, 1, 3):
            raise InputError(f"--columns: sigma.{name}={given['sigma']} spans {len(sigma)} "
                             "columns; give one column or the three sx, sy, sz")
        points.append(PointColumns(xyz=(xyz[0], xyz[1], xyz[2]), sigma=sigma, marker=name))
    if len({len(p.sigma) for p in points}) > 1:
        raise InputError("--columns: give every reflector the same kind of sigma (none, one "
                         "column, or three)")
    return tuple(points)


def parse_column_map(spec: str, header: Sequence[str], n_joints: int, method: str,
                     source: str = "CSV", followers: Mapping[int, int] | None = None,
                     joint_names: Sequence[str] = ()) -> ColumnMap:
    """Parse ``--columns`` against the CSV header; InputError naming the offending pair.
    ``followers``: coupled joints (a URDF ``<mimic>``), follower -> leader, 1-based: a
    follower left out of the mapping is computed from its leader (``ColumnMap.derived``).
    ``joint_names``: the robot's joint names in joint order (a URDF's; empty: unknown), by
    which a ``q=FIRST:LAST`` range of joint-named headers is read (``_joint_range``)."""
    joints: dict[int, str] = {}
    fields: dict[str, str] = {}
    groups: dict[str, dict[str, str]] = {}  # reflector -> {"marker": range, "sigma": ...}
    given: dict[str, str] = {}  # key -> the pair that gave it (q=A:B gives q1..qN)
    notes: list[str] = []

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
            ranged, note = _joint_range(raw, _header_range("q", column, header),
                                        tuple(joint_names), header)
            for k, name in ranged.items():
                claim(f"q{k}", raw)
                joints[k] = name
            notes.extend([note] if note else [])
            continue
        kind, dot, name = key.partition(".")
        if dot and kind in _GROUP_KEYS and name:
            claim(key, raw)
            groups.setdefault(name, {})[kind] = column
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
                             f"marker.NAME=FIRST:LAST, sigma.NAME=, "
                             f"{', '.join(sorted(_SINGLE_KEYS))})")
    for key, column in [*((f"q{k}", c) for k, c in joints.items()), *fields.items(),
                        *((f"sigma.{n}", g["sigma"]) for n, g in groups.items()
                          if ":" not in g.get("sigma", ":"))]:
        if column not in header:
            raise InputError(f"{source}: row 1 (header): no column {column!r} for --columns "
                             f"{key}={column} (columns: {listed_columns(header)})")
    followers = followers or {}
    derived = tuple(k - 1 for k in range(1, n_joints + 1)
                    if k not in joints and followers.get(k) in joints)
    for k in derived:
        joints[k + 1] = joints[followers[k + 1]]
    missing = [f"q{k}" for k in range(1, n_joints + 1) if k not in joints]
    extra = [f"q{k}" for k in joints if not 1 <= k <= n_joints]
    if missing or extra:
        problem = f"missing {', '.join(missing)}" if missing else f"extra {', '.join(extra)}"
        coupled = ", ".join(f"q{f} follows q{leader}" for f, leader in followers.items())
        hint = (f"; {coupled} (URDF <mimic>): a follower may be left out (map the others "
                "one by one, q1=COL,...), import computes it from its leader"
                if coupled else "")
        raise InputError(f"--columns: the robot has {n_joints} joints; mapping "
                         f"{problem}{hint}")
    axes = [k for k in ("sx", "sy", "sz") if k in fields]
    if axes and len(axes) != 3:
        raise InputError(f"--columns: per-axis sigmas need all of sx, sy, sz (given "
                         f"{', '.join(axes)})")
    if axes and "sigma" in fields:
        raise InputError("--columns: give sigma= or sx=, sy=, sz=, not both")
    rows = csv_row_shape(method)
    if groups and rows != "point":
        points_kinds = ", ".join(csv_row_kinds("point"))
        raise InputError(f"--columns: marker.NAME= groups are reflectors of {points_kinds}; "
                         f"use --method {points_kinds}")
    points = _groups(groups, fields, header)
    present = [name for name, keys in ORIENTATIONS.items() if any(k in fields for k in keys)]
    if len(present) > 1:
        raise InputError(f"--columns: give one orientation ({' or '.join(present)}), not both")
    orientation = present[0] if present else None
    if orientation is not None:
        lacking = [k for k in ORIENTATIONS[orientation] if k not in fields]
        if lacking:
            raise InputError(f"--columns: orientation {orientation} lacks {', '.join(lacking)}")
    if rows == "pose" and orientation is None:
        raise InputError(f"--columns: {method} needs an orientation (roll,pitch,yaw or "
                         "qw,qx,qy,qz or rx,ry,rz or e1,e2,e3 with --euler)")
    if rows == "point" and orientation is not None:
        raise InputError(f"--columns: {method} measures points; drop the orientation "
                         f"columns or use --method {', '.join(csv_row_kinds('pose'))}")
    return ColumnMap(joints=tuple(joints[k] for k in range(1, n_joints + 1)), fields=fields,
                     orientation=orientation, points=points, derived=derived,
                     notes=tuple(notes))


def listed_columns(header: Sequence[str], most: int = 40) -> str:
    """The header's column names for a one-line message: each on one line (a quoted cell
    that spans lines is shown escaped) and cut to a readable length."""
    shown = [name if name.isprintable() else repr(name) for name in header[:most]]
    text = ", ".join(shown)
    if len(header) > most:
        text += f", ... ({len(header)} columns)"
    return text if len(text) <= 400 else text[:400] + " ..."
