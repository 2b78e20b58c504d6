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

__all__ = ["SavedFit", "load_saved_fit"]


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
