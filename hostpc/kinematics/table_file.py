"""A robot from a DH / modified-DH table file: ``--robot arm.dh.json`` (docs/robots.md).

The file is one JSON object (conventions.md, "DH and MDH", gives the equations)::

    {"format": "zerocal-robot-table/1", "name": "ur5e", "convention": "dh",
     "units": {"length": "m", "angle": "deg"},
     "joints": [{"a": 0, "alpha": 90, "d": 0.1625, "theta": 0,
                 "type": "revolute", "min": -360, "max": 360}, ...]}

Per joint: ``a``, ``alpha``, ``d``, ``theta`` (the joint angle's offset at ``q = 0``) in the
table's units, for ``"mdh"`` the row of joint ``i`` holding ``a_{i-1}, alpha_{i-1}`` (as
the dataset's explicit table); ``type`` ``"revolute"`` (default) or ``"prismatic"``;
``min`` / ``max`` the joint limits (optional, both or neither; an angle for a revolute
joint, a length for a prismatic one). ``units`` default to m and rad. Unknown keys are
refused (a misspelt ``alpah`` must not read as 0). A bad file is one line naming the file
and the field (InputError: CLI exit code 2).

A dataset fitted with such a robot carries the table itself (its ``robot`` object is the
explicit table of the dataset format, in the dataset's units): the dataset stays readable
without the table file, and the limits (used only to plan live runs) are not kept.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any, Literal, cast

from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.tables import JOINT_TYPES, chain_from_table

__all__ = ["FORMAT_TAG", "SUFFIX", "is_table_file", "load_table_chain", "table_robot_document"]

FORMAT_TAG = "zerocal-robot-table/1"
SUFFIX = ".json"
"""``--robot`` names a table file when it ends with this (a URDF ends with ``.urdf``)."""

_LENGTH = {"m": 1.0, "mm": 1e-3}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_TOP_KEYS = {"format", "name", "convention", "units", "joints"}
_JOINT_KEYS = {"a", "alpha", "d", "theta", "type", "min", "max"}
MAX_JOINTS = 64
"""More joints than any serial robot has: a larger table is a wrong file."""
MAX_LENGTH_M = 10.0
"""Largest |a| or |d| and prismatic joint limit (m): no serial arm's link is longer, and a
table in mm or cm read as m (the common slip) is far beyond it."""
MAX_ANGLE_RAD = 2.0 * math.pi
"""Largest |alpha| or |theta| (rad): beyond a full turn the table's angles are degrees
read as radians (90 deg read as rad is 5157 deg)."""


def is_table_file(robot: str) -> bool:
    """Whether ``--robot`` names a table file rather than a built-in robot or a URDF."""
    return robot.lower().endswith(SUFFIX)


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _choice(document: Mapping[str, Any], key: str, choices: Mapping[str, float] | tuple[str, ...],
            default: str, where: str) -> str:
    value = document.get(key, default)
    if value not in choices:
        raise InputError(f"{where}: {key} {value!r} is not one of {', '.join(choices)}")
    return str(value)


def _read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], str]:
    source = os.fspath(path)
    text = read_input_text(path, CONFIG, source)  # a regular file within the size limit
    try:
        document = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise InputError(f"{source}: not valid JSON ({exc})") from None
    if not isinstance(document, dict):
        raise InputError(f"{source}: expected a JSON object with 'convention' and 'joints'")
    return document, source


def _rows(document: dict[str, Any], source: str) -> dict[str, Any]:
    """The table in SI: convention, name, columns a, alpha, d, theta (n,), types, limits."""
    if document.get("format", FORMAT_TAG) != FORMAT_TAG:  # e.g. a dataset given as --robot
        raise InputError(f"{source}: format {document.get('format')!r}, expected "
                         f"{FORMAT_TAG!r} (a robot table file, docs/robots.md)")
    unknown = sorted(set(document) - _TOP_KEYS)
    if unknown:
        raise InputError(f"{source}: unknown key {unknown[0]!r} (a table has "
                         f"{', '.join(sorted(_TOP_KEYS))})")
    if "convention" not in document:
        raise InputError(f"{source}: 'convention' missing ('dh' or 'mdh'; docs/conventions.md)")
    convention = _choice(document, "convention", ("dh", "mdh"), "", source)
    units = document.get("units", {})
    if not isinstance(units, dict) or set(units) - {"length", "angle"}:
        raise InputError(f"{source}: units: expected {{\"length\": \"m\"|\"mm\", "
                         f"\"angle\": \"rad\"|\"deg\"}}, got {units!r}")
    length_unit = _choice(units, "length", _LENGTH, "m", f"{source}: units")
    angle_unit = _choice(units, "angle", _ANGLE, "rad", f"{source}: units")
    length, angle = _LENGTH[length_unit], _ANGLE[angle_unit]
    name = document.get("name", os.path.basename(source))
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"{source}: name: expected a non-empty text, got {name!r}")
    joints = document.get("joints")
    if not isinstance(joints, list) or not 1 <= len(joints) <= MAX_JOINTS:
        raise InputError(f"{source}: joints: expected a list of 1..{MAX_JOINTS} rows "
                         "{a, alpha, d, theta, type?, min?, max?}")
    columns: dict[str, list[float]] = {key: [] for key in ("a", "alpha", "d", "theta",
                                                           "min", "max")}
    types: list[str] = []
    for i, row in enumerate(joints):
        where = f"{source}: joint {i + 1}"
        if not isinstance(row, dict):
            raise InputError(f"{where}: expected an object {{a, alpha, d, theta, ...}}")
        bad = sorted(set(row) - _JOINT_KEYS)
        if bad:
            raise InputError(f"{where}: unknown key {bad[0]!r} (a joint has "
                             f"{', '.join(sorted(_JOINT_KEYS))})")
        kind = _choice(row, "type", JOINT_TYPES, "revolute", where)
        types.append(kind)
        for key, factor in (("a", length), ("alpha", angle), ("d", length), ("theta", angle)):
            if key not in row:
                raise InputError(f"{where}: '{key}' missing")
            value = _number(row[key], f"{where} {key}") * factor
            if key in ("a", "d"):
                _check_length(value, f"|{key}|", row[key], length_unit, where)
            elif abs(value) > MAX_ANGLE_RAD:
                raise InputError(
                    f"{where}: |{key}| {row[key]!r} {angle_unit} > 2 pi rad: " + (
                        "the angles look like degrees; set units.angle deg"
                        if angle_unit == "rad" else "more than a full turn"))
            columns[key].append(value)
        if ("min" in row) != ("max" in row):
            raise InputError(f"{where}: give both 'min' and 'max' (the joint limits) or neither")
        limit = length if kind == "prismatic" else angle
        low = _number(row["min"], f"{where} min") * limit if "min" in row else -2.0 * math.pi
        high = _number(row["max"], f"{where} max") * limit if "max" in row else 2.0 * math.pi
        if low > high:
            raise InputError(f"{where}: min {row['min']!r} > max {row['max']!r}")
        if kind == "prismatic":
            for key, value in (("min", low), ("max", high)):
                if key in row:
                    _check_length(value, f"|{key}|", row[key], length_unit, where)
        columns["min"].append(low)
        columns["max"].append(high)
    return {"name": name.strip(), "convention": convention, "types": types, **columns}


def _check_length(value: float, what: str, written: Any, unit: str, where: str) -> None:
    """InputError (one line) for a length beyond MAX_LENGTH_M (m): in a table in m, most
    likely mm or cm read as m."""
    if abs(value) > MAX_LENGTH_M:
        hint = ("looks like mm/cm; set units.length mm (and the numbers in mm)"
                if unit == "m" else "no serial robot's link or travel is that long")
        raise InputError(f"{where}: {what} {written!r} {unit} > {MAX_LENGTH_M:g} m: {hint}")


def load_table_chain(path: str | os.PathLike[str]) -> Chain:
    """The chain of a table file (module docstring); InputError naming file and field."""
    document, source = _read(path)
    table = _rows(document, source)
    return chain_from_table(
        table["name"], cast(Literal["dh", "mdh"], table["convention"]),
        a=table["a"], alpha=table["alpha"], d=table["d"], theta=table["theta"],
        q_min=table["min"], q_max=table["max"], joint_types=table["types"])


def table_robot_document(path: str | os.PathLike[str], units: Mapping[str, Any] | None = None
                         ) -> dict[str, Any]:
    """The dataset ``robot`` object of a table file: the explicit table of the dataset
    format, in the dataset's ``units`` (its ``units`` object; default SI)."""
    document, source = _read(path)
    table = _rows(document, source)
    units = units or {}
    length = 1e3 if units.get("length") == "mm" else 1.0
    angle = 180.0 / math.pi if units.get("angle") == "deg" else 1.0
    rows = []
    for i, kind in enumerate(table["types"]):
        row = {"a": table["a"][i] * length, "alpha": table["alpha"][i] * angle,
               "d": table["d"][i] * length, "theta": table["theta"][i] * angle}
        if kind != "revolute":
            row["type"] = kind
        rows.append(row)
    return {"convention": table["convention"], "joints": rows}
