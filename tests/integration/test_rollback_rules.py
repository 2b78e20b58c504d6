"""A run's next commands keep its archive, and a rollback revises what the run did, never
more (review C: a technician, and an end-of-line station whose controller dies mid-run).

- F1: every resume / rollback a run archived with `--db` prints names the archive
  (hostpc.calibrate.next_commands), and a resume or rollback given no `--db` uses the
  archive its run.json names: a push cut short, then the resume as printed, reaches the
  archive (it was never created before).
- F2: the rollback of a run that stopped after its push (ERROR, no result.json) revises
  the archived record to ROLLED_BACK from the journal; the station's registers follow.
- F3: a rollback after the controller took a later push (the next robot's) refuses, nothing
  written, naming that push and the override.
- F5: a rolled-back FAIL has no joint calibrated (the PLC read 011111 after it).
- F7: `hostpc report` of a rolled-back run without a result names no resume to finish and
  the controller's address.

Against real simulated controllers (sockets, port 0) and real SQLite archives.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.archive import open_archive, record_from_run
from hostpc.robots.simulator import SimulatedController
from hostpc.station import registers as reg
from hostpc.station.service import archived_outcome
from tests.integration.calibrate_cli import robot_args
from tests.integration.test_calibrate_sim import run_cli, sim_scenario, truth_rig_file

# requests of the run below (--rig, 8 poses): get_state, get_offsets, the clock reading
# after the rig, (move, capture, clock) per pose, then the push's get_offsets: 28 is its
# set_offsets, 30 the move to the first verification pose (after the read-back)
DROP_SET_OFFSETS = 28
DROP_FIRST_VERIFY_MOVE = 30


def _calibrate(capsys: pytest.CaptureFixture[str], sim: SimulatedController, rig: Path,
               run: Path, url: str, *extra: str) -> tuple[int, str, str]:
    return run_cli(capsys, "calibrate", *robot_args(sim), "--known", "target", "--rig",
                   str(rig), "--poses", "8", "--verify-poses", "4", "--db", url, "--out",
                   str(run), "--no-report", *extra)


def _printed(text: str, prefix: str) -> list[str]:
    """The arguments of the command starting with `prefix` in `text` (up to ` (`, `)`,
    `;` or the line's end)."""
    start = text.index(prefix)
    end = min([i for i in (text.find(c, start) for c in (" (", ")", ";", "\n")) if i >= 0]
              + [len(text)])
    return shlex.split(text[start:end])[1:]


def _offsets(sim: SimulatedController) -> np.ndarray:
    import asyncio

    from hostpc.robots.connect import open_robot

    async def read() -> np.ndarray:
        robot = await open_robot(sim.address, "zerocal", token="zerocal-sim", timeout=5.0)
        try:
            return np.asarray(await robot.get_offsets(), float)
        finally:
            await robot.close()
    return asyncio.run(read())


def test_a_cut_push_resumed_as_printed_reaches_the_archive(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run, db = tmp_path / "r1", tmp_path / "a.db"
    url = f"sqlite:///{db}"
    with SimulatedController(sim_scenario(drop_after_requests=DROP_SET_OFFSETS),
                             tmp_path / "stub") as sim:
        code, _, err = _calibrate(capsys, sim, rig, run, url)
        assert code == 3 and "during set_offsets" in err, err
        resume = _printed(err, "hostpc calibrate --resume")
        assert resume[-2:] == ["--db", url], resume
        assert _printed(err, "hostpc rollback --run")[-2:] == ["--db", url]
        code, out, err = run_cli(capsys, *resume, "--token", "zerocal-sim")
        assert code == 0, err
        # the PASS's undo line names the archive too
        assert f"undo with hostpc rollback --run {run} --db {url})" in out, out
    with open_archive(url, create=False) as archive:
        (record,) = archive.runs(f"{sim.address.host}:{sim.address.port}")
        assert record.verdict == "PASS"


def test_a_rollback_without_db_revises_the_runs_archive(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The command an older run printed (no --db) still reaches the run's archive."""
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run, url = tmp_path / "r1", f"sqlite:///{tmp_path / 'a.db'}"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        code, _, err = _calibrate(capsys, sim, rig, run, url, "--robot-serial", "SN-P")
        assert code == 0, err
        code, out, err = run_cli(capsys, "rollback", "--run", str(run))
        assert code == 0, err
        assert f"archive: {url}" in err
    with open_archive(url, create=False) as archive:
        (record,) = archive.runs("SN-P")
        assert [r.verdict for r in archive.revisions(record.id)] == ["PASS", "ROLLED_BACK"]


def test_rolling_back_a_fail_calibrates_no_joint(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run, url = tmp_path / "r1", f"sqlite:///{tmp_path / 'a.db'}"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        code, _, err = _calibrate(capsys, sim, rig, run, url, "--robot-serial", "SN-F",
                                  "--verify-tolerance", "0.001")
        assert code == 6, err
        assert run_cli(capsys, *_printed(json.loads((run / "result.json").read_text())
                                         ["outcome"]["next_command"], "hostpc"))[0] == 0
    outcome = json.loads((run / "result.json").read_text())["outcome"]
    assert outcome["verdict"] == "ROLLED_BACK"
    assert [j["status"] for j in outcome["joints"]] == ["not_calibrated"] * 6
    assert all(j["verified"] is None and not j["pushed"] for j in outcome["joints"])
    with open_archive(url, create=False) as archive:
        (record,) = archive.runs("SN-F")
        registers = archived_outcome(archive.run(record.id))
    assert registers.joints_calibrated == 0  # it read 0b011111 (J1-J5) before
    assert registers.state == reg.State.FAIL
    assert registers.outcome_flags & reg.FLAG_ROLLED_BACK


def _station_archive(run: Path, url: str, serial: str) -> int:
    """Archive a run that ended in an error as the station does (its own run uid)."""
    with open_archive(url) as archive:
        return archive.add(record_from_run(run, serial=serial, exit_code=3,
                                           run_uid=f"station-{serial}"))


@pytest.fixture(scope="module")
def rolled_back_error(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A run whose link was lost after its push (before the verification: ERROR, no
    result.json), archived as the station archives it, then rolled back by the command
    it printed (no --db: the run's archive)."""
    from hostpc.cli.main import main

    tmp_path = tmp_path_factory.mktemp("rolled_back_error")
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run, url = tmp_path / "r1", f"sqlite:///{tmp_path / 'a.db'}"
    with SimulatedController(sim_scenario(drop_after_requests=DROP_FIRST_VERIFY_MOVE),
                             tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        code = main(["calibrate", "--robot", address, "--token", "zerocal-sim", "--known",
                     "target", "--rig", str(rig), "--poses", "8", "--verify-poses", "4",
                     "--db", url, "--out", str(run), "--no-report"])
        assert code == 3 and not (run / "result.json").exists()
        archive_id = _station_archive(run, url, "SN-E")
        assert main(["rollback", "--run", str(run)]) == 0
        offsets = _offsets(sim)
    return {"run": run, "url": url, "archive_id": archive_id, "address": address,
            "offsets": offsets, "push": json.loads((run / "push.json").read_text())}


def test_rolling_back_a_run_stopped_after_its_push_revises_its_record(
        rolled_back_error: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    pushed = rolled_back_error["push"]
    assert np.allclose(rolled_back_error["offsets"], pushed["previous_offsets"], atol=1e-12)
    with open_archive(rolled_back_error["url"], create=False) as archive:
        stored = archive.run(rolled_back_error["archive_id"])
        revisions = archive.revisions(rolled_back_error["archive_id"])
    assert [(r.verdict, r.push_status) for r in revisions] == [
        ("ERROR", "pushed"), ("ROLLED_BACK", "rolled_back")]
    assert stored.run.revision == 2 and stored.run.serial == "SN-E"
    assert len(stored.run.offsets) == 6 and not any(o.pushed for o in stored.run.offsets)
    assert [o.new_deg for o in stored.run.offsets] == pytest.approx(
        np.degrees(pushed["new_offsets"]))
    registers = archived_outcome(stored)  # the station follows its record
    assert registers.state == reg.State.FAIL and registers.joints_calibrated == 0
    assert registers.outcome_flags == reg.FLAG_ROLLED_BACK
    # its rollback again: nothing rolled back twice, the record stays as it is
    code, out, _ = run_cli(capsys, "rollback", "--run", str(rolled_back_error["run"]),
                           "--db", rolled_back_error["url"])
    assert code == 0 and "rolled back already" in out and "ROLLED_BACK" in out
    with open_archive(rolled_back_error["url"], create=False) as archive:
        assert len(archive.revisions(rolled_back_error["archive_id"])) == 2


def test_the_report_of_a_rolled_back_unfinished_run_names_no_resume_to_finish(
        rolled_back_error: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(capsys, "report", str(rolled_back_error["run"]))
    assert code == 2
    assert "finish it" not in err and "--robot HOST" not in err, err
    assert f"hostpc status --robot {rolled_back_error['address']}" in err
    assert "rolled back" in err and f"--db {rolled_back_error['url']}" in err


def _pushed_fail(capsys: pytest.CaptureFixture[str], sim: SimulatedController, rig: Path,
                 run: Path, url: str, serial: str) -> dict[str, Any]:
    code, _, err = _calibrate(capsys, sim, rig, run, url, "--robot-serial", serial,
                              "--verify-tolerance", "0.001")
    assert code == 6, err
    push: dict[str, Any] = json.loads((run / "push.json").read_text())
    return push


def test_a_rollback_after_the_next_robots_push_refuses(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    runs, url = tmp_path / "runs", f"sqlite:///{tmp_path / 'a.db'}"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        _pushed_fail(capsys, sim, rig, runs / "g", url, "SN-G")
        h = _pushed_fail(capsys, sim, rig, runs / "h", url, "SN-H")
        code, out, err = run_cli(capsys, "rollback", "--run", str(runs / "g"))
        assert code == 2, (out, err)
        line = err.strip().splitlines()[-1]
        assert f"run {runs / 'h'} at {h['time']}" in line, line
        assert "--discard-later-push" in line and "nothing written" in line
        assert f"--db {url} " in line
        assert np.allclose(_offsets(sim), h["new_offsets"], atol=1e-12)  # H's, untouched
        events = [json.loads(line).get("event") for line in
                  (runs / "g" / "journal.jsonl").read_text().splitlines()]
        assert "rollback" not in events
        code, _, err = run_cli(capsys, "rollback", "--run", str(runs / "g"),
                               "--discard-later-push")
        assert code == 0, err
        g = json.loads((runs / "g" / "push.json").read_text())
        assert np.allclose(_offsets(sim), g["previous_offsets"], atol=1e-12)
