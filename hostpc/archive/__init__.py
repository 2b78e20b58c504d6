"""The results archive: every calibration run in a database (SQLite or PostgreSQL).

    from hostpc.archive import open_archive, record_from_run
    with open_archive("sqlite:///plant.db") as archive:
        run_id = archive.add(record_from_run("runs/robot-17", serial="R17", model="ur5e"))
        history = archive.runs(serial="R17")

`records` turns a run folder into a `RunRecord` value, `database` stores and reads them
(one versioned schema with migrations), `drift` finds joints whose zero moved between
calibrations (pure), `history_page` renders the history as HTML with plots.
"""

from hostpc.archive.database import Archive, open_archive
from hostpc.archive.drift import DriftFinding, drift_findings
from hostpc.archive.records import JointOffset, RunRecord, record_from_run

__all__ = ["Archive", "DriftFinding", "JointOffset", "RunRecord", "drift_findings",
           "open_archive", "record_from_run"]
