"""What problem builds share (issue 17): the theta-only screws equal those rows of all 5n;
the chain, gravity torques and whitening are computed once per build, read-only, shared by
the problem's extensions and (the chain) by the builds handed its visible cache
(``problem.shared``, issue 26), and never handed to another dataset."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from hostpc.kinematics import forward, get_robot, joint_screws, screws
from hostpc.model.memo import SharedValues
from hostpc.model.problem import build_problem, extend_problem
from hostpc.model.registry import builtin_effects
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
                          "+geometry", shared=first.shared)
    assert again.chain is first.chain
    assert again.shared is first.shared
    again = extend_problem(first, [builtin_effects()["geometry"]()])
    assert again.context.tau is first.context.tau
    assert again.sqrt_information is first.sqrt_information
    assert build_problem(dataset).chain is not first.chain  # not handed: its own
    assert not first.context.tau.flags.writeable
    assert not first.sqrt_information.flags.writeable
    with pytest.raises(ValueError):
        first.sqrt_information[0, 0, 0] = 1.0


@pytest.mark.parametrize("method", ["world_pose", "stereo_target"])
def test_a_problems_measurements_are_read_only(method: str) -> None:
    """The memos cache what is derived from problem.measured (the latest evaluation, the
    held-out residuals): an edit in place would leave them stale, so it raises, in the
    problem and in its views; the dataset's own arrays are left as they were."""
    from hostpc.model.measurements.registry import measurement_models

    dataset = measurement_models()[method].example(np.random.default_rng(0))
    writable = dataset.samples.p.flags.writeable
    problem = build_problem(dataset)
    for measured in (problem.measured, problem.subset(np.arange(3)).measured):
        assert not measured.flags.writeable
        with pytest.raises(ValueError):
            measured[:] += 1e-3
    assert dataset.samples.p.flags.writeable == writable


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


def test_a_urdf_chain_is_read_once_and_again_when_the_file_changes(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import os
    from pathlib import Path

    from hostpc.dataset import load_dataset
    from hostpc.model.problem import robot_chain

    source = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(source.read_text())
    document = {"format": "zerocal-dataset/1", "method": "stereo_target",
                "robot": {"urdf": "arm.urdf", "base_link": "base_link", "tip_link": "tool0"},
                "frames": {"tool": {"xyz": [0, 0, 0.05], "rpy": [0, 0, 0]},
                           "target": [0.5, 0.2, 0.3]},
                "samples": [{"q": [0.1 * i] * 7, "p": [0.0, 0.0, 0.4], "sigma": 1e-4}
                            for i in range(5)]}
    (tmp_path / "set.json").write_text(json.dumps(document))
    dataset = load_dataset(tmp_path / "set.json")
    shared = SharedValues()
    first = robot_chain(dataset, shared=shared)
    assert robot_chain(dataset, shared=shared) is first
    urdf.write_text(source.read_text() + "\n")  # changed: read again
    os.utime(urdf, ns=(1, 1))
    assert robot_chain(dataset, shared=shared) is not first


def test_a_refit_builds_anew_and_gives_the_same_result() -> None:
    from hostpc.fitting import fit

    dataset = _dataset(7)
    first = fit(dataset)
    again = fit(dataset)
    assert again.problem is not first.problem  # no hidden cache keyed by the dataset
    for field in ("x", "std", "covariance", "residuals_whitened"):
        np.testing.assert_array_equal(getattr(again, field), getattr(first, field))
    assert (again.cv_rms, again.iterations, again.message) == (
        first.cv_rms, first.iterations, first.message)
    handed = fit(dataset, shared=first.problem.shared)  # the visible cache, on request
    assert handed.problem.chain is first.problem.chain
    np.testing.assert_array_equal(handed.x, first.x)


def test_editing_a_dataset_in_place_and_refitting_gives_the_new_answer() -> None:
    """A marker added in place to a world_point dataset's markers (a dict): the refit of
    the same object lays out its parameters (a refit that reused the problem built before
    did not, and failed on the stale layout)."""
    from hostpc.fitting import fit
    from hostpc.model.measurements.registry import measurement_models

    dataset = measurement_models()["world_point"].example(np.random.default_rng(0))
    first = fit(dataset)
    markers = dataset.frames["markers"]
    assert isinstance(markers, dict)
    markers["c"] = np.array([0.01, 0.0, 0.02])  # edited in place
    edited = fit(dataset)
    fresh = fit(dataclasses.replace(dataset, frames=dict(dataset.frames)))
    assert "markers.c.x" in edited.names and "markers.c.x" not in first.names
    assert edited.names == fresh.names
    np.testing.assert_array_equal(edited.x, fresh.x)
    np.testing.assert_array_equal(edited.std, fresh.std)
