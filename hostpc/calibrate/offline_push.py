"""Push the zero offsets of an offline fit (`hostpc fit DATASET --json > FIT.json`).

The same guard rails, journal and rollback as `hostpc calibrate` (hostpc.calibrate.push):
`plan_push` decides from the saved fit what to write (held joints left unchanged; the
whole push refused if the fit did not converge, does not explain its data, or a correction
exceeds the limit, unless forced), `execute_push` records the intent durably in the push
folder before writing the controller, and `hostpc rollback --run DIR` undoes it.

:class:`SavedFit` is the part of a :class:`~hostpc.fitting.FitResult` that `plan_push`
reads (both are a :class:`~hostpc.fitting.result.FitVerdict`), rebuilt from the fit's
JSON document; nothing else of the fit is needed.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate.fit_file import (
    REMEDY,
    FitDocument,
    parse_fit_text,
    validate_fit_document,
)
from hostpc.calibrate.measured_under import MeasuredUnder
from hostpc.diagnostics.robust_kept import KeptSamples
from hostpc.errors import InputError
from hostpc.fitting.identifiability import NullDirection
from hostpc.input_files import FIT, read_input_bytes, read_input_text
from hostpc.json_object import JsonObject
from hostpc.model.joint_offsets import LENGTH_UNIT, is_offset
from hostpc.model.joint_offsets import labels as offset_labels

__all__ = ["LedgerEntry", "SavedFit", "already_pushed", "ledger_path", "load_saved_fit",
           "record_push"]


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
    #: the robot's name and kinematics fingerprint (hostpc.model.context.robot_identity);
    #: None for a fit written before fits recorded it
    robot_identity: dict[str, str] | None = None
    #: the fit dataset's nominal frames as saved (SI JSON; hostpc.dataset.writing.
    #: frames_from_json reads them); None for a fit written before fits recorded them
    frames: dict[str, Any] | None = None
    #: a robust-loss fit's chi2 over the samples its loss keeps (model_adequacy.kept_samples,
    #: the one the push guard tests); None for a linear loss or a fit that left none out
    kept_samples: KeptSamples | None = None
    #: model_adequacy.next: the diagnosis of the fit's dataset (`hostpc diagnose DATASET
    #: ... --ladder`), None when the fit explains its data or the file has none
    next_command: str | None = None
    #: the controller's zero offsets the fit's dataset was measured under and its run
    #: (FIT.json measured_under); None when its dataset lay outside a run folder
    measured_under: MeasuredUnder | None = None

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def joint_labels(self) -> tuple[str, ...]:
        """The joints' names (q1..qn, or a kinematic tree's head.q1, ...), from the names
        of the fit's joint offsets."""
        return tuple(offset_labels(self.names))

    @property
    def problem(self) -> None:
        """A saved fit carries no problem (no priors, holds or dataset): see FitVerdict."""
        return None

    def joint_offsets(self) -> list[str]:
        """The joint-offset parameters of the fit, in order."""
        return [n for n in self.names if is_offset(n)]


def saved_fit_from_dict(document: Any, source: str, *, offsets: bool = True) -> SavedFit:
    """Rebuild a SavedFit from `FitResult.to_dict()`, validated first
    (`hostpc.calibrate.fit_file`: strict types, finite statistics, consistent fields, the
    robot's joint count; joint offsets required, and angles (a push), unless ``offsets`` is
    False, as for a prediction); InputError naming the field."""
    fit = validate_fit_document(document, source, offsets=offsets)
    if offsets:
        _angles_only({name: entry.unit for name, entry in fit.parameters.items()}, source)
    names = tuple(fit.parameters)
    entries = list(fit.parameters.values())
    return SavedFit(
        names=names,
        x=np.array([p.value for p in entries], dtype=float),
        std=np.array([math.nan if p.fixed or p.std is None else p.std for p in entries],
                     dtype=float),
        fixed=np.array([p.fixed for p in entries], dtype=bool),
        unidentifiable=tuple(
            NullDirection(fixed=d.fixed, parameters=tuple(d.parameters),
                          coefficients=tuple(d.coefficients), description=d.description)
            for d in fit.unidentifiable),
        converged=fit.converged, message=fit.message, chi2=fit.chi2, dof=fit.dof,
        source=source, method=fit.method, effects=tuple(fit.effects), robot=fit.robot or "",
        chi2_dof_with_calibration=fit.chi2_dof_with_calibration,
        robot_identity=(None if fit.robot_identity is None else
                        {"name": fit.robot_identity.name,
                         "kinematics": fit.robot_identity.kinematics}),
        frames=fit.frames,
        kept_samples=_kept(fit),
        next_command=None if fit.model_adequacy is None else fit.model_adequacy.next,
        measured_under=(None if fit.measured_under is None else MeasuredUnder(
            fit.measured_under.run, fit.measured_under.dataset,
            tuple(fit.measured_under.zero_offsets))),
    )


def _angles_only(units: dict[str, str], source: str) -> None:
    """A controller's zero offsets are angles (rad on the wire, protocol/): a fit with a
    prismatic joint's offset (a length, ``joint_offsets.unit``) has none to write there;
    InputError naming it and the way to use the fit instead (a calibrated URDF)."""
    lengths = [name for name, unit in units.items()
               if is_offset(name) and unit == LENGTH_UNIT]
    if lengths:
        raise InputError(f"{source}: parameters.{lengths[0]} is a prismatic joint's zero "
                         f"offset (unit {LENGTH_UNIT}), and a controller's zero offsets are "
                         "angles (rad): this fit is not pushed; write the calibrated robot "
                         "instead: hostpc fit DATASET --write-urdf OUT.urdf")


def _kept(fit: FitDocument) -> KeptSamples | None:
    """The validated model_adequacy.kept_samples as the push guard reads it."""
    kept = None if fit.model_adequacy is None else fit.model_adequacy.kept_samples
    if kept is None:
        return None
    return KeptSamples(loss=kept.loss, left_out=tuple(kept.left_out),
                       max_weight=kept.max_weight, chi2=kept.chi2, dof=kept.dof,
                       n_kept=kept.n_kept)


def load_saved_fit(path: str | Path, *, offsets: bool = True) -> SavedFit:
    """Read FIT.json (the output of `hostpc fit --json`): a regular file within the fit size
    limit (`hostpc.input_files`), then validated (``offsets``: see saved_fit_from_dict);
    InputError naming the file and field."""
    source = str(path)
    data = read_input_bytes(path, FIT, source)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{source}: not UTF-8 text (byte {exc.start}); {REMEDY}") from None
    return saved_fit_from_dict(parse_fit_text(text, source), source, offsets=offsets)


LEDGER_SUFFIX = ".pushes.jsonl"
SAME_OFFSETS_RAD = 1e-9
"""Offsets closer than this (rad, every joint) are the same: a controller's round trip."""


def ledger_path(fit_path: str | Path) -> Path:
    """FIT.json.pushes.jsonl beside the fit: one line per offline push of this fit."""
    fit_path = Path(fit_path)
    return fit_path.with_name(fit_path.name + LEDGER_SUFFIX)


@dataclass(frozen=True)
class LedgerEntry:
    """One offline push of a fit: the controller, the push's run folder, when (ISO 8601
    UTC), the offsets (n,) rad before and after. A field an older line lacks is None."""

    controller: str | None
    run_dir: str | None
    time: str | None
    before: tuple[float, ...]
    after: tuple[float, ...]

    def to_json(self) -> JsonObject:
        """One ledger line."""
        return {"controller": self.controller, "run_dir": self.run_dir, "time": self.time,
                "before": list(self.before), "after": list(self.after)}

    @classmethod
    def from_json(cls, data: JsonObject) -> LedgerEntry:
        """A ledger line read back (`after` checked by the reader)."""
        def text(key: str) -> str | None:
            value = data.get(key)
            return None if value is None else str(value)

        before = data.get("before")
        return cls(text("controller"), text("run_dir"), text("time"),
                   tuple(float(v) for v in before)
                   if isinstance(before, list) and _offsets_list(before) else (),
                   tuple(float(v) for v in data["after"]))


def _ledger_entries(fit_path: str | Path) -> list[LedgerEntry]:
    path = ledger_path(fit_path)
    if not os.path.lexists(path):
        return []
    entries = []
    for line in read_input_text(path, FIT).splitlines():  # a regular file, bounded
        try:
            entry = json.loads(line)
        except (ValueError, RecursionError):
            continue  # a line cut by a crash: the others still count
        if isinstance(entry, dict) and _offsets_list(entry.get("after")):
            entries.append(LedgerEntry.from_json(entry))
    return entries


def _offsets_list(value: Any) -> bool:
    """True for a list of finite numbers (a ledger entry's offsets, rad)."""
    return isinstance(value, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in value)


def already_pushed(fit_path: str | Path, offsets: np.ndarray) -> LedgerEntry | None:
    """The ledger entry whose offsets after the push equal ``offsets`` (rad), if any: the
    controller already carries this fit's corrections, so pushing again would double them."""
    offsets = np.asarray(offsets, float)
    for entry in _ledger_entries(fit_path):
        after = np.asarray(entry.after, float)
        if after.shape == offsets.shape and np.all(np.abs(after - offsets) <= SAME_OFFSETS_RAD):
            return entry
    return None


def record_push(fit_path: str | Path, entry: LedgerEntry) -> None:
    """Append one push (controller, before, after, run_dir, time) to the fit's ledger;
    written before the controller is, so a push cut half-way is still recorded."""
    path = ledger_path(fit_path)
    try:
        with path.open("a", encoding="utf-8") as handle:
            handle.write(json.dumps(entry.to_json()) + "\n")
            handle.flush()
    except OSError as exc:
        raise InputError(f"{path}: cannot write the push ledger ({exc.strerror or exc}); "
                         "copy the fit to a writable folder") from None
