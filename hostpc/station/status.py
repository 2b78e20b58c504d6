"""What the station knows of its runs, as values: the run in progress (`CurrentRun`, the
runs folder's current.json), the live page's view of the station (`StationStatus`) and of
the runs it concluded (`RecentRun`). hostpc.station.service keeps them up to date.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from hostpc.json_object import JsonObject


@dataclass(frozen=True)
class CurrentRun:
    """The run in progress (``current.json`` under the runs folder: hostpc.station.service
    resumes it after a restart): its archive uid, robot serial and model, run folder,
    start time (ISO 8601 UTC), the resumes taken so far and what the last resume of its
    push in flight found the controller holding (hostpc.station.runner.controller_held:
    "previous", "other", "" not known or the pushed offsets)."""

    run_uid: str
    serial: str
    model: str
    run_dir: str
    started_at: str
    attempts: int = 0
    held: str = ""

    def to_json(self) -> JsonObject:
        """current.json's document ("held" only once a resume found it)."""
        document = dataclasses.asdict(self)
        if not self.held:
            del document["held"]
        return document

    @classmethod
    def from_json(cls, document: JsonObject) -> CurrentRun:
        """current.json read back; KeyError / TypeError / ValueError if it is damaged."""
        return cls(run_uid=str(document["run_uid"]), serial=str(document["serial"]),
                   model=str(document.get("model", "")), run_dir=str(document["run_dir"]),
                   started_at=str(document["started_at"]),
                   attempts=int(document.get("attempts", 0)),
                   held=str(document.get("held", "")))


@dataclass(frozen=True)
class RecentRun:
    """A concluded run as the live page's state lists it (`StationStatus.recent`)."""

    serial: str
    verdict: str
    result_code: int
    archive_id: int | None
    run_dir: str
    reason: str


@dataclass
class StationStatus:
    """What the live page and the log show of the station: the robot, progress and output
    line of the run in progress (RUNNING); the result of the last run until acknowledged
    (PASS, FAIL, ERROR: result code, reason and its code, archive id, report); none of it
    when IDLE."""

    state: str = "IDLE"
    serial: str = ""
    model: str = ""
    progress: int = 0
    last_line: str = ""
    run_dir: str = ""
    result_code: int | None = None
    reason: str = ""
    reason_code: int = 0
    archive_id: int | None = None
    report: str = ""
    """The last run's report.html as the live page serves it (/runs/ID/report.html)."""
    runs_done: int = 0
    recent: list[RecentRun] = field(default_factory=list)

    def clear_run(self) -> None:
        """Nothing of the last run (the station is IDLE, or a new run starts)."""
        self.serial = self.model = self.last_line = self.run_dir = ""
        self.reason, self.reason_code, self.report = "", 0, ""
        self.progress, self.result_code, self.archive_id = 0, None, None
