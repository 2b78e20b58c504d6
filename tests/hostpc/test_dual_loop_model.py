"""dual_loop: the kinematic tree, the measurement model and its analytic Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.dataset import dataset_from_dict, save_dataset
from hostpc.errors import InputError
from hostpc.fitting import solve
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.kinds.dual_loop.synthesize import synthesize_dual_loop
from hostpc.kinematics import forward, get_robot
from hostpc.kinematics.humanoid import HUMANOID_HOME, get_tree, humanoid_upper, tree_names
from hostpc.kinematics.tree import Branch, KinematicTree, tree_gravity_torque
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.test_measurement_jacobians import (
    assert_jacobian_close,
    central_difference,
    random_parameters,
)

ALL_DUAL = ["joint_offsets", "camera", "left_base", "right_base", "left_target",
            "right_target", "geometry", "joint_compliance", "encoder_scale",
            "transmission_harmonic", "backlash", "depth_scale"]


@pytest.fixture(scope="module")
def poses():  # type: ignore[no-untyped-def]
    return plan_poses(12, np.random.default_rng(4))


def _home() -> np.ndarray:
    return np.concatenate([HUMANOID_HOME[b] for b in ("head", "left", "right")])[None, :]


def test_tree_layout() -> None:
    tree = humanoid_upper()
    assert tree_names() == ["humanoid_upper"]
    assert tree.names == ("head", "left", "right")
    assert tree.n == 16
    assert tree.joint_labels[:3] == ("head.q1", "head.q2", "left.q1")
    assert tree.joint_slice("right") == slice(9, 16)
    stacked = tree.stacked_chain()
    assert stacked.n == 16 and stacked.mass is None
    # the stacked kinematic vector maps back onto each branch's own vector
    for b in tree.branches:
        np.testing.assert_array_equal(stacked.kin_vector()[tree.kin_indices(b.name)],
                                      b.chain.kin_vector())
    with pytest.raises(InputError, match="kinematic tree"):
        get_robot("humanoid_upper")
    with pytest.raises(InputError, match="no chain 'torso'"):
        tree.branch("torso")


def test_tree_rejects_bad_structure() -> None:
    head = humanoid_upper().branch("head").chain
    with pytest.raises(InputError, match="must come before"):
        KinematicTree("bad", (Branch("head", head), Branch("arm", head, parent="nope")))
    with pytest.raises(InputError, match="listed twice"):
        KinematicTree("bad", (Branch("head", head), Branch("head", head, parent="head")))


def test_root_transforms_compose_the_mounts() -> None:
    tree = humanoid_upper()
    q = _home()
    frames = tree.root_transforms(q)
    left = tree.branch("left")
    T_lb_lf = forward(left.chain, q[:, tree.joint_slice("left")]).T_base_flange[0]
    np.testing.assert_allclose(frames["left"][0][0], left.T_parent_base)
    np.testing.assert_allclose(frames["left"][1][0], left.T_parent_base @ T_lb_lf)
    head_end = forward(tree.branch("head").chain, q[:, :2]).T_base_flange[0]
    np.testing.assert_allclose(frames["head"][1][0], head_end)


def test_tree_gravity_matches_numeric_potential_energy() -> None:
    """tau_i = -dV/dq_i with V = -sum m_j g . c_j (all point masses at link origins)."""
    tree = humanoid_upper()
    q = _home() + np.random.default_rng(1).uniform(-0.3, 0.3, (1, 16))
    g = np.array([0.0, 0.0, -9.81])

    def energy(qq: np.ndarray) -> float:
        total = 0.0
        for b in tree.branches:
            T_root_base = tree.root_transforms(qq)[b.name][0][0]
            links = forward(b.chain, qq[:, tree.joint_slice(b.name)]).T_base_link[0, 1:]
            for m, T in zip(b.chain.mass, links, strict=True):  # type: ignore[arg-type]
                total -= m * g @ (T_root_base @ T)[:3, 3]
        return total

    tau = tree_gravity_torque(tree, q)[0]
    for j in range(16):
        dq = np.zeros((1, 16))
        dq[0, j] = 1e-6
        numeric = -(energy(q + dq) - energy(q - dq)) / 2e-6
        assert tau[j] == pytest.approx(numeric, abs=1e-6)


def test_nominal_prediction_matches_tree_forward_kinematics(poses) -> None:  # type: ignore[no-untyped-def]
    dataset = synthesize_dual_loop({}, poses, noise_scale=0.0)
    tree = get_tree("humanoid_upper")
    q = np.zeros((poses.n, 16))
    q[:, :2] = poses.q_head
    for i, side in enumerate(poses.chain):
        q[i, tree.joint_slice(str(side))] = poses.q_arm[i]
    frames = tree.root_transforms(q)
    T_hb_cam = frames["head"][1] @ tree.frames["camera"]
    for i, side in enumerate(poses.chain):
        p = frames[side][1][i] @ np.r_[tree.frames[f"{side}_target"], 1.0]
        expected = np.linalg.solve(T_hb_cam[i], p)[:3]
        np.testing.assert_allclose(dataset.samples.p[i], expected, atol=1e-12)
    assert np.all(dataset.samples.p[:, 2] > 0.25)


@pytest.mark.parametrize("seed", [0, 1])
def test_dual_loop_jacobian_matches_central_differences(poses, seed: int) -> None:  # type: ignore[no-untyped-def]
    dataset = synthesize_dual_loop({}, poses, noise_scale=0.0)
    problem = build_problem(dataset, ALL_DUAL)
    x = random_parameters(problem, np.random.default_rng(seed))
    _, analytic = predict(problem, x)
    numeric = central_difference(problem, x)
    assert_jacobian_close(problem, analytic, numeric)


def test_unobserved_arm_has_zero_derivative(poses) -> None:  # type: ignore[no-untyped-def]
    problem = build_problem(synthesize_dual_loop({}, poses, noise_scale=0.0), ALL_DUAL)
    _, J = predict(problem, np.zeros(problem.layout.size))
    assert J is not None
    chain = problem.dataset.samples.chain
    for k, name in enumerate(problem.layout.names):
        for side, other in (("left", "right"), ("right", "left")):
            if f".{other}." in name or name.startswith(f"{other}_"):
                assert np.all(J[chain == side, :, k] == 0.0), name


def test_recovers_a_synthetic_truth_and_names_the_null_directions(poses) -> None:  # type: ignore[no-untyped-def]
    truth = {"joint_offsets.left.q3": 0.004, "joint_offsets.right.q5": -0.003,
             "camera.z": 0.002, "left_base.y": -0.0015, "right_target.z": 0.001}
    dataset = synthesize_dual_loop(truth, poses, noise_scale=0.0)
    result = solve(build_problem(dataset), cv_folds=0)
    fixed = {d.fixed for d in result.unidentifiable}
    assert fixed == {f"joint_offsets.{j}" for j in
                     ("head.q1", "head.q2", "left.q1", "left.q7", "right.q1", "right.q7")}
    for name, value in truth.items():
        assert result.value(name) == pytest.approx(value, abs=1e-9)
    assert result.rms < 1e-9


def test_dataset_file_round_trip_and_validation(poses, tmp_path) -> None:  # type: ignore[no-untyped-def]
    dataset = synthesize_dual_loop({}, poses)
    path = tmp_path / "dual.json"
    save_dataset(dataset, path)
    from hostpc.dataset import load_dataset

    loaded = load_dataset(path)
    problem = build_problem(loaded)
    assert problem.context.joint_labels[0] == "head.q1"
    assert "left.q3" in problem.context.variables and "depth" in problem.context.variables
    short = {"format": "zerocal-dataset/1", "method": "dual_loop",
             "robot": {"name": "humanoid_upper"},
             "frames": {"camera": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
                        "left_base": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
                        "right_base": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
                        "left_target": [0, 0, 0], "right_target": [0, 0, 0]},
             "samples": [{"chain": "left", "q_head": [0, 0], "q_arm": [0] * 6,
                          "p": [0, 0, 0.5], "sigma": 1e-4}]}
    with pytest.raises(InputError, match=r"samples\[0\].q_arm: 6 angles"):
        build_problem(dataset_from_dict(short))
