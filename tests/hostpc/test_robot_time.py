"""Robot time per phase (hostpc.calibrate.robot_time): journaled, summed over sessions."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.robot_time import format_robot_time, robot_time_document


def test_robot_time_sums_every_session_per_phase(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    journal.write_header({"settings": {}})
    assert robot_time_document(journal) == {"rig": 0.0, "measure": 0.0, "verify": 0.0,
                                            "total": 0.0, "clock": None}
    journal.event("robot_time", phase="rig", seconds=2.0, clock="controller")
    journal.event("robot_time", phase="measure", seconds=7.5, clock="controller")
    journal.event("robot_time", phase="measure", seconds=1.25, clock="controller")  # resume
    journal.event("robot_time", phase="verify", seconds=4.0, clock="controller")
    journal.event("robot_time", phase="bogus", seconds=99.0, clock="controller")
    reread = Journal(tmp_path)  # from the file, as a resume reads it
    document = robot_time_document(reread)
    assert document == {"rig": 2.0, "measure": 8.75, "verify": 4.0,
                        "total": pytest.approx(14.75), "clock": "controller"}
    line = format_robot_time({"robot_time_s": document})
    assert line == ("robot time: 14.8 s (rig 2.0, measure 8.8, verify 4.0; controller "
                    "clock)")
    journal.event("robot_time", phase="verify", seconds=1.0, clock="host")
    assert robot_time_document(journal)["clock"] == "mixed"
    assert format_robot_time({}) is None
