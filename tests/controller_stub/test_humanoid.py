"""The simulated humanoid: its own forward model, the stereo noise model, the controller
contract over the combined joint vector."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from controller_stub.errors import SimulationRefused
from controller_stub.geometry import make_transform
from controller_stub.scenario.spec import ScenarioError, scenario_from_dict
from controller_stub.sensors.dual_loop import StereoTriangulator
from controller_stub.world.humanoid import (
    CAMERA_NOMINAL,
    HOME,
    HumanoidSimulation,
    arm_model,
    head_model,
)
from controller_stub.world.robot_model import forward
from controller_stub.world.simulation import create_simulation


def dh(a: float, alpha: float, d: float, q: float) -> np.ndarray:
    """Standard DH transform, written out independently of both models."""
    ca, sa, cq, sq = math.cos(alpha), math.sin(alpha), math.cos(q), math.sin(q)
    return np.array([[cq, -sq * ca, sq * sa, a * cq], [sq, cq * ca, -cq * sa, a * sq],
                     [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])


HEAD_DH = [(0.0, math.pi / 2, 0.12), (0.06, 0.0, 0.0)]
ARM_DH = [(0.0, -math.pi / 2, 0.0), (0.0, math.pi / 2, 0.0), (0.0, math.pi / 2, 0.28),
          (0.0, -math.pi / 2, 0.0), (0.0, -math.pi / 2, 0.25), (0.0, math.pi / 2, 0.0),
          (0.0, 0.0, 0.10)]


@pytest.mark.parametrize("which", ["head", "left", "right"])
def test_urdf_tables_equal_the_dh_design(which: str) -> None:
    model = head_model() if which == "head" else arm_model(which)
    table = HEAD_DH if which == "head" else ARM_DH
    rng = np.random.default_rng(0)
    for q in rng.uniform(-2, 2, (5, len(table))):
        expected = np.eye(4)
        for (a, alpha, d), qi in zip(table, q, strict=True):
            expected = expected @ dh(a, alpha, d, qi)
        np.testing.assert_allclose(forward(model, q)[1][0], expected, atol=1e-12)


def test_triangulation_inverts_projection_and_its_covariance_is_right() -> None:
    stereo = StereoTriangulator(1400.0, 0.12, 1280, 1024, 0.15)
    p = np.array([0.05, -0.03, 0.5])
    point, _ = stereo.triangulate(stereo.project(p))
    np.testing.assert_allclose(point, p, atol=1e-14)
    rng = np.random.default_rng(1)
    draws = np.array([stereo.measure(p, rng)[0] for _ in range(4000)])
    _, cov, _ = stereo.measure(p, rng)
    empirical = np.cov(draws.T)
    np.testing.assert_allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(cov)), rtol=0.06)
    # depth noise far larger than lateral noise, x and z correlated
    assert np.sqrt(cov[2, 2]) > 5 * np.sqrt(cov[0, 0])
    assert abs(cov[0, 2]) > 0.05 * np.sqrt(cov[0, 0] * cov[2, 2])
    assert not stereo.visible(np.array([0.0, 0.0, -0.5]))
    assert not stereo.visible(np.array([1.0, 0.0, 0.5]))


@pytest.fixture()
def sim() -> HumanoidSimulation:
    return create_simulation(scenario_from_dict({"robot": "humanoid_upper", "seed": 3}))


def test_create_simulation_serves_the_humanoid(sim: HumanoidSimulation) -> None:
    assert isinstance(sim, HumanoidSimulation)
    assert sim.robot_name == "humanoid_upper" and sim.n_joints == 16
    np.testing.assert_allclose(sim.joint_positions(), HOME)
    lo, hi = sim.joint_limits()
    assert lo.shape == hi.shape == (16,)
    truth = json.loads(json.dumps(sim.truth()))
    assert truth["joint_order"][0] == "head.q1" and truth["joint_order"][-1] == "right.q7"
    assert np.all(np.abs(truth["zero_errors"]) <= math.radians(0.5))
    assert sim.camera_description()["T_headend_camera_nominal"]["xyz"] == \
        list(CAMERA_NOMINAL[0])
    with pytest.raises(SimulationRefused):
        sim.capture_stereo()
    with pytest.raises(SimulationRefused):
        sim.guarded_move(HOME, 0.5, 0)


def test_measure_targets_at_home_sees_both_targets(sim: HumanoidSimulation) -> None:
    q = HOME.copy()
    q[1] = -0.75  # tilt down to the hands
    moved = sim.move_joints(q, 1.0)
    assert sim.time == pytest.approx(moved.duration_s)  # the settling comes before a capture
    reading = sim.targets.measure_targets()
    assert reading["time"] == pytest.approx(moved.duration_s + 0.3)
    assert sim.time == pytest.approx(moved.duration_s + 0.4)
    assert set(reading["targets"]) == {"left", "right"}
    for side, seen in reading["targets"].items():
        truth = sim.target_in_camera(side)
        sigma = np.sqrt(np.diag(seen["cov"]))
        assert np.all(np.abs(seen["p"] - truth) < 5 * sigma)
        assert 0.3 < truth[2] < 0.8
    # looking away: nothing visible
    q[0] = 1.5
    sim.move_joints(q, 1.0)
    assert sim.targets.measure_targets()["targets"] == {}


def test_an_aborted_move_settles_before_the_next_capture(sim: HumanoidSimulation) -> None:
    """An abort decelerates the body: the capture after it waits settle_s, as after a
    completed move (the abort itself charges none)."""
    q = HOME.copy()
    q[1] = -0.75
    cut = sim.finish_move(sim.begin_move(q, 1.0), 0.5)
    assert not cut.completed and sim.time == pytest.approx(cut.duration_s)
    reading = sim.targets.measure_targets()
    assert reading["time"] == pytest.approx(cut.duration_s + 0.3)


def test_true_frames_compose_as_documented(sim: HumanoidSimulation) -> None:
    truth = sim.truth()
    q = sim.physical_angles()
    T_cam = make_transform(truth["camera"]["xyz"], truth["camera"]["rpy"])
    T_lb = make_transform(truth["left_base"]["xyz"], truth["left_base"]["rpy"])
    head_end = forward(head_model(), q[:2])[1][0]
    left_flange = forward(arm_model("left"), q[2:9])[1][0]
    p_hb = T_lb @ left_flange @ np.r_[truth["left_target"], 1.0]
    expected = np.linalg.solve(head_end @ T_cam, p_hb)[:3]
    np.testing.assert_allclose(sim.target_in_camera("left"), expected, atol=1e-12)


def test_zero_offsets_shift_the_reported_angles(sim: HumanoidSimulation) -> None:
    physical = sim.physical_angles()
    errors = sim.current_zero_errors()
    sim.set_zero_offsets(errors)  # the compensated offsets: now reported == physical
    np.testing.assert_allclose(sim.joint_positions(), physical)
    np.testing.assert_allclose(sim.current_zero_errors(), 0.0, atol=1e-15)
    sim.rollback(0)
    np.testing.assert_allclose(sim.current_zero_errors(), errors)
    with pytest.raises(SimulationRefused, match="offset"):
        sim.set_zero_offsets(np.full(16, 1.0))
    with pytest.raises(SimulationRefused, match="joint_limit|outside"):
        sim.move_joints(np.full(16, 3.1), 1.0)
    with pytest.raises(SimulationRefused):
        sim.move_joints(np.zeros(15), 1.0)


def test_scenario_checks_the_joint_count() -> None:
    with pytest.raises(ScenarioError, match="expected 16 values"):
        scenario_from_dict({"robot": "humanoid_upper", "truth": {"zero_errors": [0.0] * 6}})
