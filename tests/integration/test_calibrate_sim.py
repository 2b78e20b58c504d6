"""`hostpc calibrate --robot sim`: the README's main job, end to end, against the truth.

The simulated controller runs as a subprocess on 127.0.0.1 (real sockets); the rig is
calibrated from its chessboard captures; 60 planned poses; the result is compared with the
injected zero errors. Also the helpers the other calibrate tests share.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import load_dataset
from hostpc.kinematics import rpy_to_matrix
from hostpc.robots.simulator import default_sim_scenario

TOKEN = "zerocal-sim"


def truth_rig_file(scenario: dict[str, Any], path: Path) -> Path:
    """A rig file with the scenario's TRUE camera model (a perfectly calibrated rig), so
    tests that are not about rig calibration skip it."""
    from hostpc.vision import StereoRig, save_rig

    cam = scenario["camera"]
    K = np.array([[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]])
    R_left_right = rpy_to_matrix(np.asarray(cam["right_rpy"], float))
    t_left_right = np.array([cam["baseline"], 0.0, 0.0])
    rig = StereoRig(
        image_size=(cam["image_width"], cam["image_height"]), K_left=K,
        dist_left=np.asarray(cam["distortion"], float), K_right=K,
        dist_right=np.asarray(cam["distortion"], float), R=R_left_right.T,
        T=-R_left_right.T @ t_left_right, rms=0.0, n_views=0,
    )
    save_rig(rig, path)
    return path


def calibrate_rig_through_stub(scenario: dict[str, Any], workdir: Path, path: Path) -> Path:
    """Calibrate a rig the way a user would, from the stub's chessboard captures."""
    from hostpc.robots.simulator import SimulatedController
    from hostpc.robots.zerocal import ZerocalAdapter
    from hostpc.vision import ChessboardSpec, calibrate_rig, save_rig

    board = scenario["chessboard"]

    async def capture_all(host: str, port: int) -> list[tuple[np.ndarray, np.ndarray]]:
        robot = await ZerocalAdapter.connect(host, port, token=TOKEN)
        try:
            pairs = []
            for view in range(board["n_views"]):
                capture = await robot.capture("chessboard", view)
                pairs.append((capture.left.copy(), capture.right.copy()))
            return pairs
        finally:
            await robot.close()

    with SimulatedController(scenario, workdir) as sim:
        pairs = asyncio.run(capture_all(sim.address.host, sim.address.port))
    result = calibrate_rig(pairs, ChessboardSpec(board["cols"], board["rows"],
                                                 board["square_size"]))
    assert result.ok, result.warnings
    save_rig(result.rig, path)
    return path


@pytest.fixture(scope="module")
def calibrated_rig(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rig calibrated from 40 chessboard views of the default simulated camera."""
    directory = tmp_path_factory.mktemp("rig")
    scenario = default_sim_scenario()
    scenario["chessboard"]["n_views"] = 40
    return calibrate_rig_through_stub(scenario, directory / "stub", directory / "rig.json")


def sim_scenario(**faults: Any) -> dict[str, Any]:
    """The default `--robot sim` world, optionally with stub faults."""
    scenario = default_sim_scenario()
    if faults:
        scenario["faults"] = dict(faults)
    return scenario


def run_cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """`hostpc ARGS` in-process -> (exit code, stdout, stderr)."""
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_calibrate_sim_recovers_truth_and_verifies(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], calibrated_rig: Path
) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--poses", "60",
                                   "--verify-poses", "30", "--rig", str(calibrated_rig),
                                   "--out", str(out), "--json", "--no-report")
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["robot"]["sim"] is True and document["known"] == ["target"]
    # the truth comparison: every identifiable offset within 3 sigma and 0.01 deg
    truth = document["truth"]
    errors = truth["joint_offsets_error_deg"]
    joints = document["offsets"]["joints"]
    identified = [j for j, e in enumerate(errors) if e is not None]
    assert identified == [0, 1, 2, 3, 4]  # q6 is not separable from the camera mount
    for j in identified:
        sigma = joints[j]["sigma_deg"]
        assert abs(errors[j]) <= 0.01, (j, errors[j])
        assert abs(errors[j]) <= 3 * sigma, (j, errors[j], sigma)
    assert errors[5] is None and joints[5]["pushed"] is False
    assert "unidentifiable" in joints[5]["note"]
    # pushed: compensated offsets o + delta on the identified joints only
    assert document["push"]["status"] == "pushed"
    push = json.loads((out / "push.json").read_text())
    assert push["new_offsets"][5] == push["previous_offsets"][5]
    for j in identified:
        assert math.degrees(push["new_offsets"][j] - push["previous_offsets"][j]) == (
            pytest.approx(joints[j]["correction_deg"]))
    # verification on fresh poses after the push: the chi-square test at alpha 1 % passes
    verify = document["verify"]
    assert verify["n_measured"] == 30 and verify["passed"] is True
    assert verify["kind"] == "offsets" and verify["verdict"] == "PASS"
    assert verify["dof"] == 90 and verify["alpha"] == 0.01
    assert verify["p_value"] >= 0.01 and verify["rms_mm"] == verify["rms_after_mm"]
    assert verify["rms_before_mm"] > 10 * verify["rms_after_mm"]
    # files: dataset per the spec, fit, plan in run.json; verify poses are fresh
    dataset = load_dataset(out / "dataset.json")
    assert dataset.n_samples == 60 and dataset.method == "stereo_target"
    assert dataset.known == ("target",)
    fit_doc = json.loads((out / "fit.json").read_text())
    assert fit_doc["converged"] is True
    plan = json.loads((out / "run.json").read_text())["plan"]
    fit_q = np.asarray(plan["q"])
    verify_q = np.asarray(plan["q_verify"])
    distance = np.min(np.max(np.abs(fit_q[None] - verify_q[:, None]), axis=2), axis=1)
    assert np.all(distance > 1e-6)
    assert (out / "summary.txt").read_text().count("truth (simulation)") == 1
    assert "measure" in stderr  # progress on stderr, plain lines (not a TTY)
    # robot time from the simulator's clock: motion + 0.3 s settle + 0.1 s capture a pose
    robot_time = document["robot_time_s"]
    assert robot_time["clock"] == "controller" and robot_time["rig"] == 0.0  # rig given
    assert robot_time["measure"] > 60 * 0.4 and robot_time["verify"] > 30 * 0.4
    assert robot_time["total"] == pytest.approx(robot_time["measure"] + robot_time["verify"])
    assert "robot time: " in (out / "summary.txt").read_text()


@pytest.mark.slow
def test_readme_command_calibrates_the_rig_first(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc calibrate --robot sim` with every default: rig from chessboard captures,
    the fewest poses whose predicted joint offset sigma reaches 0.002 deg (a tour), push,
    4 verification poses, report; the text summary on stdout."""
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out))
    assert code == 0, stderr
    assert "rig calibrated" in stderr
    rig_report = json.loads((out / "rig_calibration.json").read_text())
    assert rig_report["ok"] and len(rig_report["used_views"]) >= 15
    # the planned views reach the check's 50 % coverage on this world: 20 captures (44 when
    # the plan asked for 55 %, 21 of the 24 extra adding no cell; docs/performance.md)
    plan = rig_report["plan"]
    assert len(plan["views_kept"]) + len(plan["views_rejected"]) <= 25
    assert min(plan["coverage"]) >= 0.5
    result = json.loads((out / "result.json").read_text())
    assert result["settings"]["target_sigma_deg"] == 0.002
    assert 3 <= result["plan"]["n_poses"] < 60 and result["acquisition"]["more_poses"] is None
    predicted = [s for s in result["plan"]["predicted_joint_sigma_deg"] if s is not None]
    assert len(predicted) == 5 and max(predicted) <= 0.002
    # every identifiable offset: its reported sigma within the target, its error within
    # 3 of them
    errors = result["truth"]["joint_offsets_error_deg"]
    joints = result["offsets"]["joints"]
    assert [j for j, e in enumerate(errors) if e is not None] == [0, 1, 2, 3, 4]
    for j in range(5):
        assert joints[j]["sigma_deg"] <= 0.002, (j, joints[j]["sigma_deg"])
        assert abs(errors[j]) <= 3 * joints[j]["sigma_deg"], (j, errors[j])
    assert result["verify"]["passed"] and result["push"]["status"] == "pushed"
    assert "PASS" in stdout and "truth (simulation)" in stdout
    assert "verify: 3 fresh poses: RMS before (old offsets) " in stdout
    assert result["robot_time_s"]["clock"] == "controller"
    assert "robot time: " in stdout
    # issue 17's target: every offset at <= 0.002 deg in <= 20 s of robot time (rig,
    # measurement and verification; 26.8-28.9 s while a plan measured >= 20 poses)
    assert result["robot_time_s"]["total"] <= 20.0, result["robot_time_s"]
    # the short plan's centres are re-corrected by its own preliminary fit's normals
    # (stereo_refinement; a plan under 20 poses was left as measured, which made its
    # sigma dishonest): the dataset's uv are not the journaled measurements
    records = [json.loads(line) for line in (out / "journal.jsonl").read_text().splitlines()]
    measured = [r["sample"]["uv"] for r in records
                if r.get("phase") == "fit" and r.get("sample")]
    refined = [s["uv"] for s in json.loads((out / "dataset.json").read_text())["samples"]]
    assert len(measured) == len(refined) == result["plan"]["n_poses"]
    moved = np.abs(np.asarray(refined) - np.asarray(measured))
    assert 1e-4 < float(np.max(moved)) < 0.1, float(np.max(moved))
    assert "simulated controller: nothing to roll back after the run" in stdout
    assert "hostpc rollback" not in stdout  # the simulator is gone after the run
    assert stdout.strip() == (out / "summary.txt").read_text().strip()
    if result["files"].get("report"):
        assert (out / "report.html").stat().st_size > 0


def test_rig_coverage_option_plans_more_views(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """`--rig-coverage 0.55` (the old target) plans views until both images are covered
    55 %: more captures than the default's 20 on this world (44), every kept view adding a
    cell beyond the 20 planned ones."""
    out = tmp_path / "run"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-coverage", "0.55", "--no-report", "--no-push")
    assert code == 0, stderr
    plan = json.loads((out / "rig_calibration.json").read_text())["plan"]
    assert min(plan["coverage"]) >= 0.55
    assert len(plan["views_kept"]) + len(plan["views_rejected"]) > 25
    assert json.loads((out / "run.json").read_text())["settings"]["options"][
        "rig_coverage"] == 0.55


@pytest.mark.slow
def test_all_six_offsets_with_a_measured_camera_mount_and_target(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A cell whose camera mount and target were both measured (no error on either, declared
    known): every one of the six offsets is identified, within 3 sigma and 0.01 deg.

    With the mount held, nothing absorbs a bias of the stereo rig any more: a rig calibrated
    from 40 rendered chessboards (principal point good to ~0.3 px) leaves chi2/dof ~15 and the
    push guard refuses, correctly. So this cell uses an exactly known rig; the default cell
    estimates the mount, which absorbs the rig's bias (test above)."""
    scenario = sim_scenario()
    scenario["camera"]["mount_error"] = {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}
    calibrated_rig = truth_rig_file(scenario, tmp_path / "rig.json")
    scenario_file = tmp_path / "measured_cell.json"
    scenario_file.write_text(json.dumps(scenario))
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario",
                                   str(scenario_file), "--known", "tool,target", "--poses", "60",
                                   "--rig", str(calibrated_rig), "--out", str(out), "--json",
                                   "--no-report")
    assert code == 0, stderr
    document = json.loads(stdout)
    errors = document["truth"]["joint_offsets_error_deg"]
    joints = document["offsets"]["joints"]
    assert all(e is not None for e in errors) and len(errors) == 6
    for j, error in enumerate(errors):
        assert abs(error) <= 0.01, (j, error)
        assert abs(error) <= 3 * joints[j]["sigma_deg"], (j, error, joints[j]["sigma_deg"])
        assert joints[j]["pushed"] is True
    assert document["verify"]["passed"] is True
