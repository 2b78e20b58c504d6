"""What `hostpc history` shows a person: times to the second in the local time zone (named),
and one spelling per robot model whichever way the PLC or the CLI wrote it."""

from __future__ import annotations

import os
import subprocess
from datetime import UTC, datetime
from pathlib import Path

from hostpc.archive import RunRecord, open_archive
from hostpc.archive.records import VerifyFigures
from hostpc.kinematics.robots import canonical_name
from tests.station.conftest import REPO, hostpc_command


def _record(uid: str, model: str, started_at: datetime) -> RunRecord:
    return RunRecord(
        run_uid=uid, serial="SN-7", model=model, station="cell-1", started_at=started_at,
        method="stereo_target", effects=("joint_offsets",), verdict="PASS", exit_code=0,
        push_status="pushed", largest_correction_deg=0.01, verify=VerifyFigures(), offsets=(),
        software_version="test", result=None, dataset_json=None)


def test_model_names_are_the_robot_librarys_spelling():
    assert canonical_name("UR5e") == "ur5e"
    assert canonical_name(" UR10E ") == "ur10e"
    assert canonical_name("Customer-Arm 3") == "Customer-Arm 3"  # not built in: kept


def test_history_shows_local_seconds_and_one_model_name(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 'archive.db'}"
    with open_archive(db) as archive:
        archive.add(_record("a", "UR5e", datetime(2026, 1, 5, 11, 30, 7, 654321, tzinfo=UTC)))
        archive.add(_record("b", "ur5e", datetime(2026, 1, 6, 11, 30, 8, 123456, tzinfo=UTC)))
        assert {run.model for run in archive.runs()} == {"ur5e"}
    env = {**os.environ, "PYTHONPATH": str(REPO), "TZ": "CET-1"}
    page = tmp_path / "history.html"
    run = subprocess.run(hostpc_command("history", "--db", db, "--html", str(page)), cwd=REPO,
                         env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    fleet = [line for line in run.stdout.splitlines() if line.startswith("SN-7")]
    assert len(fleet) == 1 and " ur5e " in fleet[0]
    assert "last PASS       2026-01-06 12:30:08 CET" in fleet[0]
    html = page.read_text()
    assert "2026-01-05 12:30:07 CET" in html and "654321" not in html
