"""The humanoid head camera's calibration error in the dual_loop fit (docs/vision.md 3.4).

The simulated controller triangulates with its own, erring calibration of the pair and
reports that calibration with its covariance and each target's pixels; the host re-derives
the points' sensitivity to the calibration (hostpc.vision.rig_uncertainty) and propagates
it into the fit's covariance (hostpc.fitting.shared_errors)."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

import hostpc
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.sensors.dual_loop import CALIBRATION_PARAMETERS, StereoTriangulator
from controller_stub.world.simulation import create_simulation
from hostpc.dataset import dataset_from_dict
from hostpc.errors import InputError
from hostpc.kinds.dual_loop.method import camera_calibration
from hostpc.kinds.dual_loop.planning import nominal_frames, plan_poses
from hostpc.vision.rectification import rectification_for
from hostpc.vision.rig import rig_from_dict
from hostpc.vision.rig_uncertainty import (
    RIG_PARAMETERS,
    point_sensitivity,
    uncertainty_document,
)
from hostpc.vision.triangulation import triangulate

# per camera fx, fy, cx, cy and the baseline: (px, m)
ERROR = np.array([0.3, -0.2, 0.25, -0.15, -0.1, 0.35, -0.3, 0.2, 2e-5])
SIGMA = np.array([0.2] * 8 + [1e-5])


def stereo() -> StereoTriangulator:
    return StereoTriangulator(1400.0, 0.12, 1280, 1024, 0.15, ERROR, SIGMA)


def test_reported_calibration_triangulates_as_the_controller_does() -> None:
    """The host's rig (from the reported document) turns the reported pixels into the
    reported point: the document describes the calibration the controller used."""
    pair = stereo()
    rig = rig_from_dict(pair.calibration()["rig"], "calibration")
    rng = np.random.default_rng(4)
    for p_true in ([0.05, -0.03, 0.5], [-0.12, 0.08, 0.35], [0.1, 0.1, 0.7]):
        p, _, uv = pair.measure(np.array(p_true), rng)
        np.testing.assert_allclose(triangulate(rectification_for(rig), uv[0], uv[1]).p, p,
                                   atol=1e-9)


def test_point_sensitivity_matches_the_controllers_own_triangulation() -> None:
    """dp/dcalibration from the host's rig (central differences of its triangulation)
    against central differences of the stub's independent triangulation."""
    pair = stereo()
    document = pair.calibration()
    rig = rig_from_dict(document["rig"], "calibration")
    uv = np.stack([pair.project(np.array(p)).reshape(2, 2) for p in
                   ([0.05, -0.03, 0.5], [-0.12, 0.08, 0.35])])
    D = point_sensitivity(rig, uv)
    column = {name: RIG_PARAMETERS.index(name) for name in RIG_PARAMETERS}
    for k, name in enumerate(CALIBRATION_PARAMETERS):
        step = 1e-6 if name == "baseline" else 1e-3
        moved = []
        for sign in (1.0, -1.0):
            other = stereo()
            other.calibrated = pair.calibrated.copy()
            other.calibrated[k] += sign * step
            moved.append(np.array([other.triangulate(u.ravel())[0] for u in uv]))
        expected = (moved[0] - moved[1]) / (2 * step)
        # the rig's translation is T = (-b, 0, 0): d/db = -d/dT_x
        got = -D[:, :, column["stereo.tx"]] if name == "baseline" else D[:, :, column[name]]
        np.testing.assert_allclose(got, expected, rtol=2e-4, atol=1e-12 / step)
    assert not np.allclose(D[:, :, column["left.k1"]], 0.0)  # distortion acts
    S = np.asarray(document["covariance"])
    assert S[column["left.fx"], column["left.fx"]] == pytest.approx(0.04)
    assert S[column["stereo.tx"], column["stereo.tx"]] == pytest.approx(1e-10)
    assert S[column["left.k1"], column["left.k1"]] == 0.0


def test_malformed_calibration_is_one_line() -> None:
    good = stereo().calibration()
    assert camera_calibration(None) is None
    assert camera_calibration(good) is not None
    for broken in ("nonsense", {**good, "covariance": [[1.0]]},
                   {**good, "covariance": (-np.eye(24)).tolist()},
                   {**good, "rig": {"format": "x"}}):
        with pytest.raises(InputError) as info:
            camera_calibration(broken)
        assert "\n" not in str(info.value)


def test_a_calibration_with_a_zero_focal_length_or_baseline_is_refused() -> None:
    """Review finding: fx = 0 was accepted, the floor then divided by zero and the
    calibration term was dropped without a word."""
    good = stereo().calibration()
    for field, value in (("K_left", 0.0), ("K_right", -1.0), ("T", 0.0)):
        rig = dict(good["rig"])
        if field == "T":
            rig["T"] = [0.0, 0.0, 0.0]
        else:
            K = [list(row) for row in rig[field]]
            K[0][0] = value
            rig[field] = K
        with pytest.raises(InputError, match=field):
            camera_calibration({**good, "rig": rig})


def world_documents(seed: int, poses: Any, calibration_sigma_px: float,
                    calibrated: np.ndarray | None = None) -> tuple[dict[str, Any], np.ndarray]:
    """A dual_loop dataset measured in simulated world `seed` at the planned poses (the
    controller's uv and calibration block included), and the true zero errors. calibrated:
    (9,) replaces the controller's calibration (same pixel noise)."""
    scenario = scenario_from_dict({
        "robot": "humanoid_upper", "seed": seed, "truth": {"zero_errors": {"random_deg": 0.5}},
        "humanoid": {"calibration_sigma_px": calibration_sigma_px,
                     "calibration_sigma_baseline": 2e-5}})
    sim = create_simulation(scenario)
    if calibrated is not None:
        sim.stereo.calibrated = np.asarray(calibrated, dtype=float)
    samples = []
    home = sim.joint_positions()
    for side, q_head, q_arm in zip(poses.chain, poses.q_head, poses.q_arm, strict=True):
        q = home.copy()
        q[0:2] = q_head
        q[2:9] = q_arm if side == "left" else q[2:9]
        q[9:16] = q_arm if side == "right" else q[9:16]
        sim.move_joints(q, 1.0)
        seen = sim.targets.measure_targets()["targets"].get(str(side))
        if seen is None:
            continue
        samples.append({"chain": str(side), "q_head": list(q_head), "q_arm": list(q_arm),
                        "p": seen["p"].tolist(), "cov": seen["cov"].tolist(),
                        "uv": seen["uv"].tolist()})
    frames = {k: (v.tolist() if isinstance(v, np.ndarray) else
                  {"xyz": v.xyz.tolist(), "rpy": v.rpy.tolist()})
              for k, v in nominal_frames("humanoid_upper").items()}
    calibration = sim.camera_description()["calibration"]
    rig = rig_from_dict(calibration["rig"], "calibration")
    document = {"format": "zerocal-dataset/1", "method": "dual_loop",
                "units": {"length": "m", "angle": "rad", "time": "s"},
                "robot": {"name": "humanoid_upper"}, "frames": frames, "known": [],
                "samples": samples,
                "rig_uncertainty": uncertainty_document(rig, calibration["covariance"])}
    return document, np.asarray(sim.truth()["zero_errors"])


def test_added_covariance_equals_refits_with_a_perturbed_controller_calibration() -> None:
    """The covariance the head camera calibration adds to the dual_loop fit equals
    A S A^T, A measured by letting the controller triangulate the same pixels with its
    calibration moved by one sigma per parameter and refitting; the estimate is unchanged."""
    poses = plan_poses(12, np.random.default_rng(5))
    pair = create_simulation(scenario_from_dict({
        "robot": "humanoid_upper", "seed": 7,
        "humanoid": {"calibration_sigma_px": 0.2, "calibration_sigma_baseline": 2e-5}})).stereo
    exact = pair.calibrated - pair.calibration_error  # no excess residual: S unscaled
    base_document, _ = world_documents(7, poses, 0.2, exact)
    plain = copy.deepcopy(base_document)
    plain.pop("rig_uncertainty")
    base = hostpc.fit(dataset_from_dict(plain), cv_folds=0)
    shared = hostpc.fit(dataset_from_dict(base_document), cv_folds=0)
    np.testing.assert_array_equal(base.x, shared.x)
    A = []
    for k, sigma in enumerate(pair.calibration_sigma):
        moved = exact.copy()
        moved[k] += sigma
        document, _ = world_documents(7, poses, 0.2, moved)
        document.pop("rig_uncertainty")
        A.append(hostpc.fit(dataset_from_dict(document), cv_folds=0).x - base.x)
    A = np.array(A).T
    expected = base.covariance + A @ A.T
    free = ~base.fixed
    assert np.max(shared.std[free] / base.std[free]) > 1.3  # the term matters here
    np.testing.assert_allclose(shared.std[free], np.sqrt(np.diag(expected))[free], rtol=0.03)


def test_dual_loop_sigma_covers_the_head_camera_calibration_error() -> None:
    """Over a few simulated worlds whose head camera calibration errs (3x the default),
    the offsets err more than the noise-only sigma says; with the propagated calibration
    covariance the sigma is larger (up to 3x, elbow joints) and MSE / sigma^2 comes back
    near 1 (wide band: six worlds, pooled over the ten identifiable offsets)."""
    poses = plan_poses(20, np.random.default_rng(11))
    labels = ["head.q1", "head.q2"] + [f"{s}.q{j}" for s in ("left", "right")
                                       for j in range(1, 8)]
    z_with, z_without, growth = [], [], []
    for seed in range(6):
        document, truth = world_documents(100 + seed, poses, 0.3)
        plain = copy.deepcopy(document)
        plain.pop("rig_uncertainty")
        with_block = hostpc.fit(dataset_from_dict(document), cv_folds=0)
        without = hostpc.fit(dataset_from_dict(plain), cv_folds=0)
        for k, label in enumerate(labels):
            name = f"joint_offsets.{label}"
            a, b = with_block.parameters[name], without.parameters[name]
            if a.fixed or a.std is None or not math.isfinite(a.std):
                continue
            error = a.value - truth[k]  # identifiable offsets: the raw zero errors
            z_with.append(error / a.std)
            z_without.append(error / b.std)
            growth.append(a.std / b.std)
    assert len(z_with) == 60
    assert np.min(growth) >= 1.0 - 1e-9 and np.max(growth) > 1.5
    ratio_without = float(np.mean(np.square(z_without)))
    ratio_with = float(np.mean(np.square(z_with)))
    # fixed seeds (deterministic): measured 1.78 without, 0.62 with; honest is 1, and a
    # 6-world estimate whose errors are correlated within a world allows a wide band
    assert ratio_without > 1.5, ratio_without  # the noise-only sigma does not cover it
    assert 0.4 < ratio_with < 1.5, ratio_with


def test_target_observation_pixels_are_optional_and_checked() -> None:
    from pydantic import ValidationError

    from protocol.measurement_messages import TargetObservation

    point = {"chain": "left", "p": [0.0, 0.0, 0.5], "cov": np.eye(3).tolist()}
    assert TargetObservation(**point).uv is None
    assert TargetObservation(**point, uv=[[1.0, 2.0], [3.0, 4.0]]).uv == [[1.0, 2.0], [3.0, 4.0]]
    for broken in ([[1.0, 2.0, 3.0], [3.0, 4.0]], [[1.0, 2.0]], [[1.0, float("nan")], [3.0, 4.0]]):
        with pytest.raises(ValidationError):
            TargetObservation(**point, uv=broken)


def test_method_floor_is_the_floor_the_fit_takes_back_out(tmp_path: Any) -> None:
    """The floor dual_loop adds to each sample (calibrated focal length and baseline) is
    the covariance the fit's shared error removes (the stereo kinds' floor_covariance), for a
    calibration far from the nominal 1400 px / 0.12 m."""
    from hostpc.kinds.dual_loop.method import DualLoopMethod
    from hostpc.kinds.stereo_target.rig_block import BLOCK
    from hostpc.kinds.stereo_target.shared_error import rig_floor_covariance as floor_covariance
    from hostpc.methods.base import RunSettings
    from hostpc.methods.cell import build_cell
    from hostpc.model.problem import build_problem

    pair = StereoTriangulator(1500.0, 0.1, 1280, 1024, 0.15, ERROR, SIGMA)
    cell = build_cell({"calibration": pair.calibration()}, "humanoid_upper")
    method = DualLoopMethod(RunSettings(method="dual_loop", options={"pixel_floor": 0.02}),
                            cell, tmp_path)
    poses = plan_poses(3, np.random.default_rng(2))
    document, _ = world_documents(3, poses, 0.1)
    samples = []
    for sample in document["samples"]:
        floor = method.floor_covariance(np.asarray(sample["p"]))
        samples.append({**sample, "cov": (np.asarray(sample["cov"]) + floor).tolist()})
    dataset = dataset_from_dict(method.dataset_document(samples))
    assert dataset.extra_fields[BLOCK]["pixel_floor_px"] == 0.02
    removed = floor_covariance(build_problem(dataset, None), dataset.extra_fields[BLOCK])
    assert removed is not None
    for sample, taken in zip(samples, removed, strict=True):
        np.testing.assert_allclose(taken, method.floor_covariance(np.asarray(sample["p"])),
                                   rtol=1e-12)
