"""The dataset's `rig_uncertainty` block, checked on load by the stereo kinds' file faces
(stereo_target's and dual_loop's ``check_loaded``; the dataset layer never imports vision).

A stereo_target or dual_loop dataset may carry the calibration of the camera that measured
it and that calibration's covariance (`hostpc.vision.rig_uncertainty.uncertainty_document`):

    "rig_uncertainty": {"rig": <rig file document>, "parameters": [24 names],
                        "covariance": 24 x 24, "pixel_floor_px": 0.25}

The fit propagates the covariance into its parameter sigmas, and the push guard tests the
chi2 with it inside (`hostpc.fitting.shared_errors`), so a damaged block would change what
is pushed. The fitting layer used to skip a block it could not use, silently; this module
refuses it on load with one line naming the field (DatasetError, exit code 2):

- ``rig``: a valid rig (`hostpc.vision.rig.rig_from_dict`: format, shapes, positive focal
  lengths, a rotation, a non-zero baseline);
- ``parameters``: exactly `RIG_PARAMETERS`, in that order (the covariance's rows);
- ``covariance``: 24 x 24 numbers (no strings, no booleans), symmetric (to 1e-9 of its
  largest entry), positive semi-definite (no eigenvalue below -1e-9 of the largest), every
  standard deviation within `MAX_RIG_STD` of its parameter's unit (px, unitless
  distortion, rad, m): a calibration that uncertain measures nothing;
- ``pixel_floor_px``: a number in [0, MAX_PIXEL_FLOOR_PX].

The vision package (OpenCV) is imported only when a dataset carries the block.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hostpc.dataset.model import Dataset
from hostpc.errors import DatasetError, InputError

BLOCK = "rig_uncertainty"
MAX_RIG_STD = {"px": 1e3, "1": 10.0, "rad": 1.0, "m": 10.0}
"""Largest believable standard deviation of a rig parameter, per unit: intrinsics fx fy cx cy
(px), distortion k1 k2 p1 p2 k3 (unitless), the stereo rotation (rad), the baseline (m)."""
MAX_PIXEL_FLOOR_PX = 100.0
"""Largest pixel floor (px) a sample's covariance can have been built with."""
SYMMETRY_TOLERANCE = 1e-9
"""Relative to the largest entry: how far from symmetric a covariance written as JSON is."""


def _units(n_intrinsics: int) -> list[str]:
    per_camera = ["px"] * 4 + ["1"] * (n_intrinsics - 4)
    return per_camera * 2 + ["rad"] * 3 + ["m"] * 3


def check_rig_block(dataset: Dataset, source: str) -> None:
    """The dataset's `rig_uncertainty` block, if it has one, well formed (DatasetError)."""
    if BLOCK in dataset.extra_fields:
        check_rig_uncertainty(dataset.extra_fields[BLOCK], source)


def check_rig_uncertainty(block: Any, source: str) -> None:
    """Refuse a damaged `rig_uncertainty` block (see the module docstring); DatasetError
    ``source: rig_uncertainty.<field>: ...``."""
    where = f"{source}: {BLOCK}"
    if not isinstance(block, dict):
        raise DatasetError(f"{where}: expected an object {{rig, parameters, covariance}}, "
                           f"got {type(block).__name__}")
    for name in ("rig", "parameters", "covariance"):
        if name not in block:
            raise DatasetError(f"{where}.{name}: required field missing")
    from hostpc.vision.rig import rig_from_dict
    from hostpc.vision.rig_uncertainty import RIG_PARAMETERS

    try:
        rig_from_dict(block["rig"], f"{where}.rig")
    except InputError as exc:
        raise DatasetError(str(exc)) from None
    if block["parameters"] != list(RIG_PARAMETERS):
        raise DatasetError(f"{where}.parameters: expected the {len(RIG_PARAMETERS)} rig "
                           f"parameters {RIG_PARAMETERS[0]} .. {RIG_PARAMETERS[-1]} in order")
    _check_covariance(block["covariance"], len(RIG_PARAMETERS), f"{where}.covariance")
    floor = block.get("pixel_floor_px", 0.0)
    if (isinstance(floor, bool) or not isinstance(floor, int | float)
            or not 0.0 <= floor <= MAX_PIXEL_FLOOR_PX):
        raise DatasetError(f"{where}.pixel_floor_px: expected a number of pixels in "
                           f"[0, {MAX_PIXEL_FLOOR_PX:g}], got {floor!r}")


def _check_covariance(rows: Any, size: int, where: str) -> None:
    if not (isinstance(rows, list) and len(rows) == size
            and all(isinstance(row, list) and len(row) == size for row in rows)):
        raise DatasetError(f"{where}: expected a {size} x {size} array of numbers")
    for i, row in enumerate(rows):
        for j, value in enumerate(row):
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value)):
                raise DatasetError(f"{where}[{i}][{j}]: expected a finite number, "
                                   f"got {value!r}")
    matrix = np.array(rows, dtype=float)
    scale = float(np.max(np.abs(matrix)))
    asymmetry = np.abs(matrix - matrix.T)
    if np.any(asymmetry > SYMMETRY_TOLERANCE * scale):
        i, j = (int(k) for k in np.unravel_index(int(np.argmax(asymmetry)), matrix.shape))
        raise DatasetError(f"{where}: not symmetric ([{i}][{j}] {matrix[i, j]:.6g} != "
                           f"[{j}][{i}] {matrix[j, i]:.6g})")
    eigenvalues = np.linalg.eigvalsh(0.5 * (matrix + matrix.T))
    if eigenvalues[0] < -SYMMETRY_TOLERANCE * max(eigenvalues[-1], 0.0) or (
            eigenvalues[-1] <= 0.0 and eigenvalues[0] < 0.0):
        raise DatasetError(f"{where}: not positive semi-definite (eigenvalue "
                           f"{eigenvalues[0]:.3g})")
    units = _units((size - 6) // 2)
    for k, variance in enumerate(np.diag(matrix)):
        limit = MAX_RIG_STD[units[k]]
        if not variance <= limit ** 2:
            raise DatasetError(f"{where}[{k}][{k}]: standard deviation {math.sqrt(variance):.3g}"
                               f" {units[k]} is above the believable {limit:g} {units[k]}")
