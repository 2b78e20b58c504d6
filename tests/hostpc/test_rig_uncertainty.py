"""The rig's own uncertainty (hostpc.vision.rig_uncertainty), its propagation into the fit
(hostpc.fitting.shared_errors), the centre re-correction with a better normal
(hostpc.vision.centre_refinement) and the coverage planner (hostpc.vision.rig_planning)."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from controller_stub.scenario.spec import Scenario
from controller_stub.world.simulation import Simulation
from hostpc.dataset import dataset_from_dict, dataset_to_dict
from hostpc.fitting import fit
from hostpc.synthesize import random_truth, synthesize_stereo_target
from hostpc.vision import ChessboardSpec, StereoRig, TargetMeasurer
from hostpc.vision.centre_refinement import recorrect_centres
from hostpc.vision.rectification import rectification_for
from hostpc.vision.rig import rig_from_dict
from hostpc.vision.rig_planning import CoveragePlanner, covered_cells
from hostpc.vision.rig_uncertainty import (
    N_RIG,
    RIG_PARAMETERS,
    chessboard_rig_covariance,
    point_sensitivity,
    rig_vector,
    rig_with_vector,
    uncertainty_document,
)
from hostpc.vision.triangulation import project, triangulate

BOARD = ChessboardSpec(9, 6, 0.025)


def _rig() -> StereoRig:
    K = np.array([[1400.0, 0.0, 640.0], [0.0, 1401.0, 512.0], [0.0, 0.0, 1.0]])
    R = cv2.Rodrigues(np.array([0.001, -0.004, 0.002]))[0]
    return StereoRig((1280, 1024), K, [-0.08, 0.05, 4e-4, -3e-4, 0.0], K,
                     [-0.07, 0.04, 0.0, 0.0, 0.0], R, [-0.12, 1e-4, 5e-4])


def test_rig_vector_round_trip_and_file() -> None:
    rig = _rig()
    v = rig_vector(rig)
    assert v.shape == (N_RIG,) == (len(RIG_PARAMETERS),)
    again = rig_with_vector(rig, v)
    np.testing.assert_allclose(again.K_left, rig.K_left)
    np.testing.assert_allclose(again.R, rig.R, atol=1e-15)
    cov = np.diag(np.linspace(1e-6, 1e-3, N_RIG))
    with_cov = dataclasses.replace(rig, covariance=cov)
    loaded = rig_from_dict(with_cov.to_dict())
    np.testing.assert_array_equal(loaded.covariance, cov)
    assert rig_from_dict(rig.to_dict()).covariance is None
    assert uncertainty_document(rig, cov)["parameters"] == list(RIG_PARAMETERS)


def _synthetic_views(rig: StereoRig, rng: np.random.Generator, n_views: int = 14
                     ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Exact corner projections of board poses spread over the image (no noise)."""
    obj = BOARD.object_points().astype(float)
    centre = obj.mean(axis=0)
    lefts, rights, poses = [], [], []
    while len(lefts) < n_views:
        rvec = rng.normal(0, 0.35, 3) + np.array([math.pi, 0, 0])
        R = cv2.Rodrigues(rvec)[0]
        t = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.1, 0.1), rng.uniform(0.35, 0.6)])
        t = t - R @ centre
        X = obj @ R.T + t
        uv_l = project(rig.K_left, rig.dist_left, X)
        uv_r = project(rig.K_right, rig.dist_right, X @ rig.R.T + rig.T)
        inside = all(np.all((uv[:, 0] > 5) & (uv[:, 0] < 1275) & (uv[:, 1] > 5)
                            & (uv[:, 1] < 1019)) for uv in (uv_l, uv_r))
        if inside and np.all(X[:, 2] > 0.1):
            lefts.append(uv_l)
            rights.append(uv_r)
            poses.append(np.concatenate([cv2.Rodrigues(R)[0].ravel(), t]))
    return lefts, rights, poses


@pytest.mark.slow
def test_chessboard_covariance_is_honest_for_white_corner_noise() -> None:
    """Over repeated synthetic calibrations with 0.05 px corner noise, the rig errors'
    Mahalanobis distance under the predicted covariance averages the 24 it should (the
    derivatives and the view-pose marginalisation are right)."""
    truth = _rig()
    rng = np.random.default_rng(3)
    lefts, rights, _ = _synthetic_views(truth, rng, n_views=10)
    obj = [BOARD.object_points().reshape(-1, 1, 3)] * len(lefts)
    size = truth.image_size
    # a tight tolerance: the solver must reach the noisy optimum from the truth it starts at
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-10)
    distances, sigmas = [], []
    for _ in range(8):
        noisy_l = [(u + rng.normal(0, 0.05, u.shape)).astype(np.float32).reshape(-1, 1, 2)
                   for u in lefts]
        noisy_r = [(u + rng.normal(0, 0.05, u.shape)).astype(np.float32).reshape(-1, 1, 2)
                   for u in rights]
        out = cv2.stereoCalibrateExtended(
            obj, noisy_l, noisy_r, truth.K_left.copy(), truth.dist_left.copy(),
            truth.K_right.copy(), truth.dist_right.copy(), size, truth.R.copy(),
            truth.T.reshape(3, 1).copy(), flags=cv2.CALIB_USE_INTRINSIC_GUESS
            | cv2.CALIB_USE_EXTRINSIC_GUESS, criteria=criteria)
        _, K1, d1, K2, d2, R, T = out[:7]
        fitted = StereoRig(size, K1, d1.ravel(), K2, d2.ravel(), R, T.ravel())
        cov, sigma = chessboard_rig_covariance(fitted, BOARD.object_points(), noisy_l,
                                               noisy_r, out[9], out[10])
        delta = rig_vector(fitted) - rig_vector(truth)
        delta[18:21] = cv2.Rodrigues(fitted.R @ truth.R.T)[0].ravel()
        distances.append(float(delta @ np.linalg.solve(cov, delta)))
        sigmas.append(sigma)
    assert np.mean(sigmas) == pytest.approx(0.05, rel=0.1)
    # mean of 8 chi-square(24) draws: 24 +- 2.4 (1 sigma)
    assert 16.0 < np.mean(distances) < 33.0, distances


def test_point_sensitivity_against_baseline_scaling() -> None:
    """Scaling the translation T by (1 + e) scales every triangulated point by (1 + e)."""
    rig = _rig()
    points = np.array([[0.05, -0.02, 0.45], [-0.08, 0.04, 0.6], [0.0, 0.0, 0.35]])
    uv = np.stack([np.stack([project(rig.K_left, rig.dist_left, p[None])[0],
                             project(rig.K_right, rig.dist_right, (rig.R @ p + rig.T)[None])[0]])
                   for p in points])
    D = point_sensitivity(rig, uv)
    assert D.shape == (3, 3, N_RIG)
    dp = D[:, :, 21:24] @ (rig.T * 1e-3)
    np.testing.assert_allclose(dp, points * 1e-3, rtol=2e-3, atol=2e-9)


def _dataset_with_rig(rig: StereoRig, cov: np.ndarray, stereo_poses: np.ndarray):  # type: ignore[no-untyped-def]
    truth = {k: v for k, v in random_truth(np.random.default_rng(4)).items()
             if not k.startswith("target.")}
    data = synthesize_stereo_target(truth, q=stereo_poses, noise_scale=0.0, known=("target",))
    p = data.dataset.samples.p
    uv = np.stack([np.stack([project(rig.K_left, rig.dist_left, x[None])[0],
                             project(rig.K_right, rig.dist_right, (rig.R @ x + rig.T)[None])[0]])
                   for x in p])
    document = dataset_to_dict(data.dataset)
    for sample, row in zip(document["samples"], uv, strict=True):
        sample["uv"] = row.tolist()
    plain = dataset_from_dict(document)
    document["rig_uncertainty"] = uncertainty_document(rig, cov)
    return plain, dataset_from_dict(document)


def test_shared_rig_error_matches_refits_with_a_perturbed_rig(stereo_poses) -> None:  # type: ignore[no-untyped-def]
    """The covariance the rig adds equals A S A^T with A measured by re-triangulating the
    same pixels with a perturbed rig and refitting."""
    rig = _rig()
    chosen = [RIG_PARAMETERS.index(n) for n in ("left.fx", "stereo.ry", "stereo.tx")]
    steps = np.array([0.5, 2e-4, 2e-4])
    cov = np.zeros((N_RIG, N_RIG))
    cov[chosen, chosen] = steps**2
    plain, with_rig = _dataset_with_rig(rig, cov, stereo_poses)
    base = fit(plain, cv_folds=0)
    shared = fit(with_rig, cv_folds=0)
    np.testing.assert_array_equal(base.x, shared.x)  # the estimate is unchanged
    A = []
    for k, step in zip(chosen, steps, strict=True):
        moved = rig_vector(rig)
        moved[k] += step
        rect = rectification_for(rig_with_vector(rig, moved))
        p = np.array([triangulate(rect, u[0], u[1]).p for u in plain.samples.uv])
        refit = fit(dataclasses.replace(plain, samples=dataclasses.replace(plain.samples, p=p)),
                    cv_folds=0)
        A.append(refit.x - base.x)  # per one sigma of this rig parameter
    A = np.array(A).T
    expected = base.covariance + A @ A.T
    free = ~base.fixed
    np.testing.assert_allclose(shared.std[free], np.sqrt(np.diag(expected))[free], rtol=0.03)


@pytest.fixture(scope="module")
def sim() -> Simulation:
    return Simulation(Scenario())


def test_recorrected_centres_equal_a_measurement_with_the_better_normal(sim: Simulation) -> None:
    cam = sim.truth()["camera"]
    K = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1.0]])
    T_right_left = np.linalg.inv(sim.stereo.T_left_right)
    rig = StereoRig((cam["image_width"], cam["image_height"]), K, cam["distortion"], K,
                    cam["distortion"], T_right_left[:3, :3], T_right_left[:3, 3])
    measurer = TargetMeasurer(rig, sim.scenario.target.radius)
    left_r, right_r = sim.stereo.renderers()
    T = np.eye(4)
    tilt = cv2.Rodrigues(np.array([0.35, -0.25, 0.0]))[0]
    T[:3, :3] = tilt @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0.05, -0.02, 0.42]
    left = left_r.render_disk(T, sim.stereo.disk_pattern)
    right = right_r.render_disk(T_right_left @ T, sim.stereo.disk_pattern)
    n_true = T[:3, 2]
    n_wrong = cv2.Rodrigues(np.array([0.01, -0.008, 0.0]))[0] @ n_true  # ~0.7 deg off
    with_wrong = measurer.measure(left, right, normal_hint=n_wrong)
    with_true = measurer.measure(left, right, normal_hint=n_true)
    assert np.max(np.abs(with_wrong.uv - with_true.uv)) > 3e-3  # the error being fixed
    uv, p = recorrect_centres(rig, sim.scenario.target.radius, with_wrong.uv[None],
                              with_wrong.p[None], n_wrong[None], n_true[None])
    np.testing.assert_allclose(uv[0], with_true.uv, atol=2e-4)
    np.testing.assert_allclose(p[0], with_true.p, atol=2e-7)
    same, _ = recorrect_centres(rig, 0.01, with_wrong.uv[None], with_wrong.p[None],
                                n_wrong[None], n_wrong[None])
    np.testing.assert_array_equal(same[0], with_wrong.uv)


def test_coverage_planner_replaces_rejected_views_and_adds_coverage() -> None:
    size = (1280, 1024)

    def board_at(cx: float, cy: float) -> np.ndarray:
        return np.array([[cx - 100, cy - 80], [cx + 100, cy - 80], [cx + 100, cy + 80],
                         [cx - 100, cy + 80]], float)

    planner = CoveragePlanner(n_planned=2, size=size, target=0.25)
    assert covered_cells(board_at(640, 512), size).sum() >= 4
    assert planner.offer(0, None, board_at(640, 512)) is False  # rejected: not found
    assert planner.offer(1, board_at(640, 512), board_at(600, 512))
    assert planner.offer(2, board_at(640, 512), board_at(600, 512))  # planned set: kept
    assert not planner.done()
    assert not planner.offer(3, board_at(640, 512), board_at(600, 512))  # adds nothing
    centres = [(x, y) for x in (120, 360, 900, 1160) for y in (100, 400, 700, 950)]
    for view, (x, y) in enumerate(centres, start=4):
        if planner.done():
            break
        planner.offer(view, board_at(x, y), board_at(x - 40, y))
    assert planner.done() and min(planner.coverage) >= 0.25
    assert planner.rejected[0] == (0, "chessboard not found in the left image")


@pytest.mark.slow
@pytest.mark.parametrize("world", ["faults.yaml", "default.yaml:4"])
def test_planned_views_pass_the_coverage_check(world: str) -> None:
    """Worlds whose 20 fixed views covered 45-48 % (faults.yaml, default seed 4) pass their
    rig calibration with the views planned as `hostpc calibrate` plans them."""
    from pathlib import Path

    import yaml

    from controller_stub.scenario.spec import scenario_from_dict
    from hostpc.vision import calibrate_rig
    from hostpc.vision.rig_calibration import find_chessboard

    name, _, seed = world.partition(":")
    folder = Path(__file__).resolve().parents[2] / "controller_stub" / "scenarios"
    data = yaml.safe_load((folder / name).read_text())
    if seed:
        data["seed"] = int(seed)
    sim = Simulation(scenario_from_dict(data))
    board = sim.camera_description()["chessboard"]
    spec = ChessboardSpec(board["cols"], board["rows"], board["square_size"])
    planner = CoveragePlanner(board["n_views"], (1280, 1024))
    pairs = []
    for view in range(board["max_views"]):
        if planner.done():
            break
        frame = sim.capture_stereo("chessboard", view)
        if planner.offer(view, find_chessboard(frame.left, spec),
                         find_chessboard(frame.right, spec)):
            pairs.append((frame.left, frame.right))
    assert planner.done(), planner.coverage
    fixed = [(f.left, f.right) for f in (sim.capture_stereo("chessboard", v)
                                         for v in range(board["n_views"]))]
    assert not calibrate_rig(fixed, spec).ok  # the fixed set fails its coverage check
    result = calibrate_rig(pairs, spec)
    assert result.ok, result.warnings
    assert result.rig.covariance is not None and result.corner_sigma_px < 0.1


def _floored(with_rig, rig: StereoRig, cov: np.ndarray):  # type: ignore[no-untyped-def]
    """(the dataset's document with a pixel floor added to every sample's covariance, as
    stereo_target adds it, the floor in px): the depth floor as large as the noise."""
    document = dataset_to_dict(with_rig)
    p = np.array([s["p"] for s in document["samples"]])
    depth_var = np.mean([s["cov"][2][2] for s in document["samples"]])
    fx, baseline = rig.K_left[0, 0], rig.baseline
    z = np.abs(p[:, 2])
    floor_px = float(np.sqrt(depth_var / np.mean((z**2 * np.sqrt(2.0) / (fx * baseline)) ** 2)))
    for sample, zi in zip(document["samples"], z, strict=True):
        c = np.array(sample["cov"])
        c[0, 0] += (zi * floor_px / fx) ** 2
        c[1, 1] += (zi * floor_px / fx) ** 2
        c[2, 2] += (zi**2 * np.sqrt(2.0) * floor_px / (fx * baseline)) ** 2
        sample["cov"] = c.tolist()
    return document, floor_px


def test_declared_pixel_floor_is_a_weighting_not_a_reported_noise(stereo_poses) -> None:  # type: ignore[no-untyped-def]
    """A floor added to the samples' covariances and declared in the block leaves the reported
    covariance that of the noise alone (the sandwich for the floor-weighted estimator: within
    a few % of the unfloored fit's), where an undeclared floor inflates it."""
    rig = _rig()
    cov = np.zeros((N_RIG, N_RIG))
    cov[0, 0] = 0.5**2
    _, with_rig = _dataset_with_rig(rig, cov, stereo_poses)
    document, floor_px = _floored(with_rig, rig, cov)
    undeclared = fit(dataset_from_dict(document), cv_folds=0)
    document["rig_uncertainty"] = uncertainty_document(rig, cov, floor_px)
    declared = fit(dataset_from_dict(document), cv_folds=0)
    reference = fit(with_rig, cv_folds=0)
    free = ~reference.fixed
    np.testing.assert_array_equal(declared.x, undeclared.x)  # the weighting is the same
    ratio = declared.std[free] / reference.std[free]
    assert np.all(ratio > 0.999) and np.all(ratio < 1.1), ratio  # sandwich >= optimal
    assert np.mean(undeclared.std[free] / reference.std[free]) > 1.2


def test_a_declared_floor_keeps_the_noise_of_a_prior_block(stereo_poses) -> None:  # type: ignore[no-untyped-def]
    """With a declared floor, the sandwich's noise holds the prior rows too: a cell
    reference's tool frame (the only thing that gives q6 with the target known) keeps q6's
    sigma that of the unfloored fit with the same prior. The old sandwich summed the
    samples' noise only and dropped the prior's: the sigmas the prior gives fell towards the
    rig term alone (stereo_target's all-joint MSE / sigma^2 up to 1.9, docs/performance.md)."""
    from hostpc.fitting.priors import with_prior_blocks

    rig = _rig()
    cov = np.zeros((N_RIG, N_RIG))
    cov[0, 0] = 0.5**2
    _, with_rig = _dataset_with_rig(rig, cov, stereo_poses[30:42])
    block = {"names": [f"tool.{p}" for p in ("x", "y", "z", "rx", "ry", "rz")],
             "value": [0.0] * 6,
             "covariance": np.diag([1e-5] * 3 + [1e-4] * 3).__pow__(2).tolist()}
    document, floor_px = _floored(with_rig, rig, cov)
    document["rig_uncertainty"] = uncertainty_document(rig, cov, floor_px)
    declared = fit(with_prior_blocks(dataset_from_dict(document), [block]), cv_folds=0)
    reference = fit(with_prior_blocks(with_rig, [block]), cv_folds=0)
    q6 = reference.names.index("joint_offsets.q6")
    assert not reference.fixed[q6] and reference.std[q6] > 5e-5  # the prior gives it
    free = ~reference.fixed
    ratio = declared.std[free] / reference.std[free]
    assert np.all(ratio > 0.999) and np.all(ratio < 1.1), ratio


def _three_rig_errors() -> tuple[StereoRig, list[int], np.ndarray, np.ndarray]:
    """(the rig, three of its parameters, their sigmas, S: the 24 x 24 covariance of those
    three)."""
    chosen = [RIG_PARAMETERS.index(n) for n in ("left.fx", "stereo.ry", "stereo.tx")]
    steps = np.array([0.5, 2e-4, 2e-4])
    cov = np.zeros((N_RIG, N_RIG))
    cov[chosen, chosen] = steps**2
    return _rig(), chosen, steps, cov


def _reference_and_run(rig: StereoRig, cov: np.ndarray, stereo_poses: np.ndarray):  # type: ignore[no-untyped-def]
    """(plain, with rig) of a recording run (30 poses) and of a later run (12 others)."""
    return (_dataset_with_rig(rig, cov, stereo_poses[:30]),
            _dataset_with_rig(rig, cov, stereo_poses[30:42]))


def test_a_reference_recorded_with_the_same_rig_shares_its_error(stereo_poses) -> None:  # type: ignore[no-untyped-def]
    """A cell reference's camera frame recorded with the rig a later run uses carries that
    rig's error, and so do the later run's samples: the later fit's covariance is the noise
    of both plus (A_run + A_ref) S (A_run + A_ref)^T, A measured end to end (re-triangulate
    BOTH runs' pixels with a perturbed rig, re-record the reference, refit). Counted as
    independent (the old code) the cross terms were lost and q6's sigma was optimistic."""
    from hostpc.calibrate.reference import (
        MOUNT_FLOOR_M,
        MOUNT_FLOOR_RAD,
        frame_priors,
        reference_from_fit,
    )
    from hostpc.fitting.priors import with_prior_blocks

    rig, chosen, steps, cov = _three_rig_errors()
    (plain_ref, rig_ref), (plain_run, rig_run) = _reference_and_run(rig, cov, stereo_poses)

    def later_fit(recording, run):  # type: ignore[no-untyped-def]
        reference = reference_from_fit(fit(recording, cv_folds=0), robot_serial="SN-1",
                                       cell={}, source_run="r", software="t")
        blocks = [p.block() for p in frame_priors(reference, rig_run, ("tool",))]
        return fit(with_prior_blocks(run, blocks), cv_folds=0), blocks

    shared, blocks = later_fit(rig_ref, rig_run)
    assert "shared_sensitivity" in blocks[0]
    C = np.asarray(blocks[0]["covariance"])  # the weights: noise and rig error
    base, _ = later_fit(rig_ref, plain_run)  # same weights, no shared error: (J^T J)^-1
    tool = [base.names.index(f"tool.{p}") for p in ("x", "y", "z", "rx", "ry", "rz")]
    # the reference's noise alone: a fit without the rig block, plus the mount floor
    C_noise = (fit(plain_ref, cv_folds=0).covariance[np.ix_(tool, tool)]
               + np.diag([MOUNT_FLOOR_M**2] * 3 + [MOUNT_FLOOR_RAD**2] * 3))
    G = base.covariance[:, tool] @ np.linalg.inv(C)
    noise = base.covariance + G @ (C_noise - C) @ G.T
    A = []
    for k, step in zip(chosen, steps, strict=True):
        moved = rig_vector(rig)
        moved[k] += step
        rect = rectification_for(rig_with_vector(rig, moved))

        def retriangulated(data, rect=rect):  # type: ignore[no-untyped-def]
            p = np.array([triangulate(rect, u[0], u[1]).p for u in data.samples.uv])
            return dataclasses.replace(data, samples=dataclasses.replace(data.samples, p=p))

        refit, _ = later_fit(retriangulated(rig_ref), retriangulated(plain_run))
        A.append(refit.x - base.x)  # per one sigma of this rig parameter
    A = np.array(A).T
    expected = noise + A @ A.T
    offsets = [k for k, n in enumerate(base.names) if n.startswith("joint_offsets.")
               and not base.fixed[k]]
    assert len(offsets) == 6  # q1 and q6 too: the reference gives them
    np.testing.assert_allclose(shared.std[offsets], np.sqrt(np.diag(expected))[offsets],
                               rtol=0.003)  # the old code: 1.3 % low


def test_shared_sensitivity_is_plus_the_estimate_change_per_shared_error(stereo_poses) -> None:  # type: ignore[no-untyped-def]
    """`parameter_shared_sensitivity` is +d x / d delta as documented: moving every measured
    point by D delta (and a prior block's value by its `shared_sensitivity` B times delta)
    and refitting moves x by (sensitivity) @ delta. A block whose B is written as
    documented (here measured by refits, not by that function) gets the refits' covariance:
    noise plus A S A^T, A the refitted change. The old code returned -d x / d delta and
    paired it with the same sign in the covariance: a B stated as +d value / d delta
    flipped the cross terms between the block's rig error and the samples'."""
    from hostpc.dataset import Dataset
    from hostpc.fitting.priors import with_prior_blocks
    from hostpc.fitting.shared_errors import parameter_shared_sensitivity

    rig, chosen, steps, S = _three_rig_errors()
    (plain_ref, rig_ref), (plain_run, rig_run) = _reference_and_run(rig, S, stereo_poses)

    def moved(data: Dataset, delta: np.ndarray) -> Dataset:  # the points moved by D delta
        problem = fit(data, cv_folds=0).problem
        shared = problem.measurement.shared_error(problem)
        assert shared is not None
        p = data.samples.p + np.einsum("nik,k->ni", shared.sensitivity, delta)
        return dataclasses.replace(data, samples=dataclasses.replace(data.samples, p=p))

    # the reference's tool frame and its B = +d tool / d delta, by refits
    recorded = fit(rig_ref, cv_folds=0)
    tool = [recorded.names.index(f"tool.{p}") for p in ("x", "y", "z", "rx", "ry", "rz")]
    B = np.zeros((6, N_RIG))
    for k, step in zip(chosen, steps, strict=True):
        delta = np.zeros(N_RIG)
        delta[k] = step
        B[:, k] = (fit(moved(rig_ref, delta), cv_folds=0).x[tool] - recorded.x[tool]) / step
    C_noise = fit(plain_ref, cv_folds=0).covariance[np.ix_(tool, tool)]
    C = C_noise + B @ S @ B.T

    def block(delta: np.ndarray, shared: bool = True) -> dict[str, object]:
        return {"names": [recorded.names[k] for k in tool],
                "value": (recorded.x[tool] + B @ delta).tolist(), "covariance": C.tolist(),
                **({"shared_sensitivity": B.tolist()} if shared else {})}

    zero = np.zeros(N_RIG)
    base = fit(with_prior_blocks(rig_run, [block(zero)]), cv_folds=0)
    sensitivity = parameter_shared_sensitivity(base.problem, base.x, ~base.fixed)
    assert sensitivity is not None
    A = []
    for k, step in zip(chosen, steps, strict=True):
        delta = np.zeros(N_RIG)
        delta[k] = step
        refit = fit(with_prior_blocks(moved(rig_run, delta), [block(delta)]), cv_folds=0)
        change = refit.x - base.x
        np.testing.assert_allclose(change, sensitivity @ delta, rtol=0.02,
                                   atol=0.02 * np.max(np.abs(change)))
        A.append(change)  # per one sigma of this rig parameter
    A = np.array(A).T
    # the noise: the same weights without the shared error, the block's rig part taken out
    plain = fit(with_prior_blocks(plain_run, [block(zero, shared=False)]), cv_folds=0)
    G = plain.covariance[:, tool] @ np.linalg.inv(C)
    expected = plain.covariance + G @ (C_noise - C) @ G.T + A @ A.T
    free = ~base.fixed
    np.testing.assert_allclose(base.std[free], np.sqrt(np.diag(expected))[free], rtol=0.003)
