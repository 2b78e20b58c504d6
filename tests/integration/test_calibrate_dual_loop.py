"""`hostpc calibrate --method dual_loop`: the humanoid's head camera calibrates both arms.

Against the simulated humanoid (`controller_stub.world.humanoid`) over real loopback sockets: the
`measure_targets` message, the whole run (`--robot sim`) compared with the stub's hidden
truth in the fit's gauge (`hostpc.fitting.stepwise.gauge_equivalent`), the held offsets, push
and verify, `hostpc fit` / `hostpc diagnose` on the produced dataset, and a run cut by a
dropped link and resumed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.bench_dual_loop import truth_vector as bench_truth_vector
from hostpc.dataset import load_dataset
from hostpc.errors import InputError
from hostpc.fitting.stepwise import gauge_equivalent
from hostpc.kinds.dual_loop.method import DualLoopMethod
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.methods.base import NullProgress, RunSettings
from hostpc.methods.cell import build_cell
from hostpc.model.layout import Problem
from hostpc.model.problem import build_problem
from hostpc.planning.robot_time import TimeLimits
from hostpc.planning.verify_poses import verify_poses_for_power
from hostpc.robots.simulator import SimulatedController, default_sim_scenario, sim_default_known
from hostpc.robots.zerocal import ZerocalAdapter
from hostpc.transport import ControllerClient, ControllerRefusedError
from protocol import messages as m
from protocol.measurement_messages import TargetsMeasured
from tests.integration.conftest import TOKEN, StartStub
from tests.integration.test_calibrate_sim import run_cli

SIM_TOKEN = "zerocal-sim"
HELD = ("head.q1", "head.q2", "left.q1", "left.q7", "right.q1", "right.q7")
"""The offsets the data cannot separate from the frames (docs/dual-loop.md)."""
LABELS = ("head.q1", "head.q2", *(f"left.q{j}" for j in range(1, 8)),
          *(f"right.q{j}" for j in range(1, 8)))


def left_pose() -> np.ndarray:
    """(16,) a combined pose with the head aimed at the left target (nominal model)."""
    poses = plan_poses(1, np.random.default_rng(4))
    q = np.array([0.0, -0.45, 0.1, 0.05, 0.1, -1.45, 0.0, 0.8, 0.0,
                  -0.1, 0.05, -0.1, -1.45, 0.0, 0.8, 0.0])
    q[0:2] = poses.q_head[0]
    q[2:9] = poses.q_arm[0]
    return q


# ------------------------------------------------------------------ the message


async def test_measure_targets_over_loopback(start_stub: StartStub) -> None:
    server = await start_stub({"robot": "humanoid_upper"})
    host, port = server.address
    q = left_pose()
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
        at_home = await client.measure_targets()
        assert at_home.q.shape == (16,) and {t.chain for t in at_home.targets} <= {"left",
                                                                                 "right"}
        await client.move_joints(q, 1.0)
        seen = await client.measure_targets()
    np.testing.assert_allclose(seen.q, q, atol=1e-12)
    chains = [t.chain for t in seen.targets]
    assert "left" in chains and len(set(chains)) == len(chains)  # the aimed one, maybe both
    for target in seen.targets:
        truth = server.sim.target_in_camera(target.chain)
        assert target.p.shape == (3,) and target.cov.shape == (3, 3)
        np.testing.assert_allclose(target.cov, target.cov.T, atol=0.0)
        assert np.all(np.linalg.eigvalsh(target.cov) > 0)
        # the noise is the stated one: within 5 sigma of the truth in the whitened metric
        error = target.p - truth
        assert float(error @ np.linalg.solve(target.cov, error)) < 25.0
    # the adapter passes it through
    adapter = await ZerocalAdapter.connect(host, port, token=TOKEN)
    try:
        measured = await adapter.measure_targets()
        assert [t.chain for t in measured.targets] == chains
        assert measured.q.shape == (16,)
    finally:
        await adapter.close()


async def test_state_reports_the_joint_speeds_the_plan_times_with(start_stub: StartStub
                                                                 ) -> None:
    """The controller reports each joint's top speed (the humanoid's arms 2 rad/s, its
    head 3 rad/s, slower than the UR's 180 deg/s the host assumed before): the plan's
    robot time is predicted with them."""
    server = await start_stub({"robot": "humanoid_upper"})
    adapter = await ZerocalAdapter.connect(*server.address, token=TOKEN)
    try:
        state = await adapter.state()
    finally:
        await adapter.close()
    speeds = np.asarray(state.extra["max_joint_speed"], float)
    np.testing.assert_array_equal(speeds, server.sim.max_joint_speed())
    np.testing.assert_array_equal(speeds, [3.0, 3.0] + [2.0] * 14)
    limits = TimeLimits.from_extra(state.extra, 16)
    np.testing.assert_array_equal(limits.joint_speed, speeds)


async def test_measure_targets_needs_auth_and_a_target_sensor(start_stub: StartStub) -> None:
    humanoid = await start_stub({"robot": "humanoid_upper"})
    async with ControllerClient.connect(*humanoid.address, token=None, timeout=5.0) as client:
        with pytest.raises(ControllerRefusedError) as refused:
            await client.measure_targets()
        assert refused.value.code == "auth_required"
    ur = await start_stub()
    async with ControllerClient.connect(*ur.address, token=TOKEN, timeout=5.0) as client:
        with pytest.raises(ControllerRefusedError) as refused:
            await client.measure_targets()
        assert refused.value.code == "refused" and refused.value.reason == "unsupported"


def test_targets_measured_message_is_strict() -> None:
    good = {"kind": "targets_measured", "reply_to": 3, "q": [0.0] * 16, "time": 1.0,
            "targets": [{"chain": "left", "p": [0.0, 0.1, 0.5],
                         "cov": [[1e-8, 0, 0], [0, 1e-8, 0], [0, 0, 1e-7]]}]}
    message = m.MESSAGE_ADAPTER.validate_python(good)
    assert isinstance(message, TargetsMeasured)
    assert m.REPLY_KIND["measure_targets"] == "targets_measured"
    for broken in (
        {**good, "targets": [{**good["targets"][0], "cov": [[1e-8, 0, 0], [0, 1e-8, 0]]}]},
        {**good, "targets": [{**good["targets"][0], "p": [0.0, float("nan"), 0.5]}]},
        {**good, "targets": [{**good["targets"][0], "colour": "red"}]},
    ):
        with pytest.raises(ValueError):
            m.MESSAGE_ADAPTER.validate_python(broken)


# ------------------------------------------------------------------ the method's set-up


def test_sim_world_of_dual_loop_is_the_humanoid() -> None:
    scenario = default_sim_scenario(time_scale=0.0, method="dual_loop")
    assert scenario["robot"] == "humanoid_upper" and scenario["motion"]["time_scale"] == 0.0
    assert sim_default_known("dual_loop") == ()
    assert default_sim_scenario()["robot"] == "ur5e" and sim_default_known() == ("target",)


async def test_method_refuses_a_robot_without_target_measurement(tmp_path: Path) -> None:
    cell = build_cell({}, "humanoid_upper")
    method = DualLoopMethod(RunSettings(method="dual_loop"), cell, tmp_path)
    with pytest.raises(InputError, match="measure_targets"):
        await method.prepare(object(), NullProgress())  # type: ignore[arg-type]
    with pytest.raises(InputError, match="not a dual_loop frame"):
        DualLoopMethod(RunSettings(method="dual_loop"),
                       build_cell({}, "humanoid_upper", known=("target",)), tmp_path)


# ------------------------------------------------------------------ end to end


def truth_vector(truth: Mapping[str, Any], problem: Problem) -> np.ndarray:
    """The stub's truth file as parameters on `problem`'s layout, zero errors against the
    offsets at the start of the run (the run pushed since)."""
    return bench_truth_vector(truth, problem, zero_errors="zero_errors_initial")


def test_default_dual_loop_pose_measures_both_arms(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """The default plan's every pose moves both arms and the head aims between their
    targets: one move, one settle and one capture measure both (two samples, left then
    right, one q_head and one time). Before, each pose aimed at one arm with the other at
    home: 16 of 48 poses saw both targets. The world's hidden frame errors may move a
    target out of an image at a pose the nominal model sees it in: at most 1 in 20."""
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--method",
                                   "dual_loop", "--out", str(out), "--no-push", "--json")
    assert code == 0, stderr
    plan = json.loads(stdout)["plan"]
    header = json.loads((out / "run.json").read_text())
    method = DualLoopMethod(RunSettings(method="dual_loop"),
                            build_cell(header["initial"]["camera"], "humanoid_upper"), tmp_path)
    points = method.camera_points(np.vstack([header["plan"]["q"], header["plan"]["q_verify"]]))
    assert all(np.all(method.visible(points[side])) for side in ("left", "right"))
    samples = json.loads((out / "dataset.json").read_text())["samples"]
    poses: dict[float, list[dict[str, Any]]] = {}  # one capture: one time
    for sample in samples:
        poses.setdefault(sample["t"], []).append(sample)
    assert len(poses) >= plan["n_poses"]
    both = [pose for pose in poses.values() if len(pose) == 2]
    assert len(both) >= 0.95 * len(poses)
    for pose in both:
        assert [s["chain"] for s in pose] == ["left", "right"]
        assert pose[0]["q_head"] == pose[1]["q_head"]


@pytest.mark.slow
def test_calibrate_sim_dual_loop_recovers_truth_pushes_and_verifies(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--method",
                                   "dual_loop", "--out", str(out), "--json")
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["method"] == "dual_loop" and document["robot"]["sim"] is True
    assert document["robot"]["name"] == "humanoid_upper" and document["known"] == []
    joints = document["offsets"]["joints"]
    assert len(joints) == 16

    # the truth in the fit's gauge: identifiable offsets within 3 sigma, frames within 4
    dataset = load_dataset(out / "dataset.json")
    assert dataset.method == "dual_loop" and dataset.n_samples >= 60
    assert set(dataset.samples.chain) == {"left", "right"}  # type: ignore[arg-type]
    # the head camera's calibration is in the dataset, with no pixel floor by default
    # (measured unnecessary for dual_loop: docs/vision.md 3.3), and the push tested the
    # chi2 with the calibration's covariance inside
    block = dataset.extra_fields["rig_uncertainty"]
    assert "pixel_floor_px" not in block
    assert document["method_setup"]["dual_loop"]["pixel_floor"] == 0.0
    assert document["fit"]["chi2_dof_with_calibration"] is not None
    problem = build_problem(dataset)
    fit_doc = json.loads((out / "fit.json").read_text())
    parameters = fit_doc["parameters"]
    assert list(parameters) == list(problem.layout.names)
    fixed = np.array([parameters[n]["fixed"] for n in problem.layout.names])
    x_fit = np.array([parameters[n]["value"] for n in problem.layout.names])
    truth = json.loads((out / "sim" / "truth.json").read_text())
    x_ref = gauge_equivalent(problem, truth_vector(truth, problem), fixed)
    held = {f"joint_offsets.{label}" for label in HELD}
    assert {n for n, f in zip(problem.layout.names, fixed, strict=True) if f} == held
    for k, name in enumerate(problem.layout.names):
        if fixed[k]:
            continue
        sigma = parameters[name]["std"]
        limit = 3.0 if name.startswith("joint_offsets.") else 4.0
        assert abs(x_fit[k] - x_ref[k]) <= limit * sigma, (name, x_fit[k], x_ref[k], sigma)

    # the result document: the same errors for the identified offsets, none for the held
    errors = document["truth"]["joint_offsets_error_deg"]
    for j, label in enumerate(LABELS):
        if label in HELD:
            assert errors[j] is None and joints[j]["pushed"] is False
            assert "unidentifiable" in joints[j]["note"]
        else:
            assert errors[j] is not None and joints[j]["pushed"] is True
            assert abs(errors[j]) <= 3 * joints[j]["sigma_deg"], (label, errors[j])
    described = " ".join(document["fit"]["unidentifiable"])
    for label in HELD:
        assert f"joint_offsets.{label}" in described

    # pushed: o + delta on the identified joints only; the controller now reads true angles
    assert document["push"]["status"] == "pushed"
    push = json.loads((out / "push.json").read_text())
    for j, label in enumerate(LABELS):
        change = push["new_offsets"][j] - push["previous_offsets"][j]
        if label in HELD:
            assert change == 0.0
        else:
            assert math.degrees(change) == pytest.approx(joints[j]["correction_deg"])
            remaining = math.degrees(truth["zero_errors"][j])  # truth after the push
            assert abs(remaining) <= 3 * joints[j]["sigma_deg"], (label, remaining)

    verify = document["verify"]
    # the default plan: the fewest poses that reach the kind's target sigma, the
    # verification poses its power needs; robot time as planned (the controller's speeds)
    plan = document["plan"]
    assert plan["target_sigma_deg"] == DualLoopMethod.default_target_sigma_deg
    assert all(s is None or s <= plan["target_sigma_deg"]
               for s in plan["predicted_joint_sigma_deg"])
    assert plan["n_verify"] == verify_poses_for_power()
    spent = document["robot_time_s"]
    assert spent["measure"] + spent["verify"] == pytest.approx(
        plan["predicted_robot_time_s"]["total"], rel=0.01)
    assert verify["passed"] is True and verify["n_measured"] >= plan["n_verify"]
    assert verify["verdict"] == "PASS" and verify["p_value"] >= verify["alpha"]
    # the summary names the joints as the model does
    summary = (out / "summary.txt").read_text()
    table = summary.split("\n\n")[1].splitlines()
    assert [line.split()[0] for line in table[1:]] == list(LABELS)
    assert "J16" not in summary and "pushed zero offsets: left.q2 " in stderr
    assert verify["rms_before_mm"] > 4 * verify["rms_after_mm"]

    # the produced dataset goes through `hostpc fit` and `hostpc diagnose` offline
    code, fit_out, fit_err = run_cli(capsys, "fit", "--json", "--cv-folds", "0",
                                     str(out / "dataset.json"))
    assert code == 0, fit_err
    refit = json.loads(fit_out)
    assert refit["method"] == "dual_loop" and refit["converged"] is True
    for name in problem.layout.names:
        assert refit["parameters"][name]["value"] == pytest.approx(
            parameters[name]["value"], abs=1e-9)
    code, diag_out, diag_err = run_cli(capsys, "diagnose", "--cv-folds", "2",
                                       str(out / "dataset.json"))
    assert code in (0, 1), diag_err  # 0 adequate, 1 not: both a verdict
    assert "method dual_loop" in diag_out and "verdict:" in diag_out


# ------------------------------------------------------------------ resume

RESUME_POSES = 12
# requests: get_state, get_offsets, the robot-time clock reading after the rig, then
# (move_joints, measure_targets, clock reading) per pose: index 3 + 3k is the move to pose
# k; the drop makes that move fail (not executed, not re-sent)
DROP_AT_POSE = 5
DROP_INDEX = 3 + 3 * DROP_AT_POSE


def _calibrate(capsys: pytest.CaptureFixture[str], sim: SimulatedController,
               out: Path) -> tuple[int, str, str]:
    address = f"{sim.address.host}:{sim.address.port}"
    return run_cli(capsys, "calibrate", "--robot", address, "--token", SIM_TOKEN,
                   "--method", "dual_loop", "--poses", str(RESUME_POSES), "--verify-poses",
                   "4", "--candidates", "400", "--seed", "5", "--no-push", "--no-report",
                   "--cv-folds", "0", "--out", str(out))


@pytest.mark.slow
def test_dual_loop_run_cut_and_resumed_equals_uncut_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    faulty = default_sim_scenario(method="dual_loop")
    faulty["faults"] = {"drop_after_requests": DROP_INDEX}
    cut = tmp_path / "cut"
    with SimulatedController(faulty, tmp_path / "stub-cut") as sim:
        code, _, stderr = _calibrate(capsys, sim, cut)
        assert code == 3, stderr
        last = stderr.strip().splitlines()[-1]
        assert "not re-sent" in last and f"--resume {cut}" in last
        events = [json.loads(line)["event"]
                  for line in (cut / "journal.jsonl").read_text().splitlines()]
        assert events == ["sample", "robot_time"] * DROP_AT_POSE  # each pose, its time
        code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(cut))
        assert code == 0, stderr
        assert "resuming" in stderr
    uncut = tmp_path / "uncut"
    with SimulatedController(default_sim_scenario(method="dual_loop"),
                             tmp_path / "stub-uncut") as sim:
        code, _, stderr = _calibrate(capsys, sim, uncut)
        assert code == 0, stderr
    resumed = json.loads((cut / "dataset.json").read_text())["samples"]
    whole = json.loads((uncut / "dataset.json").read_text())["samples"]
    assert len(resumed) == len(whole) >= RESUME_POSES
    for index, (a, b) in enumerate(zip(resumed, whole, strict=True)):
        assert a == b, f"sample {index} differs"
    journal = [json.loads(line) for line in (cut / "journal.jsonl").read_text().splitlines()]
    keys = [(r["phase"], r["index"]) for r in journal if r["event"] == "sample"]
    assert len(keys) == len(set(keys)) == RESUME_POSES + 4
    assert json.loads((cut / "run.json").read_text())["plan"] == json.loads(
        (uncut / "run.json").read_text())["plan"]
    verify = json.loads((cut / "result.json").read_text())["verify"]
    assert verify["kind"] == "model_check"  # --no-push: the model on fresh poses
    assert verify["rms_after_mm"] < 0.5 * verify["rms_before_mm"]
    assert "model check on fresh poses (nothing pushed)" in (cut / "summary.txt").read_text()
