"""The result of a calibration run as one frozen value: ``RunResult``.

A run builds its result once, at its end (summary.py ``run_result``), and every view reads
that value: summary.txt (summary.py), report.html, the rollback's rewrite
(outcome_files.py), a resume that finds the run finished (resume.py). ``to_dict`` is
``result.json`` (its keys in the order they always had, so the file's bytes are those of
the versions before this value) and ``from_dict`` reads it back, also when an older
version wrote it (blocks it did not have are absent, and stay absent when rewritten).

The blocks that are the JSON form of another value (the robot, the settings, the method's
setup, the plan's description, the verification, the robot time, the reference check, the
outcome, the simulation's truth comparison) are kept in that JSON form: this module is the
JSON boundary, ``JsonObject`` their honest type.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from pydantic import Field, StrictBool, StrictInt, StrictStr

from hostpc.calibrate.strict_json import StrictFile, parse_strict_json, validate_strict
from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text
from hostpc.json_object import JsonObject

GROWN_TIME = "predicted_robot_time_grown_s"
"""The plan info's key of the predicted robot time of measure + verify if the plan grows
(the fit poses, the further ones, the grown verification); result.json shows the
prediction of the plan that ran (`plan_as_run`)."""


def plan_as_run(info: JsonObject, grown: bool) -> JsonObject:
    """The plan's info as result.json shows it: `predicted_robot_time_s` is the prediction
    of the plan that ran; when it grew, the grown plan's, with the short plan's beside it
    (`predicted_robot_time_short_s`)."""
    shown = {k: v for k, v in info.items() if k != GROWN_TIME}
    if grown and info.get(GROWN_TIME) is not None:
        shown["predicted_robot_time_short_s"] = info.get("predicted_robot_time_s")
        shown["predicted_robot_time_s"] = info[GROWN_TIME]
    return shown


@dataclass(frozen=True)
class SkippedPose:
    """A pose the run could not measure: its phase (fit / verify), index and why."""

    phase: str
    index: int
    reason: str | None

    def to_dict(self) -> JsonObject:
        return {"phase": self.phase, "index": self.index, "reason": self.reason}


@dataclass(frozen=True)
class Acquisition:
    """What was measured: poses planned (with the further poses when the plan grew, and
    why it grew), samples and poses measured, the poses skipped."""

    n_planned: int
    more_poses: str | None
    n_measured: int
    n_poses_measured: int | None  # None: an older result without it
    skipped: tuple[SkippedPose, ...]

    def to_dict(self) -> JsonObject:
        block: JsonObject = {"n_planned": self.n_planned, "more_poses": self.more_poses,
                                    "n_measured": self.n_measured}
        if self.n_poses_measured is not None:
            block["n_poses_measured"] = self.n_poses_measured
        block["n_skipped"] = len(self.skipped)
        block["skipped"] = [item.to_dict() for item in self.skipped]
        return block

    @classmethod
    def from_dict(cls, data: JsonObject) -> Acquisition:
        return cls(int(data["n_planned"]), data.get("more_poses"), int(data["n_measured"]),
                   data.get("n_poses_measured"),
                   tuple(SkippedPose(str(s["phase"]), int(s["index"]), s.get("reason"))
                         for s in data.get("skipped", [])))


@dataclass(frozen=True)
class OffsetRow:
    """One joint's offset in degrees: before, the correction and its sigma (None where
    the data does not determine it), after, and whether it was pushed (and why not)."""

    joint: int
    label: str
    old_deg: float
    correction_deg: float | None
    sigma_deg: float | None
    new_deg: float
    pushed: bool
    note: str

    def to_dict(self) -> JsonObject:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: JsonObject, j: int = 0) -> OffsetRow:
        return cls(int(data.get("joint", j + 1)), str(data.get("label", "")),
                   float(data["old_deg"]), data.get("correction_deg"), data.get("sigma_deg"),
                   float(data["new_deg"]), bool(data["pushed"]), str(data.get("note", "")))


APPLIED_ON_HOST = "applied_on_host"
"""The push status result.json and the archive state for a push of a robot that keeps
no zero offsets (UR): applied on the host for this session only, the controller unchanged
(`PushResult.stated_status`)."""


@dataclass(frozen=True)
class PushResult:
    """What happened to the controller: the push status (pushed, refused, disabled,
    rolled_back, nothing), the refusal, the guard's limit; for a written push its rollback
    id, whether it was recovered after an interruption, and the push file; for a robot
    that keeps no offsets (UR) the exported files that are the push. `status` is the run's
    push step ("pushed" also for such a robot); result.json and the archive state
    `stated_status`."""

    status: str
    reason: str | None
    max_correction_deg: float | None
    written: JsonObject | None = None  # {"rollback_id", "recovered", "file"} of a push
    exports: Mapping[str, str] | None = None

    @property
    def stated_status(self) -> str:
        """The status as result.json and the archive state it: APPLIED_ON_HOST for a push
        of a robot that keeps no offsets (its exports), else `status`."""
        return (APPLIED_ON_HOST if self.status == "pushed" and self.exports is not None
                else self.status)

    def to_dict(self) -> JsonObject:
        block: JsonObject = {"status": self.stated_status, "reason": self.reason,
                             "max_correction_deg": self.max_correction_deg}
        block.update(self.written or {})
        if self.exports is not None:
            block.update(on_controller=False, exports=dict(self.exports))
        return block

    @classmethod
    def from_dict(cls, data: JsonObject) -> PushResult:
        written: JsonObject = {key: data[key] for key in ("rollback_id", "recovered", "file")
                               if key in data}
        status = str(data.get("status", "nothing"))
        return cls("pushed" if status == APPLIED_ON_HOST else status, data.get("reason"),
                   data.get("max_correction_deg"), written or None, data.get("exports"))



@dataclass(frozen=True)
class RunResult:
    """A finished run's result (module docstring); ``to_dict`` is result.json.

    The optional blocks (truth, reference_check, outcome) are None when the run (or the
    version that wrote it) had none; `absent` names the blocks of an older result that
    were not in its file at all, so a rewrite keeps them out."""

    format: str
    run_dir: str
    robot: JsonObject
    method: str
    settings: JsonObject
    known: tuple[str, ...]
    method_setup: JsonObject
    plan: JsonObject
    acquisition: Acquisition
    fit: JsonObject
    offsets: tuple[OffsetRow, ...]
    push: PushResult
    verify: JsonObject | None
    robot_time_s: JsonObject | None
    files: Mapping[str, str]
    exit_code: int
    truth: JsonObject | None = None
    reference_check: JsonObject | None = None
    outcome: JsonObject | None = None
    absent: frozenset[str] = field(default=frozenset())

    def to_dict(self) -> JsonObject:
        document: JsonObject = {
            "format": self.format, "run_dir": self.run_dir, "robot": dict(self.robot),
            "method": self.method, "settings": dict(self.settings), "known": list(self.known),
            "method_setup": dict(self.method_setup), "plan": dict(self.plan),
            "acquisition": self.acquisition.to_dict(), "fit": dict(self.fit),
            "offsets": {"joints": [row.to_dict() for row in self.offsets]},
            "push": self.push.to_dict(),
            "verify": None if self.verify is None else dict(self.verify),
            "robot_time_s": None if self.robot_time_s is None else dict(self.robot_time_s),
            "files": dict(self.files), "exit_code": self.exit_code,
        }
        if self.truth is not None:
            document["truth"] = dict(self.truth)
        for key in ("reference_check", "outcome"):
            value = getattr(self, key)
            if key not in self.absent:
                document[key] = None if value is None else dict(value)
        for key in ("method_setup", "robot_time_s", "verify"):
            if key in self.absent:
                del document[key]
        return document

    @classmethod
    def from_dict(cls, data: JsonObject) -> RunResult:
        """A result.json read back (any version: absent blocks are remembered)."""
        absent = frozenset(key for key in ("method_setup", "robot_time_s", "verify",
                                           "reference_check", "outcome") if key not in data)
        return cls(
            format=str(data.get("format", "")), run_dir=str(data.get("run_dir", "")),
            robot=data.get("robot") or {}, method=str(data.get("method", "")),
            settings=data.get("settings") or {}, known=tuple(data.get("known") or ()),
            method_setup=data.get("method_setup") or {}, plan=data.get("plan") or {},
            acquisition=Acquisition.from_dict(data["acquisition"]), fit=data["fit"],
            offsets=tuple(OffsetRow.from_dict(row, j) for j, row in
                          enumerate((data.get("offsets") or {}).get("joints", []))),
            push=PushResult.from_dict(data.get("push") or {}),
            verify=data.get("verify"), robot_time_s=data.get("robot_time_s"),
            files=data.get("files") or {}, exit_code=int(data.get("exit_code", 0)),
            truth=data.get("truth"), reference_check=data.get("reference_check"),
            outcome=data.get("outcome"), absent=absent)

    def with_files(self, **files: str) -> RunResult:
        """This result naming more files (the UR exports, the report)."""
        return dataclasses.replace(self, files={**self.files, **files})


RESULT_REMEDY = ("result.json is written by `hostpc calibrate`: use the run folder as the run "
                 "wrote it (or calibrate again)")
"""The end of a refused result.json's line."""

Finite = Annotated[float, Field(allow_inf_nan=False)]


class _FitFields(StrictFile):
    converged: StrictBool
    effects: list[StrictStr] | None = None


class _VerifyFields(StrictFile):
    verdict: StrictStr | None = None


class _ReferenceCheckFields(StrictFile):
    moved: StrictBool | None = None
    likely_cause: StrictStr | None = None


class _JointFields(StrictFile):
    joint: StrictInt
    label: StrictStr = ""
    status: StrictStr | None = None
    source: StrictStr | None = None
    reason: StrictStr | None = None
    fix: StrictStr | None = None


class _OutcomeFields(StrictFile):
    next_command: StrictStr | None = None
    unknown_zeros: list[StrictInt] | None = None
    joints: list[_JointFields] = []


class _OffsetFields(StrictFile):
    joint: StrictInt | None = None
    old_deg: Finite
    new_deg: Finite
    correction_deg: Finite | None = None
    sigma_deg: Finite | None = None
    pushed: StrictBool


class _OffsetsFields(StrictFile):
    joints: list[_OffsetFields] = []


class _AcquisitionFields(StrictFile):
    n_planned: StrictInt
    n_measured: StrictInt


class DecisionFields(StrictFile):
    """The fields of result.json a decision reads (`hostpc reference record`: did the fit
    converge, with which effects; the verification's verdict; did the reference check find a
    moved frame; the outcome's joints, unknown zeros and stored next command; the offsets),
    in strict types; the rest of the file is read as `RunResult.from_dict` reads it."""

    run_dir: StrictStr = ""
    acquisition: _AcquisitionFields
    fit: _FitFields
    offsets: _OffsetsFields | None = None
    verify: _VerifyFields | None = None
    reference_check: _ReferenceCheckFields | None = None
    outcome: _OutcomeFields | None = None


def read_run_result(path: Path) -> RunResult:
    """A run's result.json read strictly, for a decision (`hostpc.calibrate.strict_json`:
    no duplicated key, no NaN, the fields of `DecisionFields` in strict types); InputError
    (one line naming the file and the field) otherwise."""
    source = str(path)
    if not path.exists():
        raise InputError(f"{source}: no result document (result.json) here: not a finished "
                         "run folder")
    document = parse_strict_json(read_input_text(path, CONFIG, source), source, RESULT_REMEDY)
    if not isinstance(document, dict):
        raise InputError(f"{source}: expected a JSON object, got {type(document).__name__}; "
                         f"{RESULT_REMEDY}")
    validate_strict(DecisionFields, document, source, RESULT_REMEDY)
    try:
        return RunResult.from_dict(document)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{source}: not a calibration result document ({exc!r}); "
                         f"{RESULT_REMEDY}") from None
