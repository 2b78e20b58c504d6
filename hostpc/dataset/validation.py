"""Hostile and careless input: the size of a dataset file, and physical ranges of its values.

The format layer (``reading``, ``schema``) checks that a dataset is well formed: types,
shapes, finite numbers, positive-definite covariances. This module adds what a fit needs
beyond that, so that a damaged or malicious file is refused at load with one line naming the
file, the sample and the field instead of overflowing inside the solver:

- ``read_dataset_bytes``: a size limit (``ZEROCAL_MAX_DATASET_MB``, default 512 MB); a
  device (``/dev/zero``), a FIFO or a directory is refused at once (``hostpc.input_files``).
- the kind's own blocks (``MeasurementKind.check_loaded``, called by ``check_dataset``): e.g.
  the stereo kinds' ``rig_uncertainty`` block (the rig's calibration covariance the push
  guard's chi2 includes, ``hostpc.kinds.stereo_target.rig_block``) well formed.
- ``check_dataset``: every number (in SI, after unit conversion) within a physical range:
  positions below ``MAX_POSITION_M``, angles below ``MAX_ANGLE_RAD``, covariance standard
  deviations (square roots of the eigenvalues) between ``MIN_STD_M`` and ``MAX_STD_M``, and,
  for ``dual_loop``, a robot name that is a built-in kinematic tree.

Both raise ``hostpc.errors.DatasetError`` (CLI exit code 2).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from hostpc.dataset.measurement_kind import MeasurementKind
from hostpc.dataset.model import Dataset, FramePose, SphereFrame
from hostpc.errors import DatasetError
from hostpc.input_files import DATASET, read_input_bytes

MAX_DATASET_MB_ENV = DATASET.env  # ZEROCAL_MAX_DATASET_MB
DEFAULT_MAX_DATASET_MB = DATASET.default_mb

MAX_POSITION_M = 100.0
"""Largest coordinate or length (m): no robot cell is larger."""
MAX_ANGLE_RAD = 100.0
"""Largest joint angle or orientation angle (rad), about 16 turns."""
MIN_STD_M = 1e-9
"""Smallest believable measurement standard deviation (m): a nanometre."""
MAX_STD_M = 10.0
"""Largest useful measurement standard deviation (m)."""
MAX_PIXEL = 1e6
"""Largest pixel coordinate (px)."""
MAX_SPEED_MPS = 1000.0
"""Largest approach speed (m/s): faster than sound is not a robot."""
MAX_ABS_CONTEXT = 1e9
"""Largest magnitude of other recorded context (time, temperature, extra fields)."""


def max_dataset_bytes() -> int:
    """The size limit of a dataset file in bytes ($ZEROCAL_MAX_DATASET_MB, default 512)."""
    return DATASET.limit_bytes()


def read_dataset_bytes(path: str | os.PathLike[str]) -> bytes:
    """The bytes of a dataset file, refusing what is too large or not a regular file.

    Raises DatasetError (one line naming the file): missing, a directory, a device, a FIFO,
    larger than the limit, unreadable (`hostpc.input_files`, the opening every input file
    shares).
    """
    return read_input_bytes(path, DATASET)


def check_dataset(dataset: Dataset, source: str = "<dataset>",
                  kind: type[MeasurementKind] | None = None) -> Dataset:
    """Return `dataset` if every value is within its physical range; else DatasetError with
    one line: ``source: samples[i].field: value ... outside ...`` (SI units). kind: the
    dataset's measurement kind (a kinematic-tree kind's robot must be a built-in tree; the
    kind checks its own blocks, ``MeasurementKind.check_loaded``)."""
    for field, value, limit, unit in _ranged_values(dataset):
        array = np.asarray(value, dtype=np.float64)
        bad = ~(np.abs(array) < limit) & ~np.isnan(array)  # NaN: padding of absent values
        if bad.any():
            index = tuple(int(i) for i in np.argwhere(bad)[0])
            raise DatasetError(f"{source}: {_location(field, index)}: "
                               f"{float(array[index]):.6g} {unit} is outside the physical "
                               f"range (|value| < {limit:g} {unit})")
    _check_covariances(dataset, source)
    if kind is not None and kind.robot_tree:
        _check_tree_robot(dataset, source)
    if kind is not None:
        kind().check_loaded(dataset, source)
    return dataset


def _location(field: str, index: tuple[int, ...]) -> str:
    """`samples.p` + (3, 1) -> `samples[3].p[1]`; frames and robot fields keep their name."""
    if field.startswith("samples.") and index:
        rest = "".join(f"[{i}]" for i in index[1:])
        return f"samples[{index[0]}].{field[len('samples.'):]}{rest}"
    return field + "".join(f"[{i}]" for i in index)


def _ranged_values(dataset: Dataset) -> Iterator[tuple[str, Any, float, str]]:
    """(field, values, limit, unit) for every number that has a physical range."""
    s = dataset.samples
    yield "samples.q", s.q, MAX_ANGLE_RAD, "rad"
    if s.q_head is not None:
        yield "samples.q_head", s.q_head, MAX_ANGLE_RAD, "rad"
    if s.p is not None:
        yield "samples.p", s.p, MAX_POSITION_M, "m"
    if s.uv is not None:
        yield "samples.uv", s.uv, MAX_PIXEL, "px"
    if s.sigma is not None:
        yield "samples.sigma", s.sigma, MAX_STD_M, "m"
    yield "samples.speed", s.speed, MAX_SPEED_MPS, "m/s"
    yield "samples.t", s.t, MAX_ABS_CONTEXT, "s"
    yield "samples.temperature", s.temperature, MAX_ABS_CONTEXT, ""
    for name, values in s.extra.items():
        yield f"samples.{name}", values, MAX_ABS_CONTEXT, ""
    robot = dataset.robot
    for name in ("a", "d", "com"):
        if getattr(robot, name) is not None:
            yield f"robot.{name}", getattr(robot, name), MAX_POSITION_M, "m"
    for name in ("alpha", "theta"):
        if getattr(robot, name) is not None:
            yield f"robot.{name}", getattr(robot, name), MAX_ANGLE_RAD, "rad"
    for name, frame in dataset.frames.items():
        if isinstance(frame, FramePose):
            yield f"frames.{name}.xyz", frame.xyz, MAX_POSITION_M, "m"
            yield f"frames.{name}.rpy", frame.rpy, MAX_ANGLE_RAD, "rad"
        elif isinstance(frame, SphereFrame):
            yield f"frames.{name}.center", frame.center, MAX_POSITION_M, "m"
            yield f"frames.{name}.radius", frame.radius, MAX_POSITION_M, "m"
        elif isinstance(frame, np.ndarray):
            yield f"frames.{name}", frame, MAX_POSITION_M, "m"
    for name, block in dataset.blocks.items():
        for length, value in block.lengths():
            yield f"{name}.{length}", value, MAX_POSITION_M, "m"


def _check_covariances(dataset: Dataset, source: str) -> None:
    """Standard deviations along the principal axes within [MIN_STD_M, MAX_STD_M]."""
    samples = dataset.samples
    if samples.sigma is not None:
        small = np.flatnonzero(samples.sigma < MIN_STD_M)
        if small.size:
            i = int(small[0])
            raise DatasetError(f"{source}: samples[{i}].sigma: {samples.sigma[i]:.3g} m is "
                               f"below {MIN_STD_M:g} m: no instrument is that precise")
    cov = samples.cov
    if cov is None or cov.size == 0:
        return
    with np.errstate(all="ignore"):
        variances = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    lowest, highest = variances.min(axis=1), variances.max(axis=1)
    for rows, what in (
        (np.flatnonzero(~(lowest >= MIN_STD_M**2)), f"below {MIN_STD_M:g} m"),
        (np.flatnonzero(~(highest <= MAX_STD_M**2)), f"above {MAX_STD_M:g} m"),
    ):
        if rows.size:
            i = int(rows[0])
            extreme = lowest[i] if "below" in what else highest[i]
            std = np.sqrt(max(float(extreme), 0.0))
            raise DatasetError(f"{source}: samples[{i}].cov: standard deviation {std:.3g} m "
                               f"along a principal axis is {what} (not a believable "
                               "measurement covariance)")


def _check_tree_robot(dataset: Dataset, source: str) -> None:
    from hostpc.kinematics.humanoid import tree_names  # a sibling package, imported late

    name = dataset.robot.name
    if name not in tree_names():
        raise DatasetError(f"{source}: robot.name: unknown kinematic tree {name!r} for "
                           f"{dataset.method} (built-in: {', '.join(tree_names())})")
