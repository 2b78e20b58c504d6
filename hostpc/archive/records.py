"""A calibration run as one archive record (a frozen value read from a run folder).

A run folder (`hostpc calibrate --out DIR`) holds `result.json` (settings, fit, offsets,
push, verify, truth for a simulated run) and `dataset.json` (the measurements). The record
keeps both whole, so any archived run can be refit later, and lifts out the fields the
history and drift views query: robot serial and model, time, verdict, per-joint offsets
before and after with their sigmas.
"""

from __future__ import annotations

import json
import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from hostpc import __version__
from hostpc.errors import InputError


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
class RunRecord:
    """One archived calibration run.

    verdict: the run's outcome verdict (result.json "outcome", hostpc.calibrate.outcome:
    PASS, FAIL, REFUSED, JOINTS_MISSING, NOT_PUSHED, NOT_VERIFIED, ROLLED_BACK, ERROR);
    for an older result without one see `verdict_of`. exit_code is `hostpc calibrate`'s.
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
    verify: dict[str, Any]
    fit: dict[str, Any]
    offsets: tuple[JointOffset, ...]
    software_version: str
    result: dict[str, Any]
    dataset: dict[str, Any] | None
    run_dir: str = ""
    truth: dict[str, Any] | None = field(default=None)
    uid_from_folder: bool = False
    """True if run_uid derives from the run folder (no caller gave one): the archive then
    also finds the run by its folder (a station's run resumed by hand)."""
    reason: str = ""
    """One line: why the run did not PASS (the station's reason; empty if none given)."""
    report_path: str = ""
    """The run's report.html (empty if it has none)."""


def verdict_of(result: dict[str, Any], exit_code: int) -> str:
    """The archive verdict: the result's outcome verdict when it has one (the one source
    of truth; an ERROR exit still says ERROR). An older result without an outcome: a
    refused push is REFUSED, and a verification counts only if offsets were pushed (with
    nothing pushed it is a model check, never a PASS)."""
    verify = result.get("verify") or {}
    push = result.get("push") or {}
    outcome = result.get("outcome")
    if isinstance(outcome, dict) and isinstance(outcome.get("verdict"), str):
        if exit_code not in (0, 5, 6, 7) and outcome["verdict"] in ("PASS", "NOT_PUSHED"):
            return "ERROR"  # the process failed after writing its result
        return str(outcome["verdict"])
    if push.get("status") == "refused" or exit_code == 5:
        return "REFUSED"
    if push.get("status") != "pushed" and exit_code == 0:
        return "NOT_PUSHED"  # a model check on fresh poses is no verification
    if isinstance(verify, dict) and verify.get("verdict") in ("PASS", "FAIL"):
        return str(verify["verdict"])
    if isinstance(verify, dict) and "passed" in verify and verify.get("passed") is not None:
        return "PASS" if verify["passed"] else "FAIL"
    if exit_code in (5, 6):
        return "FAIL"
    if exit_code != 0:
        return "ERROR"
    return "NOT_PUSHED" if push.get("status") != "pushed" else "PASS"


def _float_or_none(value: Any) -> float | None:
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def _offsets(result: dict[str, Any]) -> tuple[JointOffset, ...]:
    joints = (result.get("offsets") or {}).get("joints") or []
    rows = []
    for index, row in enumerate(joints):
        if not isinstance(row, dict):
            continue
        rows.append(JointOffset(
            joint=int(row.get("joint", index + 1)), label=str(row.get("label", f"q{index + 1}")),
            old_deg=_float_or_none(row.get("old_deg")),
            correction_deg=_float_or_none(row.get("correction_deg")),
            sigma_deg=_float_or_none(row.get("sigma_deg")),
            new_deg=_float_or_none(row.get("new_deg")), pushed=bool(row.get("pushed", False))))
    return tuple(rows)


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read run file ({exc})") from None


def record_from_run(run_dir: str | Path, *, serial: str, model: str = "", station: str = "",
                    exit_code: int | None = None, run_uid: str | None = None,
                    started_at: datetime | None = None, reason: str = "") -> RunRecord:
    """The archive record of the run in `run_dir` (result.json and dataset.json kept whole
    when present; a run that failed before writing them is recorded with what it has).
    exit_code defaults to the one result.json states; `reason` is the one-line reason of a
    run that did not PASS; report_path is RUN/report.html when it exists."""
    folder = Path(run_dir)
    result_path = folder / "result.json"
    result: dict[str, Any] = _read_json(result_path) if result_path.exists() else {}
    if not isinstance(result, dict):
        raise InputError(f"{result_path}: not a calibration result document")
    code = int(exit_code if exit_code is not None else result.get("exit_code", 1))
    dataset_path = folder / "dataset.json"
    dataset = _read_json(dataset_path) if dataset_path.exists() else None
    offsets = _offsets(result)
    corrections = [abs(o.correction_deg) for o in offsets
                   if o.correction_deg is not None and o.pushed]
    run_json = folder / "run.json"
    created = _read_json(run_json).get("created", "") if run_json.exists() else ""
    # the same run folder archived twice is one record: its uid derives from the folder
    # and its creation time unless the caller (the station) gives one
    uid = run_uid or uuid.uuid5(uuid.NAMESPACE_URL, f"zerocal-run:{folder.resolve()}|{created}")
    fit = result.get("fit") or {}
    robot = result.get("robot") or {}
    return RunRecord(
        run_uid=str(uid or uuid.uuid4()), serial=serial,
        model=model or str(robot.get("name", "")), station=station,
        started_at=started_at or datetime.now(UTC),
        method=str(result.get("method", "")),
        effects=tuple(str(e) for e in fit.get("effects", []) or []),
        verdict=verdict_of(result, code), exit_code=code,
        push_status=str((result.get("push") or {}).get("status", "none")),
        largest_correction_deg=max(corrections) if corrections else None,
        verify=dict(result.get("verify") or {}), fit=dict(fit), offsets=offsets,
        software_version=__version__, result=result, dataset=dataset,
        run_dir=str(folder), truth=result.get("truth"), uid_from_folder=run_uid is None,
        reason=reason,
        report_path=str(folder / "report.html") if (folder / "report.html").is_file() else "")
