"""Load, validate, convert and save ``zerocal-dataset/1`` files.

The contract is ``shared/spec/dataset-format.md``; the user documentation is
``docs/dataset-format.md``. Loading converts the file's units to SI (m, rad, s) and checks
everything a fit relies on; a file that breaks the contract raises
``hostpc.errors.DatasetError`` with one line naming the file, the field and the sample
index, e.g. ``data.json: samples[3].cov: not positive definite``. Saving writes SI units,
with floats written so that they read back exactly.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.model import (
    METHODS,
    Dataset,
    FloatArray,
    FramePose,
    RobotDescription,
    Samples,
    SphereFrame,
)
from hostpc.dataset.schema import FORMAT_TAG, FieldError, Loc, show
from hostpc.errors import DatasetError, InputError

PathLike = str | os.PathLike[str]

# Sample fields each method accepts (besides these, a sample field is an error).
_CONTEXT_FIELDS = frozenset({"t", "approach", "temperature", "speed", "extra"})
_SAMPLE_FIELDS: dict[str, frozenset[str]] = {
    "stereo_target": frozenset({"q", "p", "cov", "sigma", "uv"}) | _CONTEXT_FIELDS,
    "sphere_probe": frozenset({"q", "sigma", "group"}) | _CONTEXT_FIELDS,
    "dual_loop": frozenset({"chain", "q_head", "q_arm", "p", "cov", "sigma", "uv"})
    | _CONTEXT_FIELDS,
}
_SAMPLE_HINTS = {
    ("dual_loop", "q"): " (dual_loop uses 'q_arm' and 'q_head')",
    ("stereo_target", "q_arm"): " (use 'q')",
    ("sphere_probe", "q_arm"): " (use 'q')",
    ("sphere_probe", "cov"): " (give the contact-distance 'sigma')",
    ("sphere_probe", "p"): " (a contact has no measured point)",
}

# Frames each method knows, with their kind; all but the stereo camera model are required.
_FRAMES: dict[str, dict[str, str]] = {
    "stereo_target": {"tool": "pose", "target": "point", "camera": "camera_model"},
    "sphere_probe": {"tool": "tip", "sphere": "sphere"},
    "dual_loop": {
        "camera": "pose",
        "left_base": "pose",
        "right_base": "pose",
        "left_target": "point",
        "right_target": "point",
    },
}
_OPTIONAL_FRAMES = frozenset({"camera_model"})

_SI_UNITS = {"length": "m", "angle": "rad", "time": "s"}
_SYMMETRY_TOLERANCE = 1e-6  # relative to the largest entry of the matrix


# --------------------------------------------------------------------------- public API


def load_dataset(path: PathLike) -> Dataset:
    """Read and validate a dataset file, converting it to SI units.

    Args:
        path: the ``.json`` file.

    Raises:
        DatasetError: the file is missing, unreadable, not JSON, or breaks the format; the
            one-line message names the file, the field and the sample index.
    """
    source = os.fspath(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError as exc:
        raise DatasetError(f"{source}: file not found") from exc
    except IsADirectoryError as exc:
        raise DatasetError(f"{source}: is a directory, not a dataset file") from exc
    except OSError as exc:
        raise DatasetError(f"{source}: cannot read file ({exc.strerror or exc})") from exc
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
    return dataset_from_dict(document, source)


def dataset_from_dict(doc: Any, source: str = "<dict>") -> Dataset:
    """Validate a parsed document (what ``json.load`` returns) and convert it to SI.

    Args:
        doc: the document; tuples, numpy arrays and numpy scalars are accepted as well.
        source: name used as the prefix of error messages (a file name).

    Raises:
        DatasetError: the document breaks the format (one line: source, field, sample).
    """
    try:
        return _dataset_from_document(schema.normalize(doc))
    except FieldError as exc:
        raise DatasetError(f"{source}: {exc}") from exc
    except RecursionError as exc:
        raise DatasetError(f"{source}: nested too deeply") from exc


def dataset_to_dict(dataset: Dataset) -> dict[str, Any]:
    """The JSON document of ``dataset`` in SI units (inverse of ``dataset_from_dict``).

    Absent optional values (NaN, group -1) are left out; unknown top-level fields that
    were read with the dataset are written back.
    """
    doc: dict[str, Any] = {
        "format": FORMAT_TAG,
        "method": dataset.method,
        "units": dict(_SI_UNITS),
        "robot": _robot_to_dict(dataset.robot),
        "frames": {name: _frame_to_json(value) for name, value in dataset.frames.items()},
        "known": list(dataset.known),
    }
    if dataset.probe_stylus_radius is not None:
        doc["probe"] = {"stylus_radius": float(dataset.probe_stylus_radius)}
    doc["samples"] = _samples_to_json(dataset.method, dataset.samples)
    for key, value in dataset.extra_fields.items():
        if key not in doc:
            doc[key] = copy.deepcopy(value)
    return doc


def save_dataset(dataset: Dataset, path: PathLike) -> None:
    """Write ``dataset`` as a JSON file in SI units (floats read back exactly).

    The document is validated before writing, so a file that would not load is never
    written; the file is replaced atomically.

    Raises:
        DatasetError: the dataset breaks the format (nothing is written).
        InputError: the file cannot be written.
    """
    target = os.fspath(path)
    doc = dataset_to_dict(dataset)
    dataset_from_dict(doc, source=f"{target} (not written)")
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


# --------------------------------------------------------------------------- units


class _Units:
    """Conversion of the file's numbers to SI."""

    def __init__(self, units: schema.UnitsSchema) -> None:
        self.units = units

    def length(self, value: Any) -> FloatArray:
        """File length -> m."""
        array = np.asarray(value, dtype=np.float64)
        return array / 1000.0 if self.units.length == "mm" else array

    def area(self, value: Any) -> FloatArray:
        """File length^2 (a covariance) -> m^2."""
        return self.length(self.length(value))

    def angle(self, value: Any) -> FloatArray:
        """File angle -> rad."""
        array = np.asarray(value, dtype=np.float64)
        return np.deg2rad(array) if self.units.angle == "deg" else array

    def time(self, value: Any) -> FloatArray:
        """File time -> s."""
        array = np.asarray(value, dtype=np.float64)
        return array / 1000.0 if self.units.time == "ms" else array

    def speed(self, value: Any) -> FloatArray:
        """File length/time -> m/s."""
        array = self.length(value)
        return array * 1000.0 if self.units.time == "ms" else array


# --------------------------------------------------------------------------- reading


def _dataset_from_document(doc: Any) -> Dataset:
    """Build the dataset from a normalized document; raises FieldError."""
    if not isinstance(doc, dict):
        raise FieldError((), f"expected a JSON object at the top level, got {show(doc)}")
    if "format" not in doc:
        raise FieldError(("format",), f"required field missing (expected '{FORMAT_TAG}')")
    if doc["format"] != FORMAT_TAG:
        raise FieldError(("format",), f"expected '{FORMAT_TAG}', got {show(doc['format'])}")
    if "method" not in doc:
        raise FieldError(("method",), "required field missing")
    method = doc["method"]
    if method not in METHODS:
        expected = ", ".join(f"'{m}'" for m in METHODS)
        raise FieldError(("method",), f"unknown method {show(method)} (expected {expected})")

    document: schema.DocumentSchema = schema.validate(schema.DocumentSchema, doc)
    if not document.samples:
        raise FieldError(("samples",), "no samples (expected at least one)")
    units = _Units(document.units)
    robot, n_joints, robot_label = _read_robot(document.robot, method, units)
    frames = _read_frames(document.frames, method, units)
    known = _read_known(document.known, frames)
    stylus_radius = _read_probe(document.probe, method, units)
    samples = _read_samples(document.samples, method, n_joints, robot_label, units)
    extra_fields = {k: v for k, v in doc.items() if k not in schema.DOCUMENT_FIELDS}
    return Dataset(
        method=method,
        robot=robot,
        frames=frames,
        samples=samples,
        known=known,
        probe_stylus_radius=stylus_radius,
        extra_fields=extra_fields,
    )


def _robot_joint_count(name: str) -> int:
    """Joint count of a built-in robot; raises FieldError for an unknown name."""
    from hostpc.kinematics.robots import get_robot  # imported late: a sibling package

    try:
        return int(get_robot(name).n)
    except InputError as exc:
        message = " ".join(str(exc).split()) or f"unknown robot {show(name)}"
        raise FieldError(("robot", "name"), message) from exc


def _read_robot(
    robot: schema.RobotSchema, method: str, units: _Units
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
        if method == "dual_loop":  # a kinematic tree; the samples give the joint counts
            return RobotDescription(name=robot.name), None, f"robot '{robot.name}'"
        n = _robot_joint_count(robot.name)
        return RobotDescription(name=robot.name), n, f"robot '{robot.name}'"
    if not explicit_keys:
        raise FieldError(
            ("robot",), "expected 'name' (built-in robot) or 'convention' and 'joints'"
        )
    if method == "dual_loop":
        raise FieldError(
            ("robot",), "dual_loop needs a built-in robot 'name' (chains head, left, right)"
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
    )
    return description, n, f"the robot's {n} joints"


def _check_count(loc: Loc, values: Sequence[Any], n: int, what: str) -> None:
    if len(values) != n:
        raise FieldError(loc, f"expected {n} values ({what}), got {len(values)}")


def _read_frames(frames: dict[str, Any], method: str, units: _Units) -> dict[str, Any]:
    """The nominal frames of ``method`` in SI."""
    kinds = _FRAMES[method]
    for name in frames:
        if name not in kinds:
            expected = ", ".join(kinds)
            raise FieldError(
                ("frames", name), f"unknown frame for method '{method}' (expected {expected})"
            )
    result: dict[str, Any] = {}
    for name, kind in kinds.items():
        loc: Loc = ("frames", name)
        if name not in frames:
            if kind in _OPTIONAL_FRAMES:
                continue
            raise FieldError(loc, "required field missing")
        value = frames[name]
        if kind == "pose":
            pose: schema.FramePoseSchema = schema.validate(schema.FramePoseSchema, value, loc)
            result[name] = FramePose(xyz=units.length(pose.xyz), rpy=units.angle(pose.rpy))
        elif kind == "tip":
            tip: schema.TipFrameSchema = schema.validate(schema.TipFrameSchema, value, loc)
            rpy = np.zeros(3) if tip.rpy is None else units.angle(tip.rpy)
            result[name] = FramePose(xyz=units.length(tip.xyz), rpy=rpy)
        elif kind == "point":
            result[name] = units.length(schema.validate(schema.Vec3, value, loc))
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


def _read_known(known: list[str], frames: Mapping[str, Any]) -> tuple[str, ...]:
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


def _read_probe(probe: schema.ProbeSchema | None, method: str, units: _Units) -> float | None:
    if method != "sphere_probe":
        if probe is not None:
            raise FieldError(("probe",), f"not a field of method '{method}'")
        return None
    if probe is None:
        raise FieldError(("probe",), 'required field missing ({"stylus_radius": r})')
    if probe.stylus_radius < 0:
        raise FieldError(
            ("probe", "stylus_radius"), f"must be >= 0, got {show(probe.stylus_radius)}"
        )
    return float(units.length(probe.stylus_radius))


def _require(sample: schema.SampleSchema, loc: Loc, name: str, hint: str = "") -> Any:
    value = getattr(sample, name)
    if value is None:
        raise FieldError((*loc, name), "required field missing" + hint)
    return value


def _check_joint_count(loc: Loc, values: list[float], n: int, label: str) -> None:
    if len(values) != n:
        raise FieldError(loc, f"expected {n} joint angles for {label}, got {len(values)}")


def _check_covariance(loc: Loc, cov: FloatArray) -> None:
    """(3, 3) covariance in m^2: finite, symmetric, positive definite."""
    if not np.all(np.isfinite(cov)):
        raise FieldError(loc, "out of range after unit conversion")
    scale = float(np.max(np.abs(cov)))
    if float(np.max(np.abs(cov - cov.T))) > _SYMMETRY_TOLERANCE * scale:
        raise FieldError(loc, "not symmetric")
    try:
        lower = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise FieldError(loc, "not positive definite") from None
    if not (np.all(np.isfinite(lower)) and np.all(np.diag(lower) > 0)):
        raise FieldError(loc, "not positive definite")


def _positive(loc: Loc, value: float) -> float:
    if not value > 0:
        raise FieldError(loc, f"must be positive, got {show(value)}")
    return value


class _Columns:
    """Per-sample optional values gathered into arrays (NaN / -1 where absent)."""

    def __init__(self, n_samples: int) -> None:
        self.n_samples = n_samples
        self.values: dict[str, list[Any]] = {}

    def put(self, name: str, index: int, value: Any) -> None:
        self.values.setdefault(name, [None] * self.n_samples)[index] = value

    def given(self, name: str) -> bool:
        return name in self.values

    def floats(self, name: str, convert: Callable[[Any], FloatArray]) -> FloatArray:
        column = self.values.get(name, [None] * self.n_samples)
        return convert([np.nan if v is None else v for v in column])

    def rows(self, name: str, width: int) -> FloatArray:
        """Rows of possibly different length, NaN-padded to ``width``."""
        out = np.full((self.n_samples, width), np.nan)
        for i, row in enumerate(self.values.get(name, [])):
            if row is not None:
                out[i, : len(row)] = row
        return out


def _read_samples(
    samples: list[schema.SampleSchema],
    method: str,
    n_joints: int | None,
    robot_label: str,
    units: _Units,
) -> Samples:
    """Check every sample against ``method`` and build the arrays in SI."""
    allowed = _SAMPLE_FIELDS[method]
    columns = _Columns(len(samples))
    head_width: tuple[int, int] | None = None  # (width, first sample)
    arm_width: dict[str, tuple[int, int]] = {}
    extra_names: dict[str, None] = {}

    for i, sample in enumerate(samples):
        loc: Loc = ("samples", i)
        for name in schema.SAMPLE_FIELDS:
            if name in sample.model_fields_set and name not in allowed:
                hint = _SAMPLE_HINTS.get((method, name), "")
                raise FieldError((*loc, name), f"not a field of method '{method}'{hint}")

        if method == "dual_loop":
            chain = _require(sample, loc, "chain", " ('left' or 'right')")
            q_head = _require(sample, loc, "q_head")
            q = _require(sample, loc, "q_arm")
            for name, values in (("q_head", q_head), ("q_arm", q)):
                if not values:
                    raise FieldError((*loc, name), "expected at least one joint angle")
            if head_width is None:
                head_width = (len(q_head), i)
            _check_joint_count(
                (*loc, "q_head"),
                q_head,
                head_width[0],
                f"the head (as in samples[{head_width[1]}].q_head)",
            )
            width, first = arm_width.setdefault(chain, (len(q), i))
            _check_joint_count(
                (*loc, "q_arm"),
                q,
                width,
                f"chain '{chain}' (as in samples[{first}].q_arm)",
            )
            columns.put("chain", i, chain)
            columns.put("q_head", i, q_head)
        else:
            q = _require(sample, loc, "q")
            assert n_joints is not None
            _check_joint_count((*loc, "q"), q, n_joints, robot_label)
        columns.put("q", i, q)

        if method == "sphere_probe":
            sigma = _positive((*loc, "sigma"), _require(sample, loc, "sigma"))
            columns.put("sigma", i, sigma)
            if sample.group is not None:
                columns.put("group", i, sample.group)
        else:
            columns.put("p", i, _require(sample, loc, "p"))
            if sample.cov is not None and sample.sigma is not None:
                raise FieldError((*loc, "sigma"), "give either 'cov' or 'sigma', not both")
            if sample.cov is not None:
                cov = units.area(sample.cov)
            elif sample.sigma is not None:
                sigma_m = float(units.length(_positive((*loc, "sigma"), sample.sigma)))
                variance = sigma_m * sigma_m  # float product: inf on overflow, no exception
                if not 0 < variance < np.inf:
                    raise FieldError((*loc, "sigma"), f"out of range, got {show(sample.sigma)}")
                cov = variance * np.eye(3)
            else:
                raise FieldError((*loc, "cov"), "required field missing (or give 'sigma')")
            _check_covariance((*loc, "cov" if sample.cov is not None else "sigma"), cov)
            columns.put("cov", i, cov)

        if sample.approach is not None:
            if len(sample.approach) != len(q):
                raise FieldError(
                    (*loc, "approach"),
                    f"expected {len(q)} values (one per joint), got {len(sample.approach)}",
                )
            for j, sign in enumerate(sample.approach):
                if sign not in (1.0, -1.0):
                    raise FieldError((*loc, "approach", j), f"expected +1 or -1, got {show(sign)}")
            columns.put("approach", i, sample.approach)
        for name in ("t", "temperature", "speed", "uv"):
            if getattr(sample, name) is not None:
                columns.put(name, i, getattr(sample, name))
        for key, value in (sample.extra or {}).items():
            extra_names[key] = None
            columns.put("extra." + key, i, value)

    speed = columns.floats("speed", units.speed)
    for index in np.flatnonzero(np.isinf(speed)):
        raise FieldError(("samples", int(index), "speed"), "out of range after unit conversion")

    width = max(len(row) for row in columns.values["q"])
    is_dual = method == "dual_loop"
    uv = None
    if columns.given("uv"):
        uv = np.full((len(samples), 2, 2), np.nan)
        for i, value in enumerate(columns.values["uv"]):
            if value is not None:
                uv[i] = value
    return Samples(
        q=units.angle(columns.rows("q", width)),
        p=None if method == "sphere_probe" else units.length(columns.values["p"]),
        cov=None if method == "sphere_probe" else np.asarray(columns.values["cov"]),
        sigma=units.length(columns.values["sigma"]) if method == "sphere_probe" else None,
        t=columns.floats("t", units.time),
        temperature=columns.floats("temperature", np.asarray),
        speed=speed,
        approach=columns.rows("approach", width),
        group=_groups(columns),
        extra={k: columns.floats("extra." + k, np.asarray) for k in extra_names},
        uv=uv,
        chain=np.asarray(columns.values["chain"], dtype=np.str_) if is_dual else None,
        q_head=units.angle(columns.values["q_head"]) if is_dual else None,
    )


def _groups(columns: _Columns) -> Any:
    """(N,) int group index, -1 where absent."""
    column = columns.values.get("group", [None] * columns.n_samples)
    return np.asarray([-1 if g is None else g for g in column], dtype=np.int64)


# --------------------------------------------------------------------------- writing


def _robot_to_dict(robot: RobotDescription) -> dict[str, Any]:
    if robot.name is not None:
        return {"name": robot.name}
    assert robot.a is not None and robot.alpha is not None
    assert robot.d is not None and robot.theta is not None
    out: dict[str, Any] = {
        "convention": robot.convention,
        "joints": [
            {"a": float(a), "alpha": float(alpha), "d": float(d), "theta": float(theta)}
            for a, alpha, d, theta in zip(robot.a, robot.alpha, robot.d, robot.theta, strict=True)
        ],
    }
    if robot.mass is not None:
        out["mass"] = robot.mass.tolist()
    if robot.com is not None:
        out["com"] = robot.com.tolist()
    return out


def _frame_to_json(value: Any) -> Any:
    if isinstance(value, FramePose):
        return {"xyz": value.xyz.tolist(), "rpy": value.rpy.tolist()}
    if isinstance(value, SphereFrame):
        return {"center": value.center.tolist(), "radius": float(value.radius)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    return copy.deepcopy(value)


def _samples_to_json(method: str, samples: Samples) -> list[dict[str, Any]]:
    out = []
    for i in range(samples.n):
        q_row = samples.q[i]
        q = q_row[~np.isnan(q_row)] if method == "dual_loop" else q_row
        sample: dict[str, Any] = {}
        if method == "dual_loop":
            assert samples.chain is not None and samples.q_head is not None
            sample["chain"] = str(samples.chain[i])
            sample["q_head"] = samples.q_head[i].tolist()
            sample["q_arm"] = q.tolist()
        else:
            sample["q"] = q.tolist()
        if samples.p is not None:
            sample["p"] = samples.p[i].tolist()
        if samples.cov is not None:
            sample["cov"] = samples.cov[i].tolist()
        if samples.sigma is not None:
            sample["sigma"] = float(samples.sigma[i])
        if samples.group[i] >= 0:
            sample["group"] = int(samples.group[i])
        for name in ("t", "temperature", "speed"):
            value = float(getattr(samples, name)[i])
            if np.isfinite(value):
                sample[name] = value
        approach = samples.approach[i, : len(q)]
        if np.all(np.isfinite(approach)):
            sample["approach"] = [int(v) for v in approach]
        extra = {k: float(v[i]) for k, v in samples.extra.items() if np.isfinite(v[i])}
        if extra:
            sample["extra"] = extra
        if samples.uv is not None and np.all(np.isfinite(samples.uv[i])):
            sample["uv"] = samples.uv[i].tolist()
        out.append(sample)
    return out


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
    return json.dumps(value, ensure_ascii=False, allow_nan=False)
