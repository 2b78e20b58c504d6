"""One outcome per run, in every view: result.json's "outcome" block, summary.txt,
report.html and the archive (real SQLite and PostgreSQL) say what the run did to the
robot; a later resume or rollback revises them, never leaving a stale PASS."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.archive import open_archive
from hostpc.archive.records import read_result, verdict_of
from hostpc.calibrate.run_result import RunResult
from hostpc.cli.main import main
from hostpc.db_url import redacted_url
from hostpc.robots.simulator import SimulatedController
from tests.integration.test_calibrate_sim import TOKEN, sim_scenario


def _cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def _outcome(run_dir: Path) -> dict[str, Any]:
    outcome: dict[str, Any] = json.loads((run_dir / "result.json").read_text())["outcome"]
    return outcome


def test_a_refused_push_is_refused_everywhere_and_a_forced_resume_revises_the_archive(
        tmp_path: Path, fast_rig: Path, archive_url: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = _cli(
        capsys, "calibrate", "--robot", "sim", "--max-correction", "0.01", "--poses", "12",
        "--verify-poses", "4", "--rig", str(fast_rig), "--no-report", "--out", str(out),
        "--db", archive_url, "--robot-serial", "SN-1")
    assert code == 5, stderr
    outcome = _outcome(out)
    assert outcome["verdict"] == "REFUSED" and not outcome["pushed"]
    assert outcome["controller"] == "offsets unchanged"
    # the archive the run used, without a password: following it revises the record
    assert outcome["next_command"] == (f"hostpc calibrate --resume {out} --force --db "
                                       f"{redacted_url(archive_url)}")
    assert stdout.splitlines()[0].startswith("REFUSED: push refused, offsets unchanged")
    with open_archive(archive_url) as archive:
        (run,) = archive.runs("SN-1")
        assert run.verdict == "REFUSED" and run.revision == 1

    code, stdout, stderr = _cli(capsys, "calibrate", "--resume", str(out), "--force",
                                "--db", archive_url, "--robot-serial", "SN-1")
    assert code == 0, stderr
    outcome = _outcome(out)
    assert outcome["verdict"] == "PASS" and outcome["controller"] == "new offsets, verified"
    assert [e["event"] for e in outcome["events"]] == [
        "refused", "model_check", "resumed", "pushed", "verified"]
    assert stdout.splitlines()[0].startswith("PASS: J1-J5 calibrated and verified; J6 NOT "
                                             "CALIBRATED (unidentifiable: tool frame")
    with open_archive(archive_url) as archive:
        (run,) = archive.runs("SN-1")  # the same record, revised
        assert run.verdict == "PASS" and run.revision == 2 and run.exit_code == 0
        assert run.push_status == "pushed"
        history = archive.revisions(run.id)
    assert [(r.revision, r.verdict) for r in history] == [(1, "REFUSED"), (2, "PASS")]
    assert history[1].outcome is not None and history[1].outcome["verdict"] == "PASS"


def _offsets(sim: SimulatedController) -> np.ndarray:
    """The zero offsets the simulated controller holds now (its own state)."""
    return np.asarray(sim.truth()["zero_offsets"], float)


def test_a_rollback_rewrites_result_summary_report_and_revises_the_archive(
        tmp_path: Path, fast_rig: Path, archive_url: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    with SimulatedController(sim_scenario(), tmp_path / "stub", token=TOKEN) as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, _, stderr = _cli(
            capsys, "calibrate", "--robot", address, "--token", TOKEN, "--known", "target",
            "--poses", "12", "--verify-poses", "4", "--rig", str(fast_rig), "--cv-folds",
            "0", "--out", str(out), "--db", archive_url, "--robot-serial", "SN-2")
        assert code == 0, stderr
        assert _outcome(out)["verdict"] == "PASS"
        assert "PASS: J1-J5 calibrated and verified" in (out / "report.html").read_text()
        assert not np.allclose(_offsets(sim), before)

        code, stdout, stderr = _cli(capsys, "rollback", "--run", str(out), "--token", TOKEN,
                                    "--db", archive_url, "--robot-serial", "SN-2")
        assert code == 0, stderr
        np.testing.assert_allclose(_offsets(sim), before, rtol=0, atol=1e-12)
    outcome = _outcome(out)
    assert outcome["verdict"] == "ROLLED_BACK" and not outcome["pushed"]
    assert outcome["controller"].startswith("offsets restored by rollback at ")
    assert outcome["rolled_back_at"] and outcome["events"][-1]["event"] == "rolled_back"
    summary = (out / "summary.txt").read_text()
    assert summary.startswith("ROLLED BACK at ") and "controller: offsets restored" in summary
    report = (out / "report.html").read_text()
    assert "ROLLED BACK at " in report and "offsets pushed and verified" not in report
    # the verification section: of offsets the controller no longer has
    assert "Verification of the pushed offsets on fresh poses passed" not in report
    assert "they were rolled back, and the controller has its previous offsets" in report
    assert json.loads((out / "result.1.json").read_text())["outcome"]["verdict"] == "PASS"
    with open_archive(archive_url) as archive:
        (run,) = archive.runs("SN-2")
        assert run.verdict == "ROLLED_BACK" and run.revision == 2
        assert [r.verdict for r in archive.revisions(run.id)] == ["PASS", "ROLLED_BACK"]
    # `hostpc report RUN` renders the same outcome again
    (out / "report.html").unlink()
    code, _, stderr = _cli(capsys, "report", str(out), "--no-diagnosis")
    assert code == 0, stderr
    assert "ROLLED BACK at " in (out / "report.html").read_text()
    code, stdout, _ = _cli(capsys, "history", "--db", archive_url)
    assert "last ROLLED_BACK" in stdout


def test_an_estimated_target_leaves_j1_and_j6_not_calibrated_exit_7(
        tmp_path: Path, fast_rig: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = _cli(
        capsys, "calibrate", "--robot", "sim", "--known", "none", "--require-joints", "all",
        "--poses", "12", "--verify-poses", "4", "--rig", str(fast_rig), "--out", str(out))
    assert code == 7, stderr
    outcome = _outcome(out)
    assert outcome["verdict"] == "JOINTS_MISSING" and outcome["missing_required"] == [1, 6]
    joints = {j["joint"]: j for j in outcome["joints"]}
    assert [n for n, j in joints.items() if j["status"] == "calibrated"] == [2, 3, 4, 5]
    assert all(joints[n]["verified"] is True and joints[n]["pushed"] for n in (2, 3, 4, 5))
    assert "target frame estimated" in joints[1]["reason"]
    assert joints[1]["fix"].startswith("--known target")
    assert "tool frame estimated" in joints[6]["reason"]
    seed = json.loads((out / "result.json").read_text())["settings"]["seed"]
    new_run = (f"hostpc calibrate --robot sim --method stereo_target --scenario "
               f"{out / 'sim' / 'scenario.json'} --seed {seed}")
    # a new run with the frames surveyed, or a reference of a run that calibrated J1, J6
    assert outcome["next_command"].startswith(
        f"{new_run} --known target,tool --require-joints all (with the target and tool "
        f"frame surveyed), or {new_run} --reference CELL_REFERENCE.json --require-joints all")
    assert f"reference record --run {out}" not in outcome["next_command"]
    head = stdout.splitlines()[0]
    assert head.startswith("JOINTS_MISSING: J2-J5 calibrated and verified; J1 NOT CALIBRATED")
    report = (out / "report.html").read_text()
    assert 'id="joints"' in report and report.count("NOT CALIBRATED") >= 2
    assert verdict_of(read_result(out / "result.json"), 7) == "JOINTS_MISSING"


@pytest.mark.parametrize("constraint", ["--prior", "--hold"])
def test_held_and_prior_values_are_marked_and_never_pushed(
        tmp_path: Path, fast_rig: Path, capsys: pytest.CaptureFixture[str],
        constraint: str) -> None:
    out = tmp_path / "run"
    # q6 is not separable from the estimated tool frame: a prior alone decides it; a
    # held q2 stays at its nominal value
    joint, value, mark, source = ((6, "joint_offsets.q6=0+-0.05deg", "(prior)", "prior")
                                  if constraint == "--prior" else
                                  (2, "joint_offsets.q2", "(held)", "hold"))
    code, _, stderr = _cli(
        capsys, "calibrate", "--robot", "sim", "--poses", "12", "--verify-poses", "0",
        "--rig", str(fast_rig), constraint, value, "--out", str(out), "--force")
    assert code == 0, stderr
    joints = {j["joint"]: j for j in _outcome(out)["joints"]}
    assert (joints[joint]["source"], joints[joint]["status"]) == (source, "not_calibrated")
    assert not joints[joint]["pushed"] and joints[1]["source"] == "data"
    rows = {r["joint"]: r for r in json.loads((out / "result.json").read_text())
            ["offsets"]["joints"]}
    assert not rows[joint]["pushed"] and rows[1]["pushed"]
    assert rows[joint]["new_deg"] == rows[joint]["old_deg"]
    summary = (out / "summary.txt").read_text()
    table = {line.split()[0]: line for line in summary.splitlines()
             if line.startswith("  J")}
    assert mark in table[f"J{joint}"] and "NOT CALIBRATED" in table[f"J{joint}"], summary
    assert mark not in table["J1"]
    report = (out / "report.html").read_text()
    assert mark in report and 'id="joints"' in report
    # the plan's joints line, the summary's and result.json's plan.joints say the same
    plan = json.loads((out / "result.json").read_text())["plan"]
    words = {"hold": "held at nominal by --hold", "prior": "from its --prior"}[source]
    assert f"J{joint} {words}" in plan["joints"]["text"]
    assert f"J{joint}" not in plan["joints"]["text"].split(" from the measurements")[0]
    assert f"J{joint} {words}" in next(line for line in summary.splitlines()
                                        if line.startswith("joints: "))
    assert plan["joints"]["held" if source == "hold" else "from_prior"] == [f"J{joint}"]
    if source == "hold":  # a held joint is not estimated: no predicted sigma
        assert plan["predicted_joint_sigma_deg"][joint - 1] is None


def test_a_fit_failed_with_a_hold_and_a_prior_names_them(
        tmp_path: Path, fast_rig: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The default world's zero errors are random (0.5 deg scale): J3 held at nominal and a
    tight prior J2 = 0 +- 0.0001 deg are both wrong and make the model fail; the refusal
    names them as the likely cause."""
    out = tmp_path / "run"
    code, stdout, stderr = _cli(
        capsys, "calibrate", "--robot", "sim", "--poses", "12", "--verify-poses", "4",
        "--rig", str(fast_rig), "--hold", "joint_offsets.q3", "--prior",
        "joint_offsets.q2=0+-0.0001deg", "--out", str(out))
    assert code == 5, stderr
    outcome = _outcome(out)
    assert outcome["verdict"] == "REFUSED"
    assert ("the fit failed with J3 held and a prior on J2: a likely cause; run again "
            "without them or check them") in outcome["headline"]
    assert stdout.splitlines()[0] == outcome["headline"]
    joints = json.loads((out / "result.json").read_text())["plan"]["joints"]
    assert (joints["held"], joints["from_prior"]) == (["J3"], ["J2"])
    assert "J2" not in joints["from_measurements"] and "J3" not in joints["from_measurements"]


def _older(**blocks: dict[str, object]) -> RunResult:
    """A result an older version wrote (no outcome block) with these blocks."""
    return RunResult.from_dict({"acquisition": {"n_planned": 0, "n_measured": 0}, "fit": {},
                                **blocks})


def test_an_old_result_with_a_refused_push_is_never_pass() -> None:
    old = _older(push={"status": "refused"}, verify={"verdict": "PASS", "pushed": False})
    assert verdict_of(old, 5) == "REFUSED"
    model_check = _older(push={"status": "disabled"}, verify={"verdict": "PASS"})
    assert verdict_of(model_check, 0) == "NOT_PUSHED"


def test_a_stored_joint_row_reads_as_the_runs_own_joint_outcome() -> None:
    """The archive and the station's registers (57 JOINTS_AS_FOUND, 14 JOINTS_CALIBRATED)
    read result.json's joint rows as `JointOutcome`s (`from_dict`), so they ask the same
    properties as the run's headline: every kind of row reads back equal, and the
    archive's figures are those properties."""
    from hostpc.archive.records import outcome_of
    from hostpc.calibrate.outcome import JointOutcome

    def joint(number: int, **fields: Any) -> JointOutcome:
        row: dict[str, Any] = {"joint": number, "label": f"q{number}",
                               "status": "calibrated", "source": "data", "pushed": True,
                               "verified": True, "reason": None, "fix": None}
        return JointOutcome(**{**row, **fields})

    joints = [joint(1, restored_from="/runs/ref", reference_zero="as_found"),
              joint(2, restored_from="/runs/ref", reference_zero="measured"),
              joint(3, restored_from="/runs/ref", reference_zero="unknown"),
              joint(4, verified=False, status="not_calibrated"),
              joint(5, pushed=False, verified=None, applied_on_host=True),
              joint(6, status="not_calibrated", source="hold", pushed=False, verified=None,
                    reason="held by --hold", fix="drop --hold")]
    rows = json.loads(json.dumps([j.to_dict() for j in joints]))  # as result.json has them
    assert [JointOutcome.from_dict(row) for row in rows] == joints
    result = _older(outcome={"verdict": "PASS", "headline": "", "pushed": True,
                             "verified": True, "joints": rows})
    figures = outcome_of(result)
    assert figures is not None
    assert figures.as_found == tuple(j.joint for j in joints if j.as_found) == (1, 3)
    assert figures.calibrated == tuple(j.joint for j in joints if j.on_robot) == (1, 2, 3, 5)
    assert figures.not_calibrated == (6,)
