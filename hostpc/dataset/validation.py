"""Hostile and careless input: the size of a dataset file, and physical ranges of its values.

The format layer (``reading``, ``schema``) checks that a dataset is well formed: types,
shapes, finite numbers, positive-definite covariances. This module adds what a fit needs
beyond that, so that a damaged or malicious file is refused at load with one line naming the
file, the sample and the field instead of overflowing inside the solver:

- ``read_dataset_bytes``: a size limit (``ZEROCAL_MAX_DATASET_MB``, default 512 MB); a
  device (``/dev/zero``) is refused at once, a pipe is read up to the limit only.
- ``check_dataset``: every number (in SI, after unit conversion) within a physical range:
  positions below ``MAX_POSITION_M``, angles below ``MAX_ANGLE_RAD``, covariance standard
  deviations (square roots of the eigenvalues) between ``MIN_STD_M`` and ``MAX_STD_M``, and,
  for ``dual_loop``, a robot name that is a built-in kinematic tree.

Both raise ``hostpc.errors.DatasetError`` (CLI exit code 2).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from typing import Any

import numpy as np

from hostpc.dataset.model import Dataset, FramePose, SphereFrame
from hostpc.errors import DatasetError, InputError

MAX_DATASET_MB_ENV = "ZEROCAL_MAX_DATASET_MB"
DEFAULT_MAX_DATASET_MB = 512.0
READ_CHUNK = 1 << 20

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
    text = os.environ.get(MAX_DATASET_MB_ENV)
    if text is None or not text.strip():
        return int(DEFAULT_MAX_DATASET_MB * 1e6)
    try:
        megabytes = float(text)
    except ValueError:
        megabytes = float("nan")
    if not (np.isfinite(megabytes) and megabytes > 0):
        raise InputError(f"${MAX_DATASET_MB_ENV}={text!r}: expected a positive number of MB")
    return int(megabytes * 1e6)


def read_dataset_bytes(path: str | os.PathLike[str]) -> bytes:
    """The bytes of a dataset file, refusing what is too large or not a file.

    Raises DatasetError (one line naming the file): missing, a directory, a device, larger
    than the limit (a pipe: read up to the limit, then refused), unreadable.
    """
    source = os.fspath(path)
    limit = max_dataset_bytes()
    try:
        with open(path, "rb") as handle:
            mode = os.fstat(handle.fileno()).st_mode
            if stat.S_ISDIR(mode):
                raise DatasetError(f"{source}: is a directory, not a dataset file")
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) or stat.S_ISSOCK(mode):
                raise DatasetError(f"{source}: not a regular file (a device); give a dataset file")
            if stat.S_ISREG(mode):
                size = os.fstat(handle.fileno()).st_size
                if size > limit:
                    raise DatasetError(_too_large(source, size, limit))
                return handle.read(limit + 1)
            data = bytearray()  # a pipe: no size known, read no more than the limit
            while chunk := handle.read(READ_CHUNK):
                data += chunk
                if len(data) > limit:
                    raise DatasetError(_too_large(source, None, limit))
            return bytes(data)
    except FileNotFoundError as exc:
        raise DatasetError(f"{source}: file not found") from exc
    except IsADirectoryError as exc:
        raise DatasetError(f"{source}: is a directory, not a dataset file") from exc
    except OSError as exc:
        raise DatasetError(f"{source}: cannot read file ({exc.strerror or exc})") from exc


def _too_large(source: str, size: int | None, limit: int) -> str:
    what = f"{size / 1e6:.1f} MB" if size is not None else "more than that"
    return (f"{source}: {what}, above the dataset size limit of {limit / 1e6:g} MB "
            f"(set ${MAX_DATASET_MB_ENV} to raise it)")


def check_dataset(dataset: Dataset, source: str = "<dataset>") -> Dataset:
    """Return `dataset` if every value is within its physical range; else DatasetError with
    one line: ``source: samples[i].field: value ... outside ...`` (SI units)."""
    for field, value, limit, unit in _ranged_values(dataset):
        array = np.asarray(value, dtype=np.float64)
        bad = ~(np.abs(array) < limit) & ~np.isnan(array)  # NaN: padding of absent values
        if bad.any():
            index = tuple(int(i) for i in np.argwhere(bad)[0])
            raise DatasetError(f"{source}: {_location(field, index)}: "
                               f"{float(array[index]):.6g} {unit} is outside the physical "
                               f"range (|value| < {limit:g} {unit})")
    _check_covariances(dataset, source)
    _check_dual_loop_robot(dataset, source)
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
    if dataset.probe_stylus_radius is not None:
        yield "probe.stylus_radius", dataset.probe_stylus_radius, MAX_POSITION_M, "m"


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


def _check_dual_loop_robot(dataset: Dataset, source: str) -> None:
    if dataset.method != "dual_loop":
        return
    from hostpc.kinematics.humanoid import tree_names  # a sibling package, imported late

    name = dataset.robot.name
    if name not in tree_names():
        raise DatasetError(f"{source}: robot.name: unknown kinematic tree {name!r} for "
                           f"dual_loop (built-in: {', '.join(tree_names())})")
