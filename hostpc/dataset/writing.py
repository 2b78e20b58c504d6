"""Writing ``zerocal-dataset/1``: a ``Dataset`` as a JSON document, and an atomic save.

Saving writes SI units, with floats written so that they read back exactly; the document
is validated (``reading.dataset_from_dict``) before anything is written.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from hostpc.dataset.kind_registry import measurement_kinds
from hostpc.dataset.measurement_kind import MeasurementKind
from hostpc.dataset.model import (
    Dataset,
    Frame,
    FramePose,
    RobotDescription,
    Samples,
    SphereFrame,
)
from hostpc.dataset.reading import PathLike, dataset_from_dict
from hostpc.dataset.schema import FORMAT_TAG
from hostpc.errors import InputError
from hostpc.json_object import JsonObject

_SI_UNITS = {"length": "m", "angle": "rad", "time": "s"}
#: one encoder for every value (``json.dumps`` with options builds a new one per call)
_ENCODER = json.JSONEncoder(ensure_ascii=False, allow_nan=False)


def dataset_to_dict(dataset: Dataset, plugins: Iterable[str | os.PathLike[str]] = ()
                    ) -> JsonObject:
    """The JSON document of ``dataset`` in SI units (inverse of ``dataset_from_dict``).

    Absent optional values (NaN, group -1) are left out; unknown top-level fields that
    were read with the dataset are written back.
    """
    doc: JsonObject = {
        "format": FORMAT_TAG,
        "method": dataset.method,
        "units": dict(_SI_UNITS),
        "robot": _robot_to_dict(dataset.robot),
        "frames": {name: _frame_to_json(value) for name, value in dataset.frames.items()},
        "known": list(dataset.known),
    }
    for name, block in dataset.blocks.items():
        doc[name] = block.to_json()
    kinds = measurement_kinds(plugins)
    if dataset.method not in kinds:
        raise InputError(f"method {dataset.method!r}: no measurement model of that name "
                         "(load its plugin)")
    doc["samples"] = _samples_to_json(kinds[dataset.method](), dataset.samples)
    for key, value in dataset.extra_fields.items():
        if key not in doc:
            doc[key] = copy.deepcopy(value)
    return doc


def save_dataset(dataset: Dataset, path: PathLike,
                 plugins: Iterable[str | os.PathLike[str]] = ()) -> None:
    """Write ``dataset`` as a JSON file in SI units (floats read back exactly).

    The document is validated before writing, so a file that would not load is never
    written; the file is replaced atomically.

    Raises:
        DatasetError: the dataset breaks the format (nothing is written).
        InputError: the file cannot be written.
    """
    target = os.fspath(path)
    doc = dataset_to_dict(dataset, plugins)
    dataset_from_dict(doc, source=f"{target} (not written)", plugins=plugins)
    text = _dumps(doc) + "\n"
    directory = os.path.dirname(os.path.abspath(target))
    try:
        handle, temporary = tempfile.mkstemp(prefix=".zerocal-", suffix=".json.tmp", dir=directory)
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as stream:
                stream.write(text)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(temporary, 0o666 & ~umask)  # mkstemp makes 0600; a dataset is shareable
            os.replace(temporary, target)
        except BaseException:
            os.unlink(temporary)
            raise
    except OSError as exc:
        raise InputError(f"{target}: cannot write file ({exc.strerror or exc})") from exc


def _robot_to_dict(robot: RobotDescription) -> JsonObject:
    if robot.name is not None:
        return {"name": robot.name}
    if robot.urdf is not None:  # extension A; written as an absolute path
        return {"urdf": robot.urdf, "base_link": robot.base_link, "tip_link": robot.tip_link}
    assert robot.a is not None and robot.alpha is not None
    assert robot.d is not None and robot.theta is not None
    out: JsonObject = {
        "convention": robot.convention,
        "joints": [
            {"a": float(a), "alpha": float(alpha), "d": float(d), "theta": float(theta)}
            for a, alpha, d, theta in zip(robot.a, robot.alpha, robot.d, robot.theta, strict=True)
        ],
    }
    if robot.joint_types is not None:
        for row, kind in zip(out["joints"], robot.joint_types, strict=True):
            row["type"] = kind
    if robot.mass is not None:
        out["mass"] = robot.mass.tolist()
    if robot.com is not None:
        out["com"] = robot.com.tolist()
    return out


def frames_to_json(frames: Mapping[str, Frame]) -> JsonObject:
    """Frames as the JSON of a dataset's ``frames`` object, in SI (m, rad): what a saved fit
    records of its dataset (``FitResult.to_dict``; read back by ``frames_from_json``)."""
    return {name: _frame_to_json(value) for name, value in frames.items()}


def frames_from_json(document: Mapping[str, Any], like: Mapping[str, Frame]
                     ) -> dict[str, Frame]:
    """The frames of ``frames_to_json`` (SI) back as values, each read as the frame of the
    same name in ``like`` is (a pose, a point, named points, a sphere); names ``like`` has
    not are left out. ValueError for a value of the wrong shape."""
    frames: dict[str, Frame] = {}
    for name, value in document.items():
        if name not in like:
            continue
        template = like[name]
        try:
            if isinstance(template, FramePose):
                frames[name] = FramePose(xyz=np.asarray(value["xyz"], dtype=float),
                                         rpy=np.asarray(value["rpy"], dtype=float))
            elif isinstance(template, SphereFrame):
                frames[name] = SphereFrame(center=np.asarray(value["center"], dtype=float),
                                           radius=float(value["radius"]))
            elif isinstance(template, np.ndarray):
                frames[name] = np.asarray(value, dtype=float).reshape(3)
            elif isinstance(template, Mapping) and all(
                    isinstance(v, np.ndarray) for v in template.values()):
                frames[name] = {k: np.asarray(v, dtype=float).reshape(3)
                                for k, v in value.items()}
            else:
                frames[name] = copy.deepcopy(value)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f"frames.{name}: not a frame of this kind ({exc})") from None
    return frames


def _frame_to_json(value: Frame) -> Any:
    if isinstance(value, FramePose):
        return {"xyz": value.xyz.tolist(), "rpy": value.rpy.tolist()}
    if isinstance(value, SphereFrame):
        return {"center": value.center.tolist(), "radius": float(value.radius)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict) and all(isinstance(v, np.ndarray) for v in value.values()):
        return {k: v.tolist() for k, v in value.items()}  # named points
    return copy.deepcopy(value)


def _samples_to_json(kind: MeasurementKind, samples: Samples) -> list[JsonObject]:
    """Every sample as JSON: the kind's own fields, then the context fields. Both are
    converted column by column (one finiteness test and one ``tolist`` per array, not per
    sample: the kind's ``write_columns``, where it has its own)."""
    context = []
    for name in ("t", "temperature", "speed"):
        values = np.asarray(getattr(samples, name), dtype=float)
        context.append((name, values.tolist(), np.isfinite(values).tolist()))
    extras = [(key, np.asarray(v, dtype=float).tolist(), np.isfinite(v).tolist())
              for key, v in samples.extra.items()]
    approach_finite = np.isfinite(samples.approach)
    approach = np.where(approach_finite, samples.approach, 0).astype(np.int64).tolist()
    # approach of sample i is written if its first n_joints values are all finite
    finite_prefix = np.cumprod(approach_finite, axis=1).sum(axis=1).tolist()
    uv_rows = uv_finite = None
    if samples.uv is not None:
        uv_rows = samples.uv.tolist()
        uv_finite = np.all(np.isfinite(samples.uv), axis=(1, 2)).tolist()
    written = kind.write_columns(samples) if _writes_columns(type(kind)) else None
    out = []
    for i in range(samples.n):
        if written is not None:
            sample, n_joints = written.sample(i), written.n_joints[i]
        else:
            sample, n_joints = kind.write_sample(samples, i)
        for name, values, finite in context:
            if finite[i]:
                sample[name] = values[i]
        if finite_prefix[i] >= n_joints:
            sample["approach"] = approach[i][:n_joints]
        extra = {key: values[i] for key, values, finite in extras if finite[i]}
        if extra:
            sample["extra"] = extra
        if uv_rows is not None and uv_finite is not None and uv_finite[i]:
            sample["uv"] = uv_rows[i]
        out.append(sample)
    return out


def _writes_columns(cls: type[MeasurementKind]) -> bool:
    """The kind's column writer is its own: its class (or a subclass of it) defines
    ``write_sample`` too (a plugin that overrides ``write_sample`` alone is written sample
    by sample, as it asks)."""
    owner = next(base for base in cls.__mro__ if "write_columns" in vars(base))
    return issubclass(owner, next(base for base in cls.__mro__ if "write_sample" in vars(base)))


def _dumps(value: Any, level: int = 0) -> str:
    """JSON with two-space indent; containers below the second level stay on one line."""

    def nested(v: Any) -> bool:
        items = v.values() if isinstance(v, dict) else v
        return any(isinstance(x, dict | list) for x in items)

    if isinstance(value, dict | list) and value and (level == 0 or (level == 1 and nested(value))):
        pad = "  " * (level + 1)
        if isinstance(value, dict):
            parts = [f"{pad}{json.dumps(k)}: {_dumps(v, level + 1)}" for k, v in value.items()]
            open_, close = "{", "}"
        else:
            parts = [pad + _dumps(v, level + 1) for v in value]
            open_, close = "[", "]"
        return open_ + "\n" + ",\n".join(parts) + "\n" + "  " * level + close
    return _ENCODER.encode(value)
