"""world_point with the simulated laser tracker over real loopback sockets: the
`measure_tracker` message, the method's planning and acquisition against the stub's truth,
and (once the world_point measurement model is registered) `hostpc calibrate --robot sim
--method world_point` end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.kinds.world_point.method import WorldPointMethod, identifiable_offsets
from hostpc.methods.base import NullProgress, RunSettings
from hostpc.methods.cell import build_cell
from hostpc.planning.verify_poses import verify_poses_for_power
from hostpc.robots.zerocal import ZerocalAdapter
from hostpc.transport import ControllerClient
from tests.integration.conftest import TOKEN, StartStub
from tests.integration.test_calibrate_sim import run_cli

TRACKER = {"tracker": {"reflectors": {"smr1": {"position": [0.03, -0.02, 0.06]},
                                      "smr2": {"position": [-0.04, 0.03, 0.05],
                                               "axis": [0.0, 0.6, 0.8]}}}}


def _true_point(server, name: str) -> np.ndarray:
    sim = server.sim
    T = sim.tracker.T_world_base @ sim.flange_pose()
    return T[:3, :3] @ sim.tracker.reflector_true(name) + T[:3, 3]


async def test_measure_tracker_over_loopback(start_stub: StartStub) -> None:
    server = await start_stub(TRACKER)
    host, port = server.address
    rng = np.random.default_rng(3)
    seen_names: set[str] = set()
    lost_any = False
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
        for _ in range(25):
            q = rng.uniform(-2.5, 2.5, size=6)
            await client.move_joints(q, 1.0)
            reading = await client.measure_tracker()
            np.testing.assert_allclose(reading.q, q, atol=1e-12)
            assert set(reading.points) | set(reading.lost) == {"smr1", "smr2"}
            lost_any |= bool(reading.lost)
            for name, (p, cov) in reading.points.items():
                seen_names.add(name)
                error = p - _true_point(server, name)
                assert float(error @ np.linalg.solve(cov, error)) < 25.0  # within 5 sigma
    assert seen_names == {"smr1", "smr2"} and lost_any
    assert reading.description["reflectors"]["smr2"] == [-0.04, 0.03, 0.05]


def test_identifiability_depends_on_what_is_known() -> None:
    assert identifiable_offsets(6, ("world", "markers")) == ([1, 2, 3, 4, 5, 6], [])
    joints, notes = identifiable_offsets(6, ("markers",))
    assert joints == [2, 3, 4, 5, 6] and "joint 1" in notes[0] and "world" in notes[0]
    joints, notes = identifiable_offsets(6, ())
    assert joints == [2, 3, 4, 5] and "joint 6" in notes[1] and "nest" in notes[1]


async def test_method_plans_visible_poses_and_acquires(start_stub: StartStub,
                                                       tmp_path: Path) -> None:
    server = await start_stub(TRACKER)
    host, port = server.address
    robot = await ZerocalAdapter.connect(host, port, token=TOKEN)
    try:
        state = await robot.state()
        cell = build_cell(state.camera, state.robot, None, ("world", "markers"))
        method = WorldPointMethod(RunSettings(method="world_point", n_candidates=200),
                                  cell, tmp_path)
        await method.prepare(robot, NullProgress())
        assert (tmp_path / "tracker.json").is_file()
        pool = method.candidates(state, np.random.default_rng(0))
        assert pool.shape == (200, 6)
        skipped = 0
        for index, q in enumerate(pool[:12]):
            record = await method.acquire(robot, "fit", index, q, None)
            if not record.ok:  # the true robot differs a little from the nominal one
                assert record.reason is not None and "beam lost" in record.reason
                skipped += 1
                continue
            sample = record.sample
            assert sample is not None and sample["marker"] in ("smr1", "smr2")
            p = np.asarray(sample["p"])
            cov = np.asarray(sample["cov"])
            error = p - _true_point(server, sample["marker"])
            assert float(error @ np.linalg.solve(cov, error)) < 25.0
        assert skipped <= 1  # candidates keep a 10 deg margin inside the cone
        document = method.dataset_document([])
        assert document["known"] == ["world", "markers"]
        assert set(document["frames"]["markers"]) == {"smr1", "smr2"}
    finally:
        await robot.close()


def _world_point_registered() -> bool:
    from hostpc.dataset.kind_registry import measurement_kinds

    return "world_point" in measurement_kinds()


@pytest.mark.slow
@pytest.mark.skipif(not _world_point_registered(),
                    reason="needs the world_point measurement model")
def test_calibrate_sim_world_point_recovers_every_offset(tmp_path, capsys) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--method",
                                   "world_point", "--poses", "40", "--verify-poses", "10",
                                   "--out", str(out), "--json", "--no-report")
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["known"] == ["world", "markers"]
    errors = document["truth"]["joint_offsets_error_deg"]
    assert all(e is not None and abs(e) <= 0.005 for e in errors), errors
    assert document["push"]["status"] == "pushed"
    assert document["verify"]["passed"] is True
    assert "offsets defined for joints 1, 2, 3, 4, 5, 6" in stderr
    # without the nest: joint 6 is not defined, and the output says why
    out2 = tmp_path / "run2"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--method",
                                   "world_point", "--known", "world", "--poses", "40",
                                   "--verify-poses", "10", "--out", str(out2), "--json",
                                   "--no-report")
    assert code == 0, stderr
    errors = json.loads(stdout)["truth"]["joint_offsets_error_deg"]
    assert errors[5] is None and all(abs(e) <= 0.005 for e in errors[:5])
    assert "joint 6's zero needs a reflector known in the flange frame" in stderr
    assert math.isfinite(errors[0])


@pytest.mark.slow
@pytest.mark.skipif(not _world_point_registered(),
                    reason="needs the world_point measurement model")
def test_default_sim_world_point_plans_to_the_target_sigma_in_the_planned_time(
        tmp_path, capsys) -> None:
    """Without --poses the plan stops at the kind's default target sigma (the fewest
    travel-aware poses that reach it, far fewer than the fixed 60), with the verification
    poses its power needs; the robot time spent is the one planned (each tracker reading
    costs a capture); the offsets stay within 3 of their sigmas."""
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--method",
                                   "world_point", "--out", str(out), "--json", "--no-report")
    assert code == 0, stderr
    document = json.loads(stdout)
    plan = document["plan"]
    assert plan["target_sigma_deg"] == WorldPointMethod.default_target_sigma_deg
    assert plan["n_poses"] < 60 and plan["n_verify"] == verify_poses_for_power()
    assert max(plan["predicted_joint_sigma_deg"]) <= plan["target_sigma_deg"]
    spent = document["robot_time_s"]
    assert spent["measure"] + spent["verify"] == pytest.approx(
        plan["predicted_robot_time_s"]["total"], rel=0.01)
    joints = document["offsets"]["joints"]
    errors = document["truth"]["joint_offsets_error_deg"]
    assert all(abs(e) <= 3 * j["sigma_deg"] for e, j in zip(errors, joints, strict=True))
    assert document["verify"]["passed"] is True
