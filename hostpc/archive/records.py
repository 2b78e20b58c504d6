"""A calibration run as one archive record (a frozen value read from a run folder).

A run folder (`hostpc calibrate --out DIR`) holds `result.json` (settings, fit, offsets,
push, verify, truth for a simulated run) and `dataset.json` (the measurements). The record
keeps both whole, so any archived run can be refit later, and lifts out the fields the
history and drift views query: robot serial and model, time, verdict, per-joint offsets
before and after with their sigmas.
"""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from hostpc import __version__
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Pushed, PushRecord, Rollback
from hostpc.calibrate.outcome import JointOutcome
from hostpc.calibrate.run_result import RunResult
from hostpc.errors import InputError
from hostpc.json_object import JsonObject


@dataclass(frozen=True)
class JointOffset:
    """One joint's zero offset in one run, in degrees (None where not determined)."""

    joint: int
    label: str
    old_deg: float | None
    correction_deg: float | None
    sigma_deg: float | None
    new_deg: float | None
    pushed: bool


@dataclass(frozen=True)
class VerifyFigures:
    """The verification test the station's registers show: chi-square statistic, p-value
    and degrees of freedom (None / 0 where the run verified nothing)."""

    statistic: float | None = None
    p_value: float | None = None
    dof: int = 0


@dataclass(frozen=True)
class OutcomeFigures:
    """What the station reads of a run's outcome (result.json "outcome",
    hostpc.calibrate.outcome): verdict and headline, pushed / verified, and the joints
    calibrated (from data and, if pushed, verified), not calibrated from data, and
    required but missing, by 1-based number."""

    verdict: str | None
    headline: str
    pushed: bool
    verified: bool | None
    calibrated: tuple[int, ...]
    not_calibrated: tuple[int, ...]
    missing_required: tuple[int, ...]
    as_found: tuple[int, ...] = ()
    """Of `calibrated`: restored to a cell reference whose recording run did not measure
    the zero (`JointOutcome.as_found`: its zero is as it was then)."""


@dataclass(frozen=True)
class RunRecord:
    """One archived calibration run.

    verdict: the run's outcome verdict (result.json "outcome", hostpc.calibrate.outcome:
    PASS, FAIL, REFUSED, JOINTS_MISSING, NOT_PUSHED, NOT_VERIFIED, ROLLED_BACK, ERROR);
    for an older result without one see `verdict_of`. exit_code is `hostpc calibrate`'s.
    result: the run's result.json (None: the run wrote none); dataset_json: its
    dataset.json as the archive stores it (None: none).
    """

    run_uid: str
    serial: str
    model: str
    station: str
    started_at: datetime
    method: str
    effects: tuple[str, ...]
    verdict: str
    exit_code: int
    push_status: str
    largest_correction_deg: float | None
    verify: VerifyFigures
    offsets: tuple[JointOffset, ...]
    software_version: str
    result: RunResult | None
    dataset_json: str | None
    run_dir: str = ""
    uid_from_folder: bool = False
    """True if run_uid derives from the run folder (no caller gave one): the archive then
    also finds the run by its folder (a station's run resumed by hand)."""
    reason: str = ""
    """One line: why the run did not PASS (the station's reason; empty if none given)."""
    report_path: str = ""
    """The run's report.html (empty if it has none)."""

    @property
    def outcome(self) -> OutcomeFigures | None:
        """The result's outcome block (None: no result, or one written before outcomes)."""
        return outcome_of(self.result)


def outcome_of(result: RunResult | None) -> OutcomeFigures | None:
    """The outcome figures of `result` (None: no result, or an older one without an
    outcome block). Parses the block's JSON form (the result keeps it so)."""
    block = result.outcome if result is not None else None
    if not isinstance(block, Mapping):
        return None
    joints = [JointOutcome.from_dict(j) for j in block.get("joints") or []
              if isinstance(j, Mapping)]  # the rows read as the run's own JointOutcomes
    verdict = block.get("verdict")
    return OutcomeFigures(
        verdict=verdict if isinstance(verdict, str) else None,
        headline=str(block.get("headline") or ""), pushed=bool(block.get("pushed")),
        verified=block.get("verified"),
        calibrated=tuple(j.joint for j in joints if j.on_robot),
        not_calibrated=tuple(j.joint for j in joints if j.source != "data"),
        missing_required=tuple(int(n) for n in block.get("missing_required") or []),
        as_found=tuple(j.joint for j in joints if j.as_found))


def verdict_of(result: RunResult | None, exit_code: int) -> str:
    """The archive verdict: the result's outcome verdict when it has one (the one source
    of truth; an ERROR exit still says ERROR). An older result without an outcome: a
    refused push is REFUSED, and a verification counts only if offsets were pushed (with
    nothing pushed it is a model check, never a PASS); no result: by the exit code."""
    verify = (result.verify if result is not None else None) or {}
    push_status = result.push.status if result is not None else None
    outcome = outcome_of(result)
    if outcome is not None and outcome.verdict is not None:
        if exit_code not in (0, 5, 6, 7) and outcome.verdict in ("PASS", "NOT_PUSHED"):
            return "ERROR"  # the process failed after writing its result
        return outcome.verdict
    if push_status == "refused" or exit_code == 5:
        return "REFUSED"
    if push_status != "pushed" and exit_code == 0:
        return "NOT_PUSHED"  # a model check on fresh poses is no verification
    if verify.get("verdict") in ("PASS", "FAIL"):
        return str(verify["verdict"])
    if "passed" in verify and verify.get("passed") is not None:
        return "PASS" if verify["passed"] else "FAIL"
    if exit_code in (5, 6):
        return "FAIL"
    if exit_code != 0:
        return "ERROR"
    return "NOT_PUSHED" if push_status != "pushed" else "PASS"


def _float_or_none(value: float | None) -> float | None:
    """A number of the result as a float (None: none, or not a number)."""
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def _offsets(result: RunResult | None) -> tuple[JointOffset, ...]:
    rows = result.offsets if result is not None else ()
    return tuple(JointOffset(joint=row.joint, label=row.label or f"q{row.joint}",
                             old_deg=_float_or_none(row.old_deg),
                             correction_deg=_float_or_none(row.correction_deg),
                             sigma_deg=_float_or_none(row.sigma_deg),
                             new_deg=_float_or_none(row.new_deg), pushed=row.pushed)
                 for row in rows)


def _journal_offsets(folder: Path) -> tuple[JointOffset, ...]:
    """The offsets of a run that wrote no result.json (it stopped after its push, e.g. an
    estop during the verification), from its journal: the last push, unless a rollback
    followed it (none: nothing pushed, or a journal that cannot be read)."""
    try:
        last = Journal(folder).last_event(Pushed, Rollback)
    except InputError:
        return ()
    if not isinstance(last, Pushed):
        return ()
    return push_offsets(last.record)


def push_offsets(record: PushRecord, rolled_back: bool = False) -> tuple[JointOffset, ...]:
    """The archive's offset rows of a push (`record`: previous and new per joint, which
    joints it changed). rolled_back: the push was undone since, so no joint holds its new
    offset (pushed false) and the joints it left alone show no correction."""
    previous, new = record.previous.tolist(), record.new.tolist()
    pushed = record.pushed or tuple(n != o for o, n in zip(previous, new, strict=True))
    return tuple(JointOffset(joint=j, label=f"q{j}", old_deg=math.degrees(o),
                             correction_deg=(None if rolled_back and not p
                                             else math.degrees(n - o)),
                             sigma_deg=None, new_deg=math.degrees(n),
                             pushed=bool(p) and not rolled_back)
                 for j, (o, n, p) in enumerate(zip(previous, new, pushed, strict=True),
                                               start=1))


def verify_figures(result: RunResult | None) -> VerifyFigures:
    verify = (result.verify if result is not None else None) or {}
    return VerifyFigures(_float_or_none(verify.get("statistic")),
                         _float_or_none(verify.get("p_value")), int(verify.get("dof") or 0))


def _read_json(path: Path) -> JsonObject:
    try:
        document = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read run file ({exc})") from None
    if not isinstance(document, dict):
        raise InputError(f"{path}: not a {path.stem} document")
    return document


def read_result(path: Path) -> RunResult:
    """A run's result.json as its value; InputError if it is not a calibration result."""
    try:
        return RunResult.from_dict(_read_json(path))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{path}: not a calibration result document ({exc!r})") from None


def record_from_run(run_dir: str | Path, *, serial: str, model: str = "", station: str = "",
                    exit_code: int | None = None, run_uid: str | None = None,
                    started_at: datetime | None = None, reason: str = "") -> RunRecord:
    """The archive record of the run in `run_dir` (result.json and dataset.json kept whole
    when present; a run that failed before writing them is recorded with what it has).
    exit_code defaults to the one result.json states; `reason` is the one-line reason of a
    run that did not PASS; report_path is RUN/report.html when it exists."""
    folder = Path(run_dir)
    result_path = folder / "result.json"
    result = read_result(result_path) if result_path.exists() else None
    code = int(exit_code if exit_code is not None else
               result.exit_code if result is not None else 1)
    dataset_path = folder / "dataset.json"
    dataset_json = json.dumps(_read_json(dataset_path)) if dataset_path.exists() else None
    offsets = _offsets(result) if result is not None else _journal_offsets(folder)
    corrections = [abs(o.correction_deg) for o in offsets
                   if o.correction_deg is not None and o.pushed]
    run_json = folder / "run.json"
    created = _read_json(run_json).get("created", "") if run_json.exists() else ""
    # the same run folder archived twice is one record: its uid derives from the folder
    # and its creation time unless the caller (the station) gives one
    uid = run_uid or uuid.uuid5(uuid.NAMESPACE_URL, f"zerocal-run:{folder.resolve()}|{created}")
    fit = result.fit if result is not None else {}
    return RunRecord(
        run_uid=str(uid or uuid.uuid4()), serial=serial,
        model=model or str(result.robot.get("name", "") if result is not None else ""),
        station=station, started_at=started_at or datetime.now(UTC),
        method=result.method if result is not None else "",
        effects=tuple(str(e) for e in fit.get("effects", []) or []),
        verdict=verdict_of(result, code), exit_code=code,
        push_status=(result.push.stated_status if result is not None
                     else "pushed" if any(o.pushed for o in offsets) else "none"),
        largest_correction_deg=max(corrections) if corrections else None,
        verify=verify_figures(result), offsets=offsets,
        software_version=__version__, result=result, dataset_json=dataset_json,
        run_dir=str(folder), uid_from_folder=run_uid is None, reason=reason,
        report_path=str(folder / "report.html") if (folder / "report.html").is_file() else "")
