"""What problem builds share (issue 17): the theta-only screws equal those rows of all 5n;
the chain, gravity torques and whitening are computed once per dataset, read-only, and
never handed to another dataset."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hostpc.kinematics import forward, get_robot, joint_screws, screws
from hostpc.model.problem import build_problem
from hostpc.synthesize import random_truth, synthesize_stereo_target


@pytest.mark.parametrize("name", ["ur5e", "industrial6"])
def test_joint_screws_are_the_theta_rows_of_all_screws(name: str) -> None:
    chain = get_robot(name)
    q = np.random.default_rng(1).uniform(-2.0, 2.0, (7, chain.n))
    poses = forward(chain, q)
    full, joints = screws(chain, poses), joint_screws(chain, poses)
    n = chain.n
    np.testing.assert_array_equal(joints.axis, full.axis[:, :n])
    np.testing.assert_array_equal(joints.point, full.point[:, :n])
    np.testing.assert_array_equal(joints.is_rotation, full.is_rotation[:n])


def test_joint_screws_of_a_prismatic_joint_translate() -> None:
    ur5e = get_robot("ur5e")
    prismatic = np.zeros(ur5e.n, dtype=bool)
    prismatic[2] = True
    chain = dataclasses.replace(ur5e, name="slide", prismatic=prismatic)
    poses = forward(chain, np.random.default_rng(2).uniform(-0.5, 0.5, (5, chain.n)))
    full, joints = screws(chain, poses), joint_screws(chain, poses)
    np.testing.assert_array_equal(joints.point, full.point[:, :chain.n])
    np.testing.assert_array_equal(joints.is_rotation, full.is_rotation[:chain.n])
    assert not joints.is_rotation[2]


def _dataset(seed: int):  # type: ignore[no-untyped-def]
    truth = random_truth(np.random.default_rng(seed))
    return synthesize_stereo_target(truth, n_samples=30, seed=seed).dataset


def test_builds_of_one_dataset_share_chain_torques_and_whitening() -> None:
    dataset = _dataset(3)
    first = build_problem(dataset)
    again = build_problem(dataclasses.replace(dataset, extra_fields={"note": "copy"}),
                          "+geometry")
    assert again.chain is first.chain
    assert again.context.tau is first.context.tau
    assert again.sqrt_information is first.sqrt_information
    assert not first.context.tau.flags.writeable
    assert not first.sqrt_information.flags.writeable
    with pytest.raises(ValueError):
        first.sqrt_information[0, 0, 0] = 1.0


def test_another_dataset_gets_its_own_values() -> None:
    one, other = _dataset(4), _dataset(5)
    a, b = build_problem(one), build_problem(other)
    assert a.context.tau is not b.context.tau
    assert not np.array_equal(a.context.tau, b.context.tau)
    assert not np.array_equal(a.sqrt_information, b.sqrt_information)


def test_a_problem_keeps_its_latest_evaluation_only_for_that_x() -> None:
    from hostpc.fitting.solver import evaluate

    problem = build_problem(_dataset(6))
    x = np.zeros(problem.layout.size)
    first = evaluate(problem, x)
    assert evaluate(problem, x.copy()) is first
    assert not first.jacobian.flags.writeable  # type: ignore[union-attr]
    x[0] = 1e-4  # the caller's array changes: the kept evaluation must not match it
    moved = evaluate(problem, x)
    assert moved is not first
    assert not np.array_equal(moved.whitened, first.whitened)
    fresh = build_problem(problem.dataset)  # another problem: its own evaluations
    assert evaluate(fresh, moved.x) is not moved
