"""Pose planning (hostpc.planning.design) and the stereo_target candidates: no robot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.kinds.stereo_target.method import StereoTargetMethod
from hostpc.kinematics import get_robot
from hostpc.methods.base import RunSettings
from hostpc.methods.cell import build_cell
from hostpc.planning.design import (
    Design,
    PoseGroups,
    Travel,
    check_plan,
    design_matrix,
    greedy_d_optimal,
    group_selection,
    in_pool_order,
    joint_offset_sigmas,
    make_design,
    order_for_travel,
    poses_for_target_sigma,
    prior_bounded_joints,
    random_selection,
    verify_groups,
)
from hostpc.planning.tour import (
    full_turn_joints,
    move_times,
    nearest_neighbour,
    path_time,
    plan_tour,
    short_path,
)
from hostpc.robots.base import RobotState

UR5E_HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
DESCRIPTION = {  # what the simulated controller reports (controller_stub camera_description)
    "image_width": 1280, "image_height": 1024, "baseline_nominal": 0.12,
    "T_flange_camera_nominal": {"xyz": [0.0, -0.06, 0.04], "rpy": [0.0, 0.0, 0.0]},
    "target": {"radius": 0.01, "centre_nominal": [0.45, 0.15, 0.0], "normal": [0, 0, 1]},
}


def stereo_method(known: tuple[str, ...], tmp_path: Path, n_candidates: int = 600
                  ) -> StereoTargetMethod:
    """A stereo_target method with a nominal rig (no robot needed for planning)."""
    from hostpc.vision import StereoRig

    K = np.array([[1400.0, 0.0, 640.0], [0.0, 1400.0, 512.0], [0.0, 0.0, 1.0]])
    rig = StereoRig(image_size=(1280, 1024), K_left=K, dist_left=np.zeros(5), K_right=K,
                    dist_right=np.zeros(5), R=np.eye(3), T=np.array([-0.12, 0.0, 0.0]))
    cell = build_cell(DESCRIPTION, "ur5e", known=known)
    method = StereoTargetMethod(RunSettings(method="stereo_target", n_candidates=n_candidates),
                                cell, tmp_path)
    method.rig = rig
    return method


def home_state() -> RobotState:
    chain = get_robot("ur5e")
    return RobotState(q=UR5E_HOME.copy(), zero_offsets=np.zeros(6), q_min=chain.q_min,
                      q_max=chain.q_max)


@pytest.fixture(scope="module")
def pool_and_design(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    method = stereo_method((), tmp_path_factory.mktemp("plan"))
    pool = method.candidates(home_state(), np.random.default_rng(0))
    A, names, units = design_matrix(method.design_dataset(pool), None)
    return method, pool, make_design(A, names, units)


def test_candidates_are_reachable_visible_and_within_limits(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    method, pool, _ = pool_and_design
    chain = get_robot("ur5e")
    assert pool.shape == (600, 6)
    assert np.all(pool >= chain.q_min) and np.all(pool <= chain.q_max)
    assert np.all(method.visible(pool))
    depth = method.target_in_camera(pool)[:, 2]
    assert depth.min() > 0.25 and depth.max() < 0.65
    # varied orientations: the camera rolls widely about its optical axis
    assert np.ptp(pool[:, 5]) > np.pi


def test_structural_gauge_with_both_frames_estimated_is_q1_and_q6(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    _, _, design = pool_and_design
    fixed = {design.names[k] for k in np.flatnonzero(~design.free)}
    assert fixed == {"joint_offsets.q1", "joint_offsets.q6"}
    texts = " ".join(d.description for d in design.structural)
    assert "mark target as known" in texts and "mark tool as known" in texts


def test_known_target_makes_q1_identifiable(tmp_path: Path) -> None:
    method = stereo_method(("target",), tmp_path, n_candidates=200)
    pool = method.candidates(home_state(), np.random.default_rng(1))
    design = make_design(*design_matrix(method.design_dataset(pool), None))
    assert {design.names[k] for k in np.flatnonzero(~design.free)} == {"joint_offsets.q6"}


def test_d_optimal_beats_random_and_is_nested(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    _, _, design = pool_and_design
    chosen = greedy_d_optimal(design, 30)
    assert len(set(chosen.tolist())) == 30
    assert np.array_equal(greedy_d_optimal(design, 12), chosen[:12])
    planned = np.nanmax(joint_offset_sigmas(design.subset(chosen), 6))
    rng = np.random.default_rng(2)
    random_worst = np.median([
        np.nanmax(joint_offset_sigmas(design.subset(random_selection(600, 30, rng)), 6))
        for _ in range(10)])
    assert planned < 0.6 * random_worst


def test_check_plan_names_what_too_few_poses_cannot_separate(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    _, _, design = pool_and_design
    good = check_plan(design.subset(greedy_d_optimal(design, 20)))
    assert good.ok and good.plan_rank == good.pool_rank
    bad = check_plan(design.subset(greedy_d_optimal(design, 2)))
    assert not bad.ok and bad.plan_rank < bad.pool_rank
    assert all("not separable" in d.description or "no effect" in d.description
               for d in bad.deficient)


def test_order_for_travel_is_a_permutation_starting_near_the_robot() -> None:
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (25, 6))
    start = q[7] + 0.01
    order = order_for_travel(q, start)
    assert sorted(order.tolist()) == list(range(25)) and order[0] == 7
    travel = np.sum(np.max(np.abs(np.diff(q[order], axis=0)), axis=1))
    assert travel < np.sum(np.max(np.abs(np.diff(q, axis=0)), axis=1))


def _grouped_design(n_groups: int = 30, size: int = 5, n_params: int = 6,
                    seed: int = 4) -> tuple[Design, PoseGroups]:
    """A synthetic design of n_groups groups of `size` single-row poses (1 x n_params)."""
    rng = np.random.default_rng(seed)
    scale = rng.uniform(0.05, 3.0, (n_groups, 1, 1, 1))  # some groups far more informative
    A = (rng.normal(size=(n_groups, size, 1, n_params)) * scale).reshape(-1, 1, n_params)
    names = tuple(f"p.x{k}" for k in range(n_params))
    design = make_design(A, names, ("m",) * n_params)
    return design, PoseGroups(labels=np.repeat(np.arange(n_groups), size), min_groups=4)


def _logdet(design: Design, indices: np.ndarray) -> float:
    A = design.A[indices].reshape(-1, design.A.shape[2])
    return float(np.linalg.slogdet(A.T @ A)[1])


def test_group_selection_takes_whole_groups_by_their_summed_information() -> None:
    design, groups = _grouped_design()
    rng = np.random.default_rng(0)
    chosen = in_pool_order(group_selection(design, groups, n_poses=12, criterion="D",
                                           rng=rng))
    labels = groups.labels[chosen]
    # ceil(12 / 5) = 3 groups, but at least min_groups = 4; each complete, one after another
    assert len(set(labels.tolist())) == 4 and chosen.size == 20
    assert np.all(np.diff(labels) >= 0) and np.all(np.bincount(labels)[np.unique(labels)] == 5)
    # D-optimal over groups beats random whole groups
    random = [in_pool_order(group_selection(design, groups, 12, "random",
                                            np.random.default_rng(s)))
              for s in range(20)]
    assert _logdet(design, chosen) > max(_logdet(design, r) for r in random)
    # verification: whole groups the plan did not use
    verify = verify_groups(groups, chosen, 7, rng)
    assert verify.size == 10 and not set(groups.labels[verify]) & set(labels.tolist())
    assert verify_groups(groups, chosen, 0, rng).size == 0


# ---------------------------------------------------------------- tours and target sigma


def _all_reversals_time(q: np.ndarray, order: np.ndarray, start: np.ndarray) -> float:
    """The shortest path time over every single segment reversal of `order`."""
    best = np.inf
    for i in range(len(order)):
        for j in range(i + 1, len(order)):
            trial = order.copy()
            trial[i:j + 1] = trial[i:j + 1][::-1]
            best = min(best, path_time(q[trial], start))
    return float(best)


def test_tour_is_a_permutation_never_longer_than_selection_order_or_nearest_neighbour(
) -> None:
    rng = np.random.default_rng(5)
    for trial in range(20):
        n = int(rng.integers(1, 40))
        q = rng.uniform(-2, 2, (n, 6))
        start = rng.uniform(-2, 2, 6) if trial % 2 else None
        speed = rng.uniform(0.5, 3.0, 6) if trial % 3 else None
        tour = plan_tour(q, start, speed)
        assert sorted(tour.tolist()) == list(range(n))
        t_tour = path_time(q[tour], start, speed)
        assert t_tour <= path_time(q, start, speed) + 1e-12
        assert t_tour <= path_time(q[nearest_neighbour(q, start, speed)], start, speed) + 1e-12
        if start is None:
            assert tour[0] == 0  # without a start pose the first pose stays first


def test_tour_is_a_two_opt_local_optimum_and_much_shorter_than_random_order() -> None:
    rng = np.random.default_rng(6)
    q = rng.uniform(-2, 2, (14, 6))
    start = np.zeros(6)
    tour = plan_tour(q, start)
    assert path_time(q[tour], start) <= _all_reversals_time(q, tour, start) + 1e-9
    assert path_time(q[tour], start) < 0.8 * path_time(q, start)


def test_move_time_is_the_slowest_joint_at_its_own_speed() -> None:
    q_from, q_to = np.zeros(3), np.array([0.3, -1.0, 0.5])
    assert move_times(q_from, q_to) == pytest.approx(1.0)
    assert move_times(q_from, q_to, np.array([0.1, 2.0, 1.0])) == pytest.approx(3.0)


def test_planned_tour_from_home_beats_the_selection_order(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    _, pool, design = pool_and_design
    chosen = greedy_d_optimal(design, 40)
    tour = order_for_travel(pool[chosen], UR5E_HOME, tour=True)
    assert sorted(tour.tolist()) == list(range(40))
    assert (path_time(pool[chosen][tour], UR5E_HOME)
            < 0.7 * path_time(pool[chosen], UR5E_HOME))


def test_target_sigma_stop_takes_the_fewest_poses_and_the_fit_delivers_it(
        pool_and_design) -> None:  # type: ignore[no-untyped-def]
    from hostpc.dataset import dataset_from_dict
    from hostpc.fitting import fit
    from hostpc.model.measurements.predict import predict
    from hostpc.model.problem import build_problem

    method, pool, design = pool_and_design
    target = np.radians(0.01)
    chosen = greedy_d_optimal(design, 60)
    count = poses_for_target_sigma(design, chosen, target, 6, min_poses=3)
    assert count is not None and 3 < count < 60
    identifiable = [1, 2, 3, 4]  # q1 and q6: structural gauge with both frames estimated
    sigmas = joint_offset_sigmas(design.subset(chosen[:count]), 6)
    assert np.all(sigmas[identifiable] <= target)
    assert np.isnan(sigmas[0]) and np.isnan(sigmas[5])
    fewer = joint_offset_sigmas(design.subset(chosen[:count - 1]), 6)[identifiable]
    assert not np.all(fewer <= target)  # one pose fewer does not reach it
    assert poses_for_target_sigma(design, chosen[:count - 1], target, 6) is None
    # the fit of those poses, measured with the planned noise, has the promised sigmas
    q = pool[chosen[:count]]
    placeholder = build_problem(method.design_dataset(q), "joint_offsets")
    p, _ = predict(placeholder, np.zeros(placeholder.layout.size), jacobian=False)
    cov = method.expected_covariance(p)
    noise = np.random.default_rng(7).normal(size=(count, 3))
    measured = p + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), noise)
    document = method.dataset_document([
        {"q": q[k].tolist(), "p": measured[k].tolist(), "cov": cov[k].tolist(),
         "t": float(k)} for k in range(count)])
    result = fit(dataset_from_dict(document), None, cv_folds=0)
    assert result.converged
    fitted = np.array([result.sigma(f"joint_offsets.q{j + 1}") for j in identifiable])
    np.testing.assert_allclose(fitted, sigmas[identifiable], rtol=0.05)
    assert np.all(fitted <= 1.05 * target)


def test_travel_aware_selection_is_nested_and_its_tour_shorter(pool_and_design) -> None:  # type: ignore[no-untyped-def]
    """The short plan's selection (run_plan.TRAVEL_SLACK): within 15 % of the best gain,
    the candidate nearest the poses already chosen. Still nested (a prefix is the selection
    of that size, so the target-sigma stop is a prefix), the plain D-optimal order without
    slack, and its 10-pose tour from home takes about a third less joint motion (15.1 ->
    10.4 rad on this pool)."""
    _, pool, design = pool_and_design
    chain = get_robot("ur5e")
    periodic = full_turn_joints(chain.q_min, chain.q_max)
    near = Travel(pool, UR5E_HOME, periodic, 0.15)
    chosen = greedy_d_optimal(design, 10, travel=near)
    assert np.array_equal(greedy_d_optimal(design, 6, travel=near), chosen[:6])
    plain = greedy_d_optimal(design, 10)
    assert np.array_equal(greedy_d_optimal(design, 10, travel=Travel(pool, UR5E_HOME,
                                                                      periodic, 0.0)), plain)
    assert not np.array_equal(chosen, plain)

    def tour_time(indices: np.ndarray) -> float:
        _, q = short_path(pool[indices], UR5E_HOME, chain.q_min, chain.q_max)
        return path_time(q, UR5E_HOME)

    assert tour_time(chosen) < 0.8 * tour_time(plain)


def test_a_joint_only_a_prior_identifies_is_planned_with_the_prior() -> None:
    """q1 and a frame's rotation f enter every pose only as q1 + f (a joint a frame hides,
    as world_point's J6 behind the markers' frame); a cell reference's prior on f
    identifies q1, with a floor no pose lowers. The plan counts q1 (its sigma is finite,
    not in the gauge): a target the prior allows is reached on q1 too; a target below the
    prior's floor adds no pose for q1 (the plain count of q2, q3 stands)."""
    rng = np.random.default_rng(2)
    n_pool = 200
    rows = rng.normal(size=(n_pool, 2, 3)) * 30.0
    A = np.zeros((n_pool, 2, 4))
    A[:, :, 0] = A[:, :, 3] = rows[:, :, 0]  # q1 and f: always together
    A[:, :, 1:3] = rows[:, :, 1:]             # q2, q3: seen by the poses
    names = ("joint_offsets.q1", "joint_offsets.q2", "joint_offsets.q3", "f.rz")
    units = ("rad",) * 4
    plain = make_design(A, names, units)
    design = make_design(A, names, units, np.array([[0.0, 0.0, 0.0, 1.0 / 0.01]]))
    assert design.free.sum() == 3  # the poses alone: one of q1, f is the gauge
    assert design.by_prior is not None
    assert design.by_prior.tolist() == [True, False, False, True]
    order = greedy_d_optimal(design, 120)
    floor = joint_offset_sigmas(design.subset(order), 3)[0]
    assert 0.01 <= floor < 0.0105  # the prior's sigma bounds q1
    assert np.isnan(joint_offset_sigmas(plain.subset(order), 3)[0])  # the plain design
    # a target above the floor: q1 needs more poses than q2 and q3 do
    assert prior_bounded_joints(design, order, 0.0125, 3) == {}
    fewest = poses_for_target_sigma(design, order, 0.0125, 3)
    assert fewest is not None and fewest > poses_for_target_sigma(plain, order, 0.0125, 3)
    assert joint_offset_sigmas(design.subset(order[:fewest]), 3)[0] <= 0.0125
    # below the floor: q1 is bounded and adds nothing
    assert prior_bounded_joints(design, order, 0.005, 3) == {0: pytest.approx(floor)}
    assert (poses_for_target_sigma(design, order, 0.005, 3)
            == poses_for_target_sigma(plain, order, 0.005, 3))


def test_per_second_selection_reaches_the_target_sigma_in_less_robot_time(
        pool_and_design) -> None:  # type: ignore[no-untyped-def]
    """stereo_target's short plan (`ShortPlan.selection` "per_second", design.Travel.per_pose_s):
    each pose the most information per second of its move from the last one, settle and
    capture. Nested, and the fewest of its poses that reach a target sigma cost less robot
    time as a tour from home (moves ramped at the simulator's 4 rad/s^2, half speed) than
    those of the nearest-within-15 % selection it replaces."""
    from hostpc.calibrate.run_plan import TRAVEL_SLACK
    from hostpc.kinds.stereo_target.method import StereoTargetMethod
    from hostpc.planning.robot_time import TimeLimits

    assert StereoTargetMethod.short_plan.selection == "per_second"
    _, pool, design = pool_and_design
    chain = get_robot("ur5e")
    periodic = full_turn_joints(chain.q_min, chain.q_max)
    limits = TimeLimits.from_extra({"max_joint_acceleration": 4.0}, 6)
    rates = limits.rates(0.5)
    per_pose = limits.settle_s + limits.capture_s
    path = Travel(pool, UR5E_HOME, periodic, rates=rates, per_pose_s=per_pose)
    chosen = greedy_d_optimal(design, 20, travel=path)
    assert np.array_equal(greedy_d_optimal(design, 8, travel=path), chosen[:8])
    slack = greedy_d_optimal(design, 20, travel=Travel(pool, UR5E_HOME, periodic,
                                                       TRAVEL_SLACK))
    target = np.radians(0.01)

    def robot_time(order: np.ndarray) -> float:
        count = poses_for_target_sigma(design, order, target, 6, min_poses=6)
        assert count is not None
        _, q = short_path(pool[order[:count]], UR5E_HOME, chain.q_min, chain.q_max, rates)
        return float(np.sum(move_times(np.vstack([UR5E_HOME, q[:-1]]), q, rates))
                     + per_pose * count)

    assert robot_time(chosen) < 0.95 * robot_time(slack)  # 7.4 s against 8.3 s
