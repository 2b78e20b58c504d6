"""Archived runs as values: what the archive's reads return (hostpc.archive.database).

`ArchivedRun` is a run as the history, drift and station views read it, `Revision` one
outcome a run has had, `StoredRun` a run with its documents. `archived_run` and
`stored_result` turn a database row and a stored result.json into them.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from hostpc.archive.records import JointOffset
from hostpc.calibrate.run_result import RunResult
from hostpc.json_object import JsonObject
from hostpc.kinematics.robots import canonical_name

if TYPE_CHECKING:
    import sqlalchemy as sa


@dataclass(frozen=True)
class ArchivedRun:
    """One archived run as the history, drift and station views read it (`Archive.runs`):
    its archive id, the record's fields (times as ISO 8601 UTC text, the model in the robot
    library's spelling), its revision and its per-joint offsets."""

    id: int
    run_uid: str
    serial: str
    model: str
    station: str
    started_at: str
    archived_at: str
    method: str
    effects: tuple[str, ...]
    verdict: str
    exit_code: int
    push_status: str
    largest_correction_deg: float | None
    software_version: str
    run_dir: str
    revision: int
    reason: str | None
    report_path: str | None
    offsets: tuple[JointOffset, ...]

    def to_json(self) -> JsonObject:
        """The run as `hostpc history --json` prints it (the table's column order)."""
        return asdict(self)


@dataclass(frozen=True)
class Revision:
    """One outcome a run has had (`Archive.revisions`): revision number, time (ISO 8601
    UTC), verdict, exit code, push status, and the result's outcome block as stored
    (None: the result had none)."""

    run_id: int
    revision: int
    revised_at: str
    verdict: str
    exit_code: int
    push_status: str
    outcome: JsonObject | None


@dataclass(frozen=True)
class StoredRun:
    """One archived run with its documents (`Archive.run`): the run, its result (None: the
    run wrote none, or one this version cannot read) and its dataset.json as stored (None:
    none)."""

    run: ArchivedRun
    result: RunResult | None
    dataset_json: str | None


def archived_run(row: sa.Row[Any], offsets: tuple[JointOffset, ...]) -> ArchivedRun:
    """A row of `runs` as its value (runs stored before the model was canonical get it)."""
    return ArchivedRun(
        id=int(row.id), run_uid=row.run_uid, serial=row.serial,
        model=canonical_name(row.model), station=row.station,
        started_at=as_utc(row.started_at).isoformat(),
        archived_at=as_utc(row.archived_at).isoformat(), method=row.method,
        effects=tuple(json.loads(row.effects)), verdict=row.verdict,
        exit_code=int(row.exit_code), push_status=row.push_status,
        largest_correction_deg=row.largest_correction_deg,
        software_version=row.software_version, run_dir=row.run_dir,
        revision=int(row.revision), reason=row.reason, report_path=row.report_path,
        offsets=offsets)


def stored_result(text: str) -> RunResult | None:
    """A stored result.json as its value (None: the run wrote none, or an older version
    wrote one this version cannot read)."""
    try:
        return RunResult.from_dict(json.loads(text))
    except (KeyError, TypeError, ValueError, AttributeError):
        return None


def as_utc(value: datetime) -> datetime:
    """A stored time as an aware UTC time (SQLite keeps them naive)."""
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
