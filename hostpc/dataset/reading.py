"""Reading ``zerocal-dataset/1``: parse a file, validate it and convert it to a ``Dataset``.

Loading converts the file's units to SI (``units.Units``) and checks everything a fit
relies on; a file that breaks the contract raises ``hostpc.errors.DatasetError`` with one
line naming the file, the field and the sample index, e.g.
``data.json: samples[3].cov: not positive definite``. The document level (format, method,
robot, frames, known, the kind's blocks) is checked here, the samples in ``reading_samples``.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.dataset import schema, validation
from hostpc.dataset.file_units import Units
from hostpc.dataset.kind_registry import measurement_kinds
from hostpc.dataset.measurement_kind import MeasurementKind
from hostpc.dataset.model import (
    Dataset,
    Frame,
    FramePose,
    KindBlock,
    RobotDescription,
    Samples,
    SphereFrame,
)
from hostpc.dataset.reading_columns import NotColumnar, read_columns
from hostpc.dataset.reading_samples import read_samples
from hostpc.dataset.schema import FORMAT_TAG, FieldError, Loc, show
from hostpc.errors import DatasetError, InputError
from hostpc.json_object import JsonObject
from hostpc.kinematics.robots import get_robot

PathLike = str | os.PathLike[str]

def load_dataset(path: PathLike, plugins: Iterable[str | os.PathLike[str]] = ()) -> Dataset:
    """Read and validate a dataset file, converting it to SI units.

    Args:
        path: the ``.json`` file.
        plugins: Python files that may define measurement models (``--plugin``).

    Raises:
        DatasetError: the file is missing, unreadable, not JSON, or breaks the format; the
            one-line message names the file, the field and the sample index.
    """
    source = os.fspath(path)
    raw = validation.read_dataset_bytes(path)  # size limit; devices refused
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{source}: not UTF-8 text (byte {exc.start})") from exc
    try:
        document = json.loads(
            text, parse_constant=schema.NonFinite, object_pairs_hook=schema.pairs_hook
        )
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from exc
    except RecursionError as exc:
        raise DatasetError(f"{source}: not valid JSON (nested too deeply)") from exc
    except ValueError as exc:  # e.g. an integer literal with thousands of digits
        raise DatasetError(f"{source}: not valid JSON ({exc})") from exc
    return dataset_from_dict(document, source, plugins, base_dir=Path(path).parent)


def dataset_from_dict(doc: Any, source: str = "<dict>",
                      plugins: Iterable[str | os.PathLike[str]] = (),
                      base_dir: PathLike | None = None) -> Dataset:
    """Validate a parsed document (what ``json.load`` returns) and convert it to SI.

    Args:
        doc: the document; tuples, numpy arrays and numpy scalars are accepted as well.
        source: name used as the prefix of error messages (a file name).
        plugins: Python files that may define measurement models.
        base_dir: directory a relative ``robot.urdf`` path is resolved against (default:
            the working directory).

    Raises:
        DatasetError: the document breaks the format (one line: source, field, sample).
    """
    kinds = measurement_kinds(plugins)
    try:
        dataset = _columnar_dataset(doc, kinds, base_dir)
        if dataset is None:  # read sample by sample: the error names the first bad sample
            dataset = _dataset_from_document(schema.normalize(doc), kinds, base_dir)
        return validation.check_dataset(dataset, source, kinds[dataset.method])
    except FieldError as exc:
        raise DatasetError(f"{source}: {exc}") from exc
    except RecursionError as exc:
        raise DatasetError(f"{source}: nested too deeply") from exc


def _columnar_dataset(doc: Any, kinds: Mapping[str, type[MeasurementKind]],
                      base_dir: PathLike | None) -> Dataset | None:
    """The dataset read by whole columns (``reading_columns``), or None where the file
    needs the sample-by-sample reader (any error, any irregular sample)."""
    if not (type(doc) is dict and type(doc.get("samples")) is list and doc["samples"]):
        return None
    try:
        head = schema.normalize({key: value for key, value in doc.items() if key != "samples"})
        return _dataset_from_document({**head, "samples": []}, kinds, base_dir,
                                      columnar_samples=doc["samples"])
    except (FieldError, NotColumnar, RecursionError):
        return None


def _dataset_from_document(doc: Any, kinds: Mapping[str, type[MeasurementKind]],
                           base_dir: PathLike | None = None,
                           columnar_samples: list[Any] | None = None) -> Dataset:
    """Build the dataset from a normalized document; raises FieldError.

    With ``columnar_samples`` (the raw samples; ``doc`` holds none), the samples are read by
    columns, and NotColumnar is raised where they cannot be."""
    if not isinstance(doc, dict):
        raise FieldError((), f"expected a JSON object at the top level, got {show(doc)}")
    if "format" not in doc:
        raise FieldError(("format",), f"required field missing (expected '{FORMAT_TAG}')")
    if doc["format"] != FORMAT_TAG:
        raise FieldError(("format",), f"expected '{FORMAT_TAG}', got {show(doc['format'])}")
    if "method" not in doc:
        raise FieldError(("method",), "required field missing")
    method = doc["method"]
    if not isinstance(method, str) or method not in kinds:
        expected = ", ".join(f"'{m}'" for m in kinds)
        plugin = (f"; if a plugin folder defines the kind {method!r}, add --plugin FOLDER "
                  "(the folder whose __init__.py declares it)" if isinstance(method, str)
                  and method.isidentifier() else "")
        raise FieldError(("method",), f"unknown method {show(method)} (expected {expected})"
                         f"{plugin}")
    kind = kinds[method]()

    document = schema.validate_document(doc)
    if not document.samples and columnar_samples is None:
        raise FieldError(("samples",), "no samples (expected at least one)")
    units = Units(document.units)
    n_joints: int | None
    if document.robot.urdf is not None:  # extension A (hostpc.kinematics.urdf)
        robot, n_joints, robot_label = read_urdf_robot(document.robot, kind, base_dir)
    else:
        robot, n_joints, robot_label = _read_robot(document.robot, kind, units)
    frames = _read_frames(document.frames, kind, units)
    known = _read_known(document.known, frames)
    blocks = _read_blocks(doc, kind, kinds, units)
    if columnar_samples is not None:
        fast = read_columns(columnar_samples, kind, n_joints, units)
        if fast is None:
            raise NotColumnar
        kind.check_samples(fast, frames)
        samples = fast
    else:
        samples = read_samples(document.samples, kind, n_joints, robot_label, units, frames)
    samples = prismatic_q_to_length(samples, robot, units)
    extra_fields = {k: v for k, v in doc.items()
                    if k not in schema.DOCUMENT_FIELDS and k not in kind.document_blocks}
    return Dataset(
        method=method,
        robot=robot,
        frames=frames,
        samples=samples,
        known=known,
        blocks=blocks,
        extra_fields=extra_fields,
    )


def read_urdf_robot(robot: schema.RobotSchema, kind: MeasurementKind, base_dir: PathLike | None
                    ) -> tuple[RobotDescription, int, str]:
    """Extension A: ``{"urdf": PATH, "base_link", "tip_link"}``, PATH relative to the file."""
    from hostpc.kinematics.urdf import load_urdf_chain  # imported late: a sibling package

    for key in ("name", "convention", "joints", "mass", "com"):
        if getattr(robot, key) is not None:
            raise FieldError(("robot", key), "not allowed with 'urdf'")
    if kind.robot_tree:
        raise FieldError(("robot", "urdf"), f"{kind.name} needs a built-in robot 'name'")
    for key in ("base_link", "tip_link"):
        if not getattr(robot, key):
            raise FieldError(("robot", key), "required with 'urdf'")
    assert robot.urdf is not None and robot.base_link and robot.tip_link
    path = Path(base_dir or ".") / robot.urdf
    try:
        n = load_urdf_chain(path, robot.base_link, robot.tip_link).n
    except InputError as exc:
        raise FieldError(("robot", "urdf"), " ".join(str(exc).split())) from exc
    description = RobotDescription(urdf=os.fspath(path.resolve()), base_link=robot.base_link,
                                   tip_link=robot.tip_link)
    return description, n, f"the URDF chain's {n} joints"


def prismatic_q_to_length(samples: Samples, robot: RobotDescription, units: Units) -> Samples:
    """Extension A: prismatic joints' ``q`` is a length; reading converted it as an angle."""
    if robot.urdf is not None:
        from hostpc.kinematics.urdf import load_urdf_chain

        assert robot.base_link and robot.tip_link
        prismatic = load_urdf_chain(robot.urdf, robot.base_link, robot.tip_link).prismatic
    elif robot.joint_types is not None:
        prismatic = np.array([kind == "prismatic" for kind in robot.joint_types])
    else:
        return samples
    assert prismatic is not None
    if not prismatic.any():
        return samples
    q = np.array(samples.q, dtype=np.float64)
    raw = np.rad2deg(q[:, prismatic]) if units.units.angle == "deg" else q[:, prismatic]
    q[:, prismatic] = units.length(raw)
    return dataclasses.replace(samples, q=q)


def _robot_joint_count(name: str) -> int:
    """Joint count of a built-in robot; raises FieldError for an unknown name."""
    try:
        return int(get_robot(name).n)
    except InputError as exc:
        message = " ".join(str(exc).split()) or f"unknown robot {show(name)}"
        raise FieldError(("robot", "name"), message) from exc


def _read_robot(
    robot: schema.RobotSchema, kind: MeasurementKind, units: Units
) -> tuple[RobotDescription, int | None, str]:
    """The robot description, its joint count (None if not resolved) and a label."""
    explicit_keys = [
        k for k in ("convention", "joints", "mass", "com") if getattr(robot, k) is not None
    ]
    if robot.name is not None:
        if explicit_keys:
            raise FieldError(
                ("robot", explicit_keys[0]),
                "not allowed with 'name' (give a built-in 'name' or an explicit description)",
            )
        if kind.robot_tree:  # a kinematic tree; the samples give the joint counts
            return RobotDescription(name=robot.name), None, f"robot '{robot.name}'"
        n = _robot_joint_count(robot.name)
        return RobotDescription(name=robot.name), n, f"robot '{robot.name}'"
    if not explicit_keys:
        raise FieldError(
            ("robot",), "expected 'name' (built-in robot) or 'convention' and 'joints'"
        )
    if kind.robot_tree:
        raise FieldError(
            ("robot",), f"{kind.name} needs a built-in robot 'name' (chains head, left, right)"
        )
    if robot.convention is None:
        raise FieldError(("robot", "convention"), "required field missing ('dh' or 'mdh')")
    if robot.joints is None:
        raise FieldError(("robot", "joints"), "required field missing")
    if not robot.joints:
        raise FieldError(("robot", "joints"), "expected at least one joint")
    n = len(robot.joints)
    mass = com = None
    if robot.mass is not None:
        _check_count(("robot", "mass"), robot.mass, n, "one per joint")
        for i, value in enumerate(robot.mass):
            if value < 0:
                raise FieldError(("robot", "mass", i), f"must be >= 0, got {show(value)}")
        mass = np.asarray(robot.mass, dtype=np.float64)
    if robot.com is not None:
        _check_count(("robot", "com"), robot.com, n, "one per joint")
        com = units.length(robot.com)
    description = RobotDescription(
        convention=robot.convention,
        a=units.length([row.a for row in robot.joints]),
        alpha=units.angle([row.alpha for row in robot.joints]),
        d=units.length([row.d for row in robot.joints]),
        theta=units.angle([row.theta for row in robot.joints]),
        mass=mass,
        com=com,
        joint_types=(tuple(row.type for row in robot.joints)
                     if any(row.type != "revolute" for row in robot.joints) else None),
    )
    return description, n, f"the robot's {n} joints"


def _check_count(loc: Loc, values: Sequence[Any], n: int, what: str) -> None:
    if len(values) != n:
        raise FieldError(loc, f"expected {n} values ({what}), got {len(values)}")


def _read_frames(frames: JsonObject, method: MeasurementKind, units: Units
                 ) -> dict[str, Frame]:
    """The nominal frames of ``method`` in SI."""
    kinds = method.frames
    for name in frames:
        if name not in kinds:
            expected = ", ".join(kinds)
            raise FieldError(
                ("frames", name),
                f"unknown frame for method '{method.name}' (expected {expected})",
            )
    result: dict[str, Frame] = {}
    for name, kind in kinds.items():
        loc: Loc = ("frames", name)
        if name not in frames:
            if name in method.optional_frames:
                continue
            raise FieldError(loc, "required field missing")
        value = frames[name]
        if kind == "pose":
            pose = schema.validate_frame_pose(value, loc)
            result[name] = FramePose(xyz=units.length(pose.xyz), rpy=units.angle(pose.rpy))
        elif kind == "tip":
            tip: schema.TipFrameSchema = schema.validate(schema.TipFrameSchema, value, loc)
            rpy = np.zeros(3) if tip.rpy is None else units.angle(tip.rpy)
            result[name] = FramePose(xyz=units.length(tip.xyz), rpy=rpy)
        elif kind == "point":
            result[name] = units.length(schema.validate_vec3(value, loc))
        elif kind == "points":
            points = schema.validate_points(value, loc)
            if not points:
                raise FieldError(loc, "expected at least one named point")
            result[name] = {key: units.length(point) for key, point in points.items()}
        elif kind == "sphere":
            sphere: schema.SphereSchema = schema.validate(schema.SphereSchema, value, loc)
            if sphere.radius <= 0:
                raise FieldError((*loc, "radius"), f"must be positive, got {show(sphere.radius)}")
            result[name] = SphereFrame(
                center=units.length(sphere.center), radius=float(units.length(sphere.radius))
            )
        else:  # the stereo camera model: kept as given, not converted
            if not isinstance(value, dict):
                raise FieldError(loc, f"expected a JSON object, got {show(value)}")
            result[name] = copy.deepcopy(value)
    return result


def _read_known(known: list[str], frames: Mapping[str, Frame]) -> tuple[str, ...]:
    seen: set[str] = set()
    for i, name in enumerate(known):
        if name not in frames:
            available = ", ".join(frames)
            raise FieldError(
                ("known", i), f"no frame named {show(name)} in frames (frames: {available})"
            )
        if name in seen:
            raise FieldError(("known", i), f"{show(name)} listed twice")
        seen.add(name)
    return tuple(known)


def _read_blocks(doc: JsonObject, kind: MeasurementKind,
                 kinds: Mapping[str, type[MeasurementKind]], units: Units
                 ) -> dict[str, KindBlock]:
    """The kind's own top-level blocks (``MeasurementKind.read_block``); another kind's
    block in this kind's file is an error."""
    for other in kinds.values():
        for name in other.document_blocks:
            if name in doc and name not in kind.document_blocks:
                raise FieldError((name,), f"not a field of method '{kind.name}'")
    blocks = {}
    for name in kind.document_blocks:
        block = kind.read_block(name, doc.get(name), units)
        if block is not None:
            blocks[name] = block
    return blocks
