"""Push the zero offsets of an offline fit (`hostpc fit DATASET --json > FIT.json`).

The same guard rails, journal and rollback as `hostpc calibrate` (hostpc.calibrate.push):
`plan_push` decides from the saved fit what to write (held joints left unchanged; the
whole push refused if the fit did not converge, does not explain its data, or a correction
exceeds the limit, unless forced), `execute_push` records the intent durably in the push
folder before writing the controller, and `hostpc rollback --run DIR` undoes it.

:class:`SavedFit` is the part of a :class:`~hostpc.fitting.FitResult` that `plan_push`
reads, rebuilt from the fit's JSON document; nothing else of the fit is needed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.fitting.identifiability import NullDirection

__all__ = ["SavedFit", "already_pushed", "ledger_path", "load_saved_fit", "record_push"]


@dataclass(frozen=True)
class SavedFit:
    """A fit's parameters and verdict as saved by `hostpc fit --json` (SI, radians).

    names: parameter names; x, std (NaN where fixed), fixed: (P,); unidentifiable: the
    held null directions; converged, message, chi2, dof: the fit's verdict; source: the
    file it came from; method / effects: of the fit."""

    names: tuple[str, ...]
    x: np.ndarray
    std: np.ndarray
    fixed: np.ndarray
    unidentifiable: tuple[NullDirection, ...]
    converged: bool
    message: str
    chi2: float
    dof: int
    source: str
    method: str = ""
    effects: tuple[str, ...] = ()
    robot: str = ""  # the dataset's built-in robot name ("" if unknown: a table or URDF)
    chi2_dof_with_calibration: float | None = None  # the push guard's chi2, if the fit has it

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def problem(self) -> Any:
        """What plan_push reads of the problem: the joint labels (q1..qn)."""
        return SimpleNamespace(context=SimpleNamespace(joint_labels=()))

    def joint_offsets(self) -> list[str]:
        """The joint-offset parameters of the fit, in order."""
        return [n for n in self.names if n.startswith("joint_offsets.")]


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _finite(value: Any, where: str) -> float:
    number = _number(value, where)
    if not math.isfinite(number):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    return number


def saved_fit_from_dict(document: Any, source: str) -> SavedFit:
    """Rebuild a SavedFit from `FitResult.to_dict()`; InputError naming the field."""
    if not isinstance(document, Mapping):
        raise InputError(f"{source}: expected a JSON object (the output of hostpc fit --json)")
    for key in ("parameters", "converged", "chi2", "dof"):
        if key not in document:
            raise InputError(f"{source}: no {key!r}: not the output of `hostpc fit --json`")
    parameters = document["parameters"]
    if not isinstance(parameters, Mapping) or not parameters:
        raise InputError(f"{source}: parameters: expected a non-empty object")
    names, x, std, fixed = [], [], [], []
    for name, p in parameters.items():
        where = f"{source}: parameters.{name}"
        if not isinstance(p, Mapping) or "value" not in p:
            raise InputError(f"{where}: expected {{value, std, fixed}}")
        names.append(str(name))
        x.append(_number(p["value"], f"{where}.value"))
        held = bool(p.get("fixed", False))
        fixed.append(held)
        std.append(math.nan if held or p.get("std") is None
                   else _number(p["std"], f"{where}.std"))
    directions = []
    for k, d in enumerate(document.get("unidentifiable") or []):
        if not isinstance(d, Mapping) or "fixed" not in d:
            raise InputError(f"{source}: unidentifiable[{k}]: expected {{fixed, parameters}}")
        directions.append(NullDirection(
            fixed=str(d["fixed"]), parameters=tuple(map(str, d.get("parameters", []))),
            coefficients=tuple(float(c) for c in d.get("coefficients", [])),
            description=str(d.get("description", ""))))
    if not any(n.startswith("joint_offsets.") for n in names):
        raise InputError(f"{source}: the fit has no joint_offsets parameters: nothing to push")
    return SavedFit(
        names=tuple(names), x=np.array(x), std=np.array(std), fixed=np.array(fixed),
        unidentifiable=tuple(directions), converged=bool(document["converged"]),
        message=str(document.get("message", "")),
        chi2=_number(document["chi2"], f"{source}: chi2"),
        dof=int(_number(document["dof"], f"{source}: dof")), source=source,
        method=str(document.get("method", "")),
        effects=tuple(map(str, document.get("effects", []))),
        robot=str(document.get("robot") or ""),
        chi2_dof_with_calibration=(
            None if document.get("chi2_dof_with_calibration") is None
            else _finite(document["chi2_dof_with_calibration"],
                         f"{source}: chi2_dof_with_calibration")),
    )


def load_saved_fit(path: str | Path) -> SavedFit:
    """Read FIT.json (the output of `hostpc fit --json`); InputError naming the file."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{source}: cannot read ({exc.strerror or exc})") from None
    try:
        document = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{source}: not valid JSON ({exc})") from None
    return saved_fit_from_dict(document, source)


LEDGER_SUFFIX = ".pushes.jsonl"
SAME_OFFSETS_RAD = 1e-9
"""Offsets closer than this (rad, every joint) are the same: a controller's round trip."""


def ledger_path(fit_path: str | Path) -> Path:
    """FIT.json.pushes.jsonl beside the fit: one line per offline push of this fit."""
    fit_path = Path(fit_path)
    return fit_path.with_name(fit_path.name + LEDGER_SUFFIX)


def _ledger_entries(fit_path: str | Path) -> list[dict[str, Any]]:
    path = ledger_path(fit_path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    entries = []
    for line in lines:
        try:
            entry = json.loads(line)
        except ValueError:
            continue  # a line cut by a crash: the others still count
        if isinstance(entry, Mapping) and isinstance(entry.get("after"), list):
            entries.append(dict(entry))
    return entries


def already_pushed(fit_path: str | Path, offsets: np.ndarray) -> dict[str, Any] | None:
    """The ledger entry whose offsets after the push equal ``offsets`` (rad), if any: the
    controller already carries this fit's corrections, so pushing again would double them."""
    offsets = np.asarray(offsets, float)
    for entry in _ledger_entries(fit_path):
        after = np.asarray(entry["after"], float)
        if after.shape == offsets.shape and np.all(np.abs(after - offsets) <= SAME_OFFSETS_RAD):
            return entry
    return None


def record_push(fit_path: str | Path, entry: Mapping[str, Any]) -> None:
    """Append one push (controller, before, after, run_dir, time) to the fit's ledger;
    written before the controller is, so a push cut half-way is still recorded."""
    path = ledger_path(fit_path)
    try:
        with path.open("a", encoding="utf-8") as handle:
            handle.write(json.dumps(dict(entry)) + "\n")
            handle.flush()
    except OSError as exc:
        raise InputError(f"{path}: cannot write the push ledger ({exc.strerror or exc}); "
                         "copy the fit to a writable folder") from None
