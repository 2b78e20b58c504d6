"""`hostpc calibrate --resume RUN --effects +EFFECT` refits the measured dataset with the new
model, pushes and verifies without measuring the fit poses again (issue 11), on the world
with a hidden joint compliance: the pushed offsets' truth error falls."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.robots.simulator import load_scenario_file
from tests.integration.test_calibrate_sim import run_cli, truth_rig_file

REPO = Path(__file__).resolve().parents[2]
HIDDEN = REPO / "controller_stub" / "scenarios" / "stereo_hidden_compliance.yaml"


def calibrate_hidden(tmp_path: Path, capsys: pytest.CaptureFixture[str], *options: str
                     ) -> tuple[Path, int, str, str]:
    """`hostpc calibrate --robot sim` in the hidden-compliance world (its true rig, the
    target known, no cross-validation, no report, --json) with `options`: (run folder,
    exit code, stdout, stderr)."""
    rig = truth_rig_file(load_scenario_file(HIDDEN), tmp_path / "rig.json")
    run = tmp_path / "run"
    code, stdout, stderr = run_cli(
        capsys, "calibrate", "--robot", "sim", "--scenario", str(HIDDEN), "--known", "target",
        "--rig", str(rig), "--cv-folds", "0", "--no-report", "--json", "--out", str(run),
        *options)
    return run, code, stdout, stderr


def _fit_lines(run: Path) -> list[str]:
    return [line for line in (run / "journal.jsonl").read_text().splitlines()
            if '"phase":"fit"' in line]


@pytest.mark.slow
def test_resume_with_the_missing_effect_refits_pushes_and_verifies(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, code, stdout, stderr = calibrate_hidden(tmp_path, capsys, "--poses", "40")
    assert code == 5, stderr  # the lean model does not explain the data: push refused
    lean = json.loads(stdout)
    assert lean["push"]["status"] == "refused" and lean["verify"]["verdict"] == "FAIL"
    measured = _fit_lines(run)

    code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(run), "--effects",
                                   "+joint_compliance", "--json")
    assert code == 0, stderr
    full = json.loads(stdout)
    assert "joint_compliance" in full["fit"]["effects"]
    assert full["push"]["status"] == "pushed" and full["verify"]["verdict"] == "PASS"
    assert _fit_lines(run) == measured  # not one fit pose measured again
    assert full["truth"]["max_abs_error_deg"] < 0.5 * lean["truth"]["max_abs_error_deg"]
    # the refused run's result is kept beside the new one
    assert json.loads((run / "result.1.json").read_text())["push"]["status"] == "refused"


@pytest.mark.slow
def test_a_resume_after_a_push_never_measures_more_fit_poses(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The short plan grows (more fit poses) when its model fails, but never after a push:
    poses measured under the pushed offsets would be fitted as if taken under the initial
    ones. Session 1 fits the right model on the short plan and pushes; the resume drops
    joint_compliance, so its model fails the chi2 band: it must refit the journaled poses
    only (the old runner measured the plan's further poses under the pushed offsets)."""
    run, code, stdout, stderr = calibrate_hidden(tmp_path, capsys, "--effects",
                                                 "+joint_compliance")
    first = json.loads(stdout)
    assert first["push"]["status"] == "pushed", (code, stderr)
    measured = _fit_lines(run)

    code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(run),
                                   "--effects", "joint_offsets,tool", "--json")
    assert _fit_lines(run) == measured, "fit poses measured after the push"
    assert '"event":"more_poses"' not in (run / "journal.jsonl").read_text().replace(" ", "")
