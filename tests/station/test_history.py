"""Drift between calibrations: the pure finding rule, and `hostpc history` on a robot
calibrated 5 times by the simulated controller with a growing drift of joint 3."""

from __future__ import annotations

import copy
import json
import subprocess
from pathlib import Path

import pytest

from hostpc.archive.drift import drift_findings, fleet_summary
from hostpc.archive.records import JointOffset
from hostpc.archive.rows import ArchivedRun
from hostpc.robots.simulator import default_sim_scenario
from tests.station.conftest import REPO, hostpc_command


def _run(run_id: int, serial: str, zeros: list[float], sigma: float = 1e-4) -> ArchivedRun:
    stamp = f"2026-01-0{run_id}T00:00:00+00:00"
    return ArchivedRun(
        id=run_id, run_uid=f"uid-{run_id}", serial=serial, model="ur5e", station="cell",
        started_at=stamp, archived_at=stamp, method="stereo_target", effects=(),
        verdict="PASS", exit_code=0, push_status="pushed", largest_correction_deg=None,
        software_version="test", run_dir="", revision=1, reason=None, report_path=None,
        offsets=tuple(JointOffset(joint=j + 1, label=f"q{j + 1}", old_deg=None,
                                  correction_deg=None, sigma_deg=sigma, new_deg=z, pushed=True)
                      for j, z in enumerate(zeros)))


def test_drift_is_raised_on_the_joint_that_moved_and_only_there() -> None:
    runs = [_run(1, "A", [0.1, 0.2, 0.3]), _run(2, "A", [0.1001, 0.2, 0.35]),
            _run(3, "B", [0.0, 0.0, 0.0]), _run(4, "B", [0.0002, -0.0001, 0.0])]
    findings = drift_findings(runs)
    assert [(f.serial, f.label) for f in findings] == [("A", "q3")]
    assert findings[0].moved_deg == pytest.approx(0.05)
    # below the threshold but far beyond what the two fits' sigmas allow
    precise = [_run(1, "C", [0.0]), _run(2, "C", [0.005])]
    assert drift_findings(precise, threshold_deg=0.02)[0].z == pytest.approx(0.005 / 1.414e-4,
                                                                            rel=1e-3)
    assert drift_findings([_run(1, "D", [0.0]), _run(2, "D", [0.0003])]) == []
    assert fleet_summary(runs)[0].serial == "A"


@pytest.mark.slow
def test_history_raises_the_drift_alarm_on_the_drifting_joint(tmp_path: Path,
                                                              fast_rig: Path) -> None:
    base = default_sim_scenario()  # the default stereo cell: target surveyed (known)
    db = f"sqlite:///{tmp_path / 'archive.db'}"
    zeros = [-0.2, 0.15, 0.1, -0.3, 0.25, 0.0]
    for calibration in range(5):
        scenario = copy.deepcopy(base)
        drifted = list(zeros)
        drifted[2] += 0.03 * calibration ** 1.5  # joint 3 slips more each time
        scenario["truth"]["zero_errors"] = [z * 3.141592653589793 / 180 for z in drifted]
        path = tmp_path / f"world{calibration}.json"
        path.write_text(json.dumps(scenario))
        run = subprocess.run(hostpc_command(
            "calibrate", "--robot", "sim", "--scenario", str(path), "--poses", "12",
            "--verify-poses", "4", "--rig", str(fast_rig), "--no-report", "--known", "target",
            "--out", str(tmp_path / f"run{calibration}"), "--db", db,
            "--robot-serial", "UR-DRIFT"), cwd=REPO, capture_output=True, text=True,
            timeout=300)
        assert "archived as run" in run.stderr, run.stderr[-1500:]
    page = tmp_path / "history.html"
    history = subprocess.run(hostpc_command("history", "--db", db, "--robot", "UR-DRIFT",
                                            "--json", "--html", str(page)),
                             cwd=REPO, capture_output=True, text=True, timeout=120)
    assert history.returncode == 1, history.stderr  # 1 = a drift alarm
    document = json.loads(history.stdout)
    assert len(document["runs"]) == 5
    assert {d["joint"] for d in document["drift"]} == {"q3"}
    assert len(document["drift"]) >= 2  # the later, larger moves at least
    html = page.read_text()
    assert "DRIFT UR-DRIFT q3" in html and "data:image/png;base64," in html


def test_history_html_to_a_bad_path_is_one_line_exit_2(tmp_path: Path) -> None:
    from hostpc.archive import open_archive

    db = f"sqlite:///{tmp_path / 'archive.db'}"
    open_archive(db).close()  # an (empty) archive: history reads, never creates one
    for target in (tmp_path / "missing" / "h.html", tmp_path):
        run = subprocess.run(hostpc_command("history", "--db", db, "--html", str(target)),
                             cwd=REPO, capture_output=True, text=True, timeout=120)
        assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
        assert "cannot write" in run.stderr


def test_a_relative_sqlite_archive_is_beside_the_config_file(tmp_path: Path) -> None:
    from hostpc.station.config import load_station_config

    config_file = tmp_path / "cell" / "station.yaml"
    config_file.parent.mkdir()
    config_file.write_text("robot: sim\ndb: sqlite:///station.db\n")
    config = load_station_config(config_file)
    assert config.database_url() == f"sqlite:///{(tmp_path / 'cell' / 'station.db').resolve()}"
    absolute = load_station_config(config_file, db="sqlite:////var/x.db")
    assert absolute.database_url() == "sqlite:////var/x.db"
