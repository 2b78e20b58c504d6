"""dual_loop against the simulated controller's independent humanoid model: recovery of
the truth, the named null directions, joint vs stepwise, Mahalanobis vs plain least
squares (seeded; the full 50-run study is the slow test and bench/bench_dual_loop.py)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.bench_dual_loop import (
    acquire,
    monte_carlo,
    random_scenario,
    true_points,
    truth_vector,
)
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.humanoid import HumanoidSimulation
from hostpc.fitting import solve
from hostpc.fitting.stepwise import fit_stepwise, gauge_equivalent
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

NULL_PAIRS = {
    "joint_offsets.head.q1": {"left_base", "right_base"},  # pan vs both bases about pan axis
    "joint_offsets.head.q2": {"camera"},  # tilt vs the camera about the tilt axis
    "joint_offsets.left.q1": {"left_base"},
    "joint_offsets.right.q1": {"right_base"},
    "joint_offsets.left.q7": {"left_target"},
    "joint_offsets.right.q7": {"right_target"},
}


@pytest.fixture(scope="module")
def stub_run():  # type: ignore[no-untyped-def]
    sim = HumanoidSimulation(scenario_from_dict(random_scenario(3)))
    poses = plan_poses(60, np.random.default_rng(0))
    dataset, kept = acquire(sim, poses)
    return sim, poses.subset(kept), dataset


def test_host_model_agrees_with_the_independent_stub_model(stub_run) -> None:  # type: ignore[no-untyped-def]
    sim, poses, dataset = stub_run
    problem = build_problem(dataset)
    predicted, _ = predict(problem, truth_vector(sim.truth(), problem), jacobian=False)
    np.testing.assert_allclose(predicted, true_points(sim, poses), atol=1e-12)


def test_joint_fit_recovers_every_identifiable_unknown_within_3_sigma(stub_run) -> None:  # type: ignore[no-untyped-def]
    sim, _, dataset = stub_run
    problem = build_problem(dataset)
    result = solve(problem, cv_folds=0)
    assert result.converged
    assert 0.7 < result.chi2_dof < 1.3
    # the non-identifiable unknowns are named, each with the frames that absorb it
    named = {d.fixed: {p.split(".")[0] for p in d.parameters[1:]} for d in result.unidentifiable}
    assert set(named) == set(NULL_PAIRS)
    for fixed, frames in NULL_PAIRS.items():
        assert frames <= named[fixed], (fixed, named[fixed])
    # every free parameter within 3 sigma of the truth expressed in the fit's gauge
    x_true = gauge_equivalent(problem, truth_vector(sim.truth(), problem), result.fixed)
    free = ~result.fixed
    z = (result.x[free] - x_true[free]) / result.std[free]
    worst = int(np.argmax(np.abs(z)))
    names = np.array(problem.layout.names)[free]
    assert np.all(np.abs(z) < 3.0), f"{names[worst]}: {z[worst]:.2f} sigma"
    # the identifiable zero offsets are the raw truth (no gauge shift on them)
    raw = truth_vector(sim.truth(), problem)
    for name in ("joint_offsets.left.q4", "joint_offsets.right.q2"):
        k = problem.layout.index(name)
        assert abs(result.x[k] - raw[k]) < 3.0 * result.std[k]


def test_stepwise_uses_the_same_gauge(stub_run) -> None:  # type: ignore[no-untyped-def]
    _, _, dataset = stub_run
    stepwise = fit_stepwise(dataset)
    joint = solve(build_problem(dataset), cv_folds=0)
    np.testing.assert_array_equal(stepwise.fixed, joint.fixed)
    assert all(step.converged for step in stepwise.steps)


def _check_study(study: dict) -> None:  # type: ignore[type-arg]
    table = study["table"]
    joint, stepwise, plain = table["joint"], table["stepwise"], table["joint_unweighted"]
    # the joint solve's error on the shared camera transform <= the stepwise one
    assert joint["camera_mm"]["rms"] <= stepwise["camera_mm"]["rms"]
    assert joint["camera_deg"]["rms"] <= stepwise["camera_deg"]["rms"]
    assert joint["bases_mm"]["rms"] <= stepwise["bases_mm"]["rms"]
    assert joint["heldout_mm"]["rms"] <= stepwise["heldout_mm"]["rms"]
    # Mahalanobis weighting beats identity weights on every metric
    for metric in joint:
        assert joint[metric]["rms"] < plain[metric]["rms"], metric


def test_joint_beats_stepwise_and_mahalanobis_beats_unweighted_quick() -> None:
    _check_study(monte_carlo(n_runs=8, first_seed=1000, n_per_arm=60))


@pytest.mark.slow
def test_monte_carlo_50_runs() -> None:
    study = monte_carlo(n_runs=50, first_seed=1000, n_per_arm=60)
    _check_study(study)
    assert study["joint_camera_wins"] > 0.5
