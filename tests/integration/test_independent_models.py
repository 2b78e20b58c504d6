"""hostpc's DH measurement model against the simulated controller's own, independent
URDF-style model: the target seen from the true camera pose must be exactly what hostpc
predicts with the true parameters, for every built-in robot. A kinematics bug on either side
cannot cancel out here."""

from __future__ import annotations

import numpy as np
import pytest

from controller_stub.scenario.spec import default_scenario
from controller_stub.world.simulation import Simulation
from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem


@pytest.mark.parametrize("robot", ["ur5e", "ur10e", "industrial6"])
def test_stub_and_host_agree_on_the_measurement(robot: str) -> None:
    scenario = default_scenario().model_copy(update={"robot": robot, "seed": 4})
    sim = Simulation(scenario)
    lower, upper = sim.joint_limits()
    rng = np.random.default_rng(4)
    q_reported, expected = [], []
    for _ in range(12):
        q = np.clip(rng.uniform(-2.5, 2.5, sim.n_joints), lower + 0.1, upper - 0.1)
        assert sim.move_joints(q, 1.0).completed
        q_reported.append(sim.joint_positions())
        T_base_camera = sim.camera_pose()
        target = np.append(sim.stereo.target_centre, 1.0)
        expected.append((np.linalg.inv(T_base_camera) @ target)[:3])
    truth = sim.truth()
    mount = truth["camera"]["T_flange_camera"]
    n = sim.n_joints
    dataset = Dataset(
        method="stereo_target", robot=RobotDescription(name=robot),
        frames={"tool": FramePose(np.array(mount["xyz"]), np.array(mount["rpy"])),
                "target": np.asarray(sim.stereo.target_centre)},
        samples=Samples(q=np.array(q_reported), p=np.zeros((12, 3)),
                        cov=np.broadcast_to(np.eye(3) * 1e-8, (12, 3, 3))),
        known=("tool", "target"),
    )
    problem = build_problem(dataset, ["joint_offsets"])
    x = np.array([truth["zero_errors"][i] for i in range(n)])
    predicted, _ = predict(problem, x, jacobian=False)
    np.testing.assert_allclose(predicted, np.array(expected), atol=1e-10)
    # and the zero errors matter: without them the prediction is off by millimetres
    nominal, _ = predict(problem, np.zeros(n), jacobian=False)
    assert np.max(np.abs(nominal - np.array(expected))) > 1e-4
