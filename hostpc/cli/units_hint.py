"""What a dataset's numbers say of its declared length unit: the facts behind `hostpc fit`'s
units hint (hostpc.cli.format), for a fit whose residuals are far above the stated noise."""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from hostpc.dataset import Dataset
from hostpc.dataset.validation import read_dataset_bytes

CLOSE_MM = 50.0
"""Positions declared in mm that all lie within this many of the sensor (5 cm) read as
metres: no cell measures every pose that close."""
FAR_M = 50.0
"""Positions declared in m that all lie this far or farther (50 m) read as millimetres."""


def declared_length_unit(path: str | os.PathLike[str]) -> str:
    """The file's `units.length` ("m" when it states none, or cannot be read here: reading
    the dataset reports that)."""
    try:
        document: Any = json.loads(read_dataset_bytes(path).decode("utf-8-sig"))
        unit = document.get("units", {}).get("length", "m")
    except (OSError, ValueError, AttributeError):
        return "m"
    return unit if unit in ("m", "mm") else "m"


def length_unit_hint(dataset: Dataset, declared: str) -> str:
    """The declared length unit, the span of the measured positions' distances in the file's
    numbers, and the unit that span suggests when it tells one."""
    p = dataset.samples.p
    check = f"units.length is {declared}: check that the numbers are in {declared}"
    if p is None or not np.isfinite(p).any():
        return check
    distances = np.linalg.norm(p, axis=1) * (1000.0 if declared == "mm" else 1.0)
    distances = distances[np.isfinite(distances)]
    lo, hi = float(distances.min()), float(distances.max())
    span = f"units.length is {declared}, but the positions span {lo:.3g}-{hi:.3g}"
    if declared == "mm" and hi < CLOSE_MM:
        return f"{span}: metres? set units.length m"
    if declared == "m" and lo >= FAR_M:
        return f"{span}: millimetres? set units.length mm"
    return f"{check} (the positions span {lo:.3g}-{hi:.3g})"
