"""A cell reference: the cell's frames recorded once, while the robot's zeros are good, and
loaded by later runs as priors, so that every joint's zero is identifiable.

Why: with every frame estimated, joint 1's zero cannot be told from the target's (sphere's,
tracker registration's) rotation about base z, nor the last joint's from the camera's
(stylus tip's, reflector's) rotation about the flange axis: the fit leaves them unchanged,
and a J1 or J6 motor swap goes unfixed. A reference recorded at commissioning (or right
after a verified calibration) holds those frames to within their recorded covariance, so
the later run determines J1 and J6 as well (docs/calibrate.md "A cell reference").

File (`zerocal-cell-reference/1`, JSON, SI units, written by `hostpc reference record`):

    {"format": "zerocal-cell-reference/1", "recorded": "2025-01-10T09:12:00+00:00",
     "software": "zerocal 0.1.0", "robot": {"model": "ur5e", "serial": "SN-1234"},
     "method": "stereo_target", "cell": {... the run's cell description ...},
     "source_run": "/abs/run/folder", "joint_zeros": {"1": "as_found", "2": "measured", ..},
     "frames": {"target": {"parameters": ["x", "y", "z"], "nominal": [..], "delta": [..],
                           "covariance": [[..], ..]}, "tool": {...}}}

A frame the recording run measured with a stereo rig also keeps `rig_sensitivity` (K x 24:
how the fitted frame moves with the rig's calibration error, +d frame / d delta (the frame
a refit gives moves by rig_sensitivity @ delta when the rig errs by delta), from the fit's
shared error, hostpc.fitting.shared_errors.parameter_shared_sensitivity); its covariance
includes that error. A later run with the same rig carries the same error in its own
samples, so the prior block says so (`shared_sensitivity`) and the fit counts the rig's
error once, correlated, instead of twice as independent (which loses the cross terms, of
either sign).

`joint_zeros` says, per joint, whether the recording run calibrated its zero ("measured")
or not ("as_found": the zero as it was then, e.g. J1 with every frame estimated). A frame
fitted while a joint trades against it (J1 and the target's turn about base z) carries
that joint's zero as it was: a later run that can calibrate J1 only through that frame
restores J1 TO THE REFERENCE, which is the true zero only if the recording run measured
it. A file written before this record has none: every joint reads "unknown".

Per frame: the parameter names (after the frame's name, in the fit's order), the nominal
the recording run fitted its deltas against (a pose's rotation as a rotation vector), the
fitted delta and its covariance block. On load, a frame enters a run as a prior block
(hostpc.fitting.priors) on that run's own deltas (its nominal may differ: sphere_probe
starts from each run's closed-form estimate), with the covariance plus MOUNT_FLOOR on the
diagonal. The file is read with a size check (MAX_REFERENCE_BYTES) and json; anything
malformed is one InputError line naming the field.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.dataset import Dataset, FramePose, SphereFrame
from hostpc.errors import InputError
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject
from hostpc.kinematics.rotations import matrix_to_rotvec, rotvec_to_matrix

REFERENCE_FORMAT = "zerocal-cell-reference/1"
REFERENCE_FILE = "reference.json"
"""The run folder's copy of the reference a run loaded (a resume and the record read it)."""
MAX_REFERENCE_BYTES = 2_000_000
MOUNT_FLOOR_M = 5e-6
"""Added (as a standard deviation) to every recorded length parameter on load: what a
dowel-pinned target, a kinematic camera mount or a reflector nest repeats to after being
touched (a few um). It keeps a reference recorded from a very long run from claiming more
than the cell's mechanics hold."""
MOUNT_FLOOR_RAD = math.radians(0.001)
"""The same floor for angles (17 urad: a kinematic mount's angular repeatability)."""
REFERENCE_ZEROS = ("measured", "as_found", "unknown")
"""A reference's record of each joint's zero at its recording run (module docstring)."""
RIG_FRAMES = ("tool", "camera")
"""Frames that are a stereo rig's left optical frame: defined by the rig calibration, so a
reference's value holds only for runs with the same rig (the reference keeps the rig;
`hostpc reference record` writes it beside the reference for `--rig`)."""


@dataclass(frozen=True)
class ReferenceFrame:
    """One recorded frame. parameters: the names after the frame's (e.g. x, y, z, rx, ry,
    rz; world_point markers: smr1.x ...); nominal, delta: (K,) SI; covariance: (K, K)."""

    name: str
    parameters: tuple[str, ...]
    nominal: np.ndarray
    delta: np.ndarray
    covariance: np.ndarray
    rig_sensitivity: np.ndarray | None = None
    """(K, 24) d frame / d rig error of the recording fit, or None (no rig)."""

    @property
    def full_names(self) -> list[str]:
        return [f"{self.name}.{p}" for p in self.parameters]

    def floored_covariance(self) -> np.ndarray:
        """(K, K) the covariance with the mount floor added on the diagonal."""
        floor = np.array([MOUNT_FLOOR_RAD if _is_angle(p) else MOUNT_FLOOR_M
                          for p in self.parameters])
        floored: np.ndarray = self.covariance + np.diag(floor**2)
        return floored

    def absolute(self) -> np.ndarray:
        """(K,) the frame's fitted value (points: coordinates; a pose: xyz, rotation
        vector of the rotation)."""
        return _absolute(self.parameters, self.nominal, self.delta)

    def distance_from_nominal(self) -> tuple[float, float]:
        """(m, rad) how far the recorded frame lies from the cell's nominal: the largest
        translation of one point (a pose's x, y, z; each marker of a point set) and the
        rotation angle (a pose's rx, ry, rz, a rotation vector applied to the nominal's
        rotation; 0 for points)."""
        points: dict[str, list[float]] = {}
        for parameter, delta in zip(self.parameters, self.delta, strict=True):
            if not _is_angle(parameter):
                points.setdefault(parameter.rpartition(".")[0], []).append(float(delta))
        _, rotation = _rotation_slices(self.parameters)
        move = max((math.hypot(*d) for d in points.values()), default=0.0)
        return move, float(np.linalg.norm(self.delta[rotation])) if rotation else 0.0

    def to_dict(self) -> JsonObject:
        return {"parameters": list(self.parameters), "nominal": self.nominal.tolist(),
                "delta": self.delta.tolist(), "covariance": self.covariance.tolist(),
                "value": self.absolute().tolist(),
                **({"rig_sensitivity": self.rig_sensitivity.tolist()}
                   if self.rig_sensitivity is not None else {})}


@dataclass(frozen=True)
class CellReference:
    """A loaded (or recorded) reference; see the module docstring."""

    method: str
    robot_model: str
    robot_serial: str
    recorded: str
    software: str
    frames: tuple[ReferenceFrame, ...]
    cell: JsonObject = field(default_factory=dict)  # the run's cell, `Cell.to_dict()`
    source_run: str = ""
    rig: JsonObject | None = None
    """The stereo rig the camera frame was measured with (the dataset's
    rig_uncertainty.rig document), or None."""
    zeros: Mapping[int, str] | None = None
    """Per joint (1-based) "measured" or "as_found" at the recording run (`joint_zeros`),
    None: a file written before it was kept."""

    def zero_of(self, joint: int) -> str:
        """"measured" | "as_found" | "unknown": whether the recording run calibrated the
        zero of `joint` (REFERENCE_ZEROS)."""
        return "unknown" if self.zeros is None else self.zeros.get(joint, "unknown")

    def distances_line(self) -> str:
        """One line: each frame's distance from the cell's nominal, and what a large one can
        mean (a lost joint zero the recording run did not calibrate ends up in the frame it
        trades against: an undeclared motor swap of 10 deg on J1 put the target 83 mm off)."""
        parts = []
        for frame in self.frames:
            move, turn = frame.distance_from_nominal()
            angle = f", {math.degrees(turn):.2f} deg" if any(map(_is_angle, frame.parameters)) \
                else ""
            parts.append(f"{frame.name} {move * 1e3:.1f} mm{angle}")
        return ("from the cell's nominal: " + "; ".join(parts) + " (a joint zero lost and not "
                "calibrated by the recording run ends up in these frames: far more than the "
                "cell's drawing can be off means check the robot's zeros before using it)")

    def rig_matches(self, dataset: Dataset) -> bool:
        """True unless both this reference and `dataset` name a rig and they differ."""
        other = (dataset.extra_fields.get("rig_uncertainty") or {}).get("rig")
        if self.rig is None or other is None:
            return True
        return _digest(self.rig) == _digest(other)

    def frame(self, name: str) -> ReferenceFrame | None:
        return next((f for f in self.frames if f.name == name), None)

    @property
    def date(self) -> str:
        """The recording date (YYYY-MM-DD) for messages."""
        return self.recorded[:10]

    def to_dict(self) -> JsonObject:
        return {"format": REFERENCE_FORMAT, "recorded": self.recorded,
                "software": self.software,
                "robot": {"model": self.robot_model, "serial": self.robot_serial},
                "method": self.method, "cell": dict(self.cell),
                "source_run": self.source_run,
                "floor": {"length_m": MOUNT_FLOOR_M, "angle_rad": MOUNT_FLOOR_RAD},
                "frames": {f.name: f.to_dict() for f in self.frames},
                **({"rig": dict(self.rig)} if self.rig is not None else {}),
                **({"joint_zeros": {str(j): z for j, z in sorted(self.zeros.items())}}
                   if self.zeros is not None else {})}


def _digest(document: JsonObject) -> str:
    import hashlib

    return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()


def _is_angle(parameter: str) -> bool:
    return parameter.rsplit(".", 1)[-1] in ("rx", "ry", "rz")


def _rotation_slices(parameters: Sequence[str]) -> tuple[list[int], list[int]]:
    """(indices of a pose's translation, of its rotation vector) - rotation empty for
    point frames."""
    angles = [k for k, p in enumerate(parameters) if _is_angle(p)]
    return [k for k in range(len(parameters)) if k not in angles], angles


def _absolute(parameters: Sequence[str], nominal: np.ndarray, delta: np.ndarray
              ) -> np.ndarray:
    """The frame's value from its nominal and delta (a pose: R = R_nom exp(delta_r),
    t = t_nom + delta_t, as hostpc.model.frame_math.perturbed_pose)."""
    lengths, angles = _rotation_slices(parameters)
    value = np.asarray(nominal, float) + np.asarray(delta, float)
    if len(angles) == 3:
        R = rotvec_to_matrix(nominal[angles]) @ rotvec_to_matrix(delta[angles])
        value[angles] = matrix_to_rotvec(R)
    return value


def _delta_for(parameters: Sequence[str], nominal: np.ndarray, absolute: np.ndarray
               ) -> np.ndarray:
    """The inverse of _absolute: the delta from `nominal` that gives `absolute`."""
    lengths, angles = _rotation_slices(parameters)
    delta = np.asarray(absolute, float) - np.asarray(nominal, float)
    if len(angles) == 3:
        R = rotvec_to_matrix(nominal[angles]).T @ rotvec_to_matrix(absolute[angles])
        delta[angles] = matrix_to_rotvec(R)
    return delta


def nominal_vector(dataset: Dataset, frame: str, parameters: Sequence[str]) -> np.ndarray:
    """(K,) a dataset's nominal of `frame` in the order of `parameters` (a pose's rotation
    as a rotation vector). InputError if the dataset has no such frame."""
    value = dataset.frames.get(frame)
    if value is None:
        raise InputError(f"reference frame {frame}: this run's dataset has no such frame")
    if isinstance(value, FramePose):
        coords = {"x": value.xyz[0], "y": value.xyz[1], "z": value.xyz[2]}
        rotvec = matrix_to_rotvec(_rpy_matrix(value.rpy))
        coords.update({"rx": rotvec[0], "ry": rotvec[1], "rz": rotvec[2]})
        return np.array([float(coords[p]) for p in parameters])
    if isinstance(value, SphereFrame):
        point = np.asarray(value.center, float)
        return np.array([point["xyz".index(p)] for p in parameters])
    if isinstance(value, Mapping):  # named points (world_point markers): NAME.x
        out = []
        for p in parameters:
            marker, _, axis = p.rpartition(".")
            if marker not in value:
                raise InputError(f"reference frame {frame}: no marker {marker!r} in this "
                                 "run's cell")
            out.append(float(np.asarray(value[marker], float)["xyz".index(axis)]))
        return np.array(out)
    point = np.asarray(value, float).reshape(-1)
    return np.array([point["xyz".index(p)] for p in parameters])


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    from hostpc.kinematics.rotations import rpy_to_matrix

    return np.asarray(rpy_to_matrix(np.asarray(rpy, float)), float)


# ------------------------------------------------------------------ record


def reference_from_fit(result: FitResult, *, robot_serial: str, cell: JsonObject,
                       source_run: str, software: str, recorded: str | None = None,
                       zeros: Mapping[int, str] | None = None) -> CellReference:
    """The reference of a fit: every frame it estimated, with its delta and covariance
    block (a parameter the fit held is left out: the data did not determine it), and, with
    a stereo rig, its rig sensitivity; zeros: the recording run's record of each joint's
    zero (`joint_zeros`, outcome.reference_zeros)."""
    from hostpc.fitting.shared_errors import parameter_shared_sensitivity

    problem = result.problem
    sensitivity = parameter_shared_sensitivity(problem, result.x, ~np.asarray(result.fixed))
    dataset = problem.dataset
    names = list(result.names)
    frames = []
    for frame in problem.frame_names:
        span = problem.layout.effect_slices[frame]
        index = [k for k in range(span.start, span.stop) if not result.fixed[k]]
        if not index:
            continue
        parameters = tuple(names[k].split(".", 1)[1] for k in index)
        covariance = np.asarray(result.covariance, float)[np.ix_(index, index)]
        if not np.all(np.isfinite(covariance)):
            raise InputError(f"the fit's covariance of frame {frame} is not finite: this "
                             "run cannot be a reference")
        frames.append(ReferenceFrame(frame, parameters,
                                     nominal_vector(dataset, frame, parameters),
                                     np.asarray(result.x, float)[index],
                                     0.5 * (covariance + covariance.T),
                                     None if sensitivity is None else sensitivity[index]))
    if not frames:
        raise InputError("the fit estimated no frame (all known): nothing to record")
    return CellReference(
        method=str(problem.method), robot_model=str(dataset.robot.name or ""),
        robot_serial=robot_serial,
        recorded=recorded or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        software=software, frames=tuple(frames), cell=dict(cell), source_run=source_run,
        rig=(dataset.extra_fields.get("rig_uncertainty") or {}).get("rig"),
        zeros=None if zeros is None else dict(zeros))


# ------------------------------------------------------------------ load


def _field(data: JsonObject, key: str, kind: type, where: str) -> Any:
    value = data.get(key)
    if not isinstance(value, kind):
        raise InputError(f"{where}: {key!r} missing or not a {kind.__name__}")
    return value


def reference_from_dict(data: Any, where: str) -> CellReference:
    """Validate a reference document; InputError (one line naming `where` and the field)."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a JSON object")
    if data.get("format") != REFERENCE_FORMAT:
        raise InputError(f"{where}: format {data.get('format')!r} is not "
                         f"{REFERENCE_FORMAT!r} (a cell reference from hostpc reference "
                         "record)")
    robot = _field(data, "robot", dict, where)
    frames_raw = _field(data, "frames", dict, where)
    frames = []
    for name, spec in frames_raw.items():
        here = f"{where}: frames.{name}"
        if not isinstance(spec, dict):
            raise InputError(f"{here}: expected an object")
        parameters = spec.get("parameters")
        if (not isinstance(parameters, list) or not parameters
                or not all(isinstance(p, str) for p in parameters)):
            raise InputError(f"{here}.parameters: expected a list of names")
        k = len(parameters)
        try:
            nominal = np.asarray(spec.get("nominal"), float).reshape(-1)
            delta = np.asarray(spec.get("delta"), float).reshape(-1)
            covariance = np.asarray(spec.get("covariance"), float)
        except (TypeError, ValueError):
            raise InputError(f"{here}: nominal, delta and covariance must be numbers") from None
        if nominal.shape != (k,) or delta.shape != (k,) or covariance.shape != (k, k):
            raise InputError(f"{here}: expected {k} nominal and delta values and a {k}x{k} "
                             "covariance")
        if not (np.all(np.isfinite(nominal)) and np.all(np.isfinite(delta))
                and np.all(np.isfinite(covariance))):
            raise InputError(f"{here}: values must be finite")
        if np.any(np.abs(nominal) > 100.0) or np.any(np.abs(delta) > 100.0):
            raise InputError(f"{here}: values outside the physical range (|v| <= 100 SI)")
        symmetric = 0.5 * (covariance + covariance.T)
        if (not np.allclose(covariance, symmetric, rtol=1e-6, atol=1e-30)
                or np.min(np.linalg.eigvalsh(symmetric)) < -1e-12 * max(
                    1e-30, float(np.max(np.abs(symmetric))))):
            raise InputError(f"{here}.covariance: not symmetric positive semi-definite")
        frames.append(ReferenceFrame(str(name), tuple(parameters), nominal, delta, symmetric,
                                     _rig_sensitivity(spec, k, here)))
    if not frames:
        raise InputError(f"{where}: frames: none recorded")
    cell, rig = data.get("cell"), data.get("rig")
    if rig is not None and not isinstance(rig, dict):
        raise InputError(f"{where}: rig: expected a rig document (an object)")
    return CellReference(
        method=str(_field(data, "method", str, where)),
        robot_model=str(robot.get("model") or ""), robot_serial=str(robot.get("serial") or ""),
        recorded=str(_field(data, "recorded", str, where)),
        software=str(data.get("software", "")), frames=tuple(frames),
        cell=cell if isinstance(cell, dict) else {},
        source_run=str(data.get("source_run", "")), rig=rig, zeros=_joint_zeros(data, where))


def _joint_zeros(data: JsonObject, where: str) -> dict[int, str] | None:
    """A reference's `joint_zeros` ({"1": "measured", ..}), None if it has none (older)."""
    raw = data.get("joint_zeros")
    if raw is None:
        return None
    if not isinstance(raw, dict) or not all(
            isinstance(k, str) and k.isdigit() and v in REFERENCE_ZEROS
            for k, v in raw.items()):
        raise InputError(f"{where}: joint_zeros: expected {{\"JOINT\": one of "
                         f"{', '.join(REFERENCE_ZEROS)}}}")
    return {int(k): str(v) for k, v in raw.items()}


def _rig_sensitivity(spec: JsonObject, k: int, where: str) -> np.ndarray | None:
    """A recorded frame's `rig_sensitivity` (k rows, finite), or None if it has none."""
    raw = spec.get("rig_sensitivity")
    if raw is None:
        return None
    try:
        sensitivity = np.asarray(raw, float)
    except (TypeError, ValueError):
        raise InputError(f"{where}.rig_sensitivity: must be numbers") from None
    if sensitivity.ndim != 2 or sensitivity.shape[0] != k or not np.all(
            np.isfinite(sensitivity)):
        raise InputError(f"{where}.rig_sensitivity: expected {k} rows of finite numbers")
    return sensitivity


def load_reference(path: str | Path) -> CellReference:
    """Read and validate a reference file (size-checked, then json)."""
    path = Path(path)
    where = f"--reference {path}"
    try:
        size = path.stat().st_size
        if size > MAX_REFERENCE_BYTES:
            raise InputError(f"{where}: {size} bytes, more than a reference holds "
                             f"({MAX_REFERENCE_BYTES})")
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{where}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"{where}: not UTF-8 text") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{where}: not valid JSON ({exc})") from None
    return reference_from_dict(data, where)


def check_reference_matches(reference: CellReference, *, method: str, robot_model: str,
                            robot_serial: str | None, where: str) -> None:
    """InputError (one line) if the reference was recorded for another method, robot
    model or robot serial than this run's."""
    fix = "record one for this robot and cell: hostpc reference record --run RUN --out FILE"
    if reference.method != method:
        raise InputError(f"{where}: recorded with --method {reference.method}, this run "
                         f"uses {method}; {fix}")
    if reference.robot_model and robot_model and reference.robot_model != robot_model:
        raise InputError(f"{where}: recorded on a {reference.robot_model}, this robot is a "
                         f"{robot_model}; {fix}")
    if (robot_serial and reference.robot_serial and reference.robot_serial != robot_serial):
        raise InputError(f"{where}: recorded on robot {reference.robot_serial}, this is "
                         f"robot {robot_serial}; {fix}")


# ------------------------------------------------------------------ priors


@dataclass(frozen=True)
class FramePrior:
    """A reference frame expressed in one run's deltas: names (full parameter names),
    value (K,) and covariance (K, K) with the floor, SI."""

    frame: str
    names: tuple[str, ...]
    value: np.ndarray
    covariance: np.ndarray
    shared_sensitivity: np.ndarray | None = None
    """(K, 24) how the value moves with this run's rig error (the same rig), or None."""

    def block(self) -> JsonObject:
        """The dataset's `prior_blocks` entry (hostpc.fitting.priors)."""
        return {"names": list(self.names), "value": self.value.tolist(),
                "covariance": self.covariance.tolist(), "reference_frame": self.frame,
                **({"shared_sensitivity": self.shared_sensitivity.tolist()}
                   if self.shared_sensitivity is not None else {})}


def frame_priors(reference: CellReference, dataset: Dataset,
                 estimated: Sequence[str]) -> list[FramePrior]:
    """The reference's frames as priors on `dataset`'s deltas, for the frames the run
    estimates (`estimated`; a frame the run holds known keeps its surveyed value).

    The recorded value (nominal + delta) is re-expressed against this dataset's nominal,
    and the covariance (and rig sensitivity) carried through by the (numeric) Jacobian of
    that change. A camera frame measured with another rig than this dataset's is left out
    (RIG_FRAMES); a frame measured with this dataset's rig keeps its rig sensitivity (the
    same error as this run's samples)."""
    out = []
    same_rig = reference.rig_matches(dataset)
    this_rig = (dataset.extra_fields.get("rig_uncertainty") or {}).get("rig")
    shared_rig = same_rig and reference.rig is not None and this_rig is not None
    for frame in reference.frames:
        if frame.name not in estimated or (frame.name in RIG_FRAMES and not same_rig):
            continue
        nominal = nominal_vector(dataset, frame.name, frame.parameters)
        value = _delta_for(frame.parameters, nominal, frame.absolute())
        J = np.eye(len(frame.parameters))
        if not np.allclose(nominal, frame.nominal, rtol=0.0, atol=1e-12):
            step = 1e-7
            for k in range(len(frame.parameters)):
                bump = np.zeros(len(frame.parameters))
                bump[k] = step
                plus = _delta_for(frame.parameters, nominal,
                                  _absolute(frame.parameters, frame.nominal, frame.delta + bump))
                minus = _delta_for(frame.parameters, nominal,
                                   _absolute(frame.parameters, frame.nominal,
                                             frame.delta - bump))
                J[:, k] = (plus - minus) / (2 * step)
        covariance = J @ frame.floored_covariance() @ J.T
        sensitivity = (J @ frame.rig_sensitivity
                       if shared_rig and frame.rig_sensitivity is not None else None)
        out.append(FramePrior(frame.name, tuple(frame.full_names), value,
                              0.5 * (covariance + covariance.T), sensitivity))
    return out
