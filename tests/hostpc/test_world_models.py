"""world_point and world_pose (dataset-format extension A): simulated round trips with a
known truth (random offsets, world, markers / tool), the Monte-Carlo spread against the
reported sigma, identifiability in words, and their dataset files."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.dataset import Dataset, dataset_from_dict, dataset_to_dict, load_dataset, save_dataset
from hostpc.errors import DatasetError
from hostpc.fitting import solve
from hostpc.fitting.stepwise import gauge_equivalent
from hostpc.kinds.world_point.model import WorldPoint
from hostpc.kinds.world_pose.model import WorldPose
from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix, rpy_to_matrix
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.test_dataset_errors import stereo

SIGMA_POINT = 2e-5    # m, a laser tracker
SIGMA_ANGLE = 1e-4    # rad, a 6-DoF probe


def random_truth(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """0.5 deg scale joint offsets, mm and mrad scale frames."""
    scale = {"rad": 0.01, "m": 0.003}
    x = np.array([rng.uniform(-1, 1) * scale[u] for u in problem.layout.units])
    for k, name in enumerate(problem.layout.names):
        if name.startswith("joint_offsets."):
            x[k] = rng.uniform(-1, 1) * np.deg2rad(0.5)
    return x


def measured_at(dataset: Dataset, x: np.ndarray, rng: np.random.Generator | None = None
                ) -> Dataset:
    """The dataset with its measurements replaced by the model's at x (plus noise)."""
    problem = build_problem(dataset)
    y, _ = predict(problem, x, jacobian=False)
    samples = dataset.samples
    n = samples.n
    noise = np.zeros((n, 6)) if rng is None else np.concatenate(
        [rng.normal(0, SIGMA_POINT, (n, 3)), rng.normal(0, SIGMA_ANGLE, (n, 3))], axis=1)
    p = y[:, :3] + noise[:, :3]
    if dataset.method == "world_point":
        cov = np.broadcast_to(np.eye(3) * SIGMA_POINT**2, (n, 3, 3))
        return dataset.with_samples(replace(samples, p=p, cov=cov))
    R_meas = rpy_to_matrix(samples.fields["rpy"])
    R_true = rotvec_to_matrix(y[:, 3:]) @ R_meas
    rpy = matrix_to_rpy(rotvec_to_matrix(noise[:, 3:]) @ R_true)
    cov = np.diag([SIGMA_POINT**2] * 3 + [SIGMA_ANGLE**2] * 3)
    fields = dict(samples.fields, rpy=rpy, pose_cov=np.broadcast_to(cov, (n, 6, 6)))
    return dataset.with_samples(replace(samples, p=p, fields=fields))


@pytest.mark.parametrize("model", [WorldPoint, WorldPose])
def test_noise_free_round_trip_recovers_the_truth_in_the_fits_gauge(model: Any) -> None:
    rng = np.random.default_rng(7)
    example = model.example(rng)
    x_truth = random_truth(build_problem(example), rng)
    exact = measured_at(example, x_truth)
    result = solve(build_problem(exact), cv_folds=0)
    assert result.converged
    held = {result.names[k] for k in np.flatnonzero(result.fixed)}
    assert held == {"joint_offsets.q1", "joint_offsets.q6"}
    expected = gauge_equivalent(result.problem, x_truth, result.fixed)
    assert np.max(np.abs(result.x - expected)) < 1e-9
    # the identifiable offsets are the truth itself (the gauge only moves the frames)
    for j in (2, 3, 4, 5):
        k = result.problem.layout.index(f"joint_offsets.q{j}")
        assert abs(result.x[k] - x_truth[k]) < 1e-9
    words = " ".join(d.description for d in result.unidentifiable)
    assert "joint_offsets.q1 and world.rz are not separable" in words
    assert "mark world as known" in words


@pytest.mark.parametrize("model", [WorldPoint, WorldPose])
def test_with_world_and_flange_frame_known_all_six_offsets_are_identified(model: Any) -> None:
    rng = np.random.default_rng(8)
    example = model.example(rng)
    flange_frame = "markers" if model is WorldPoint else "tool"
    known = replace(example, known=("world", flange_frame))
    problem = build_problem(known)
    assert problem.effect_names == ("joint_offsets",)
    x_truth = random_truth(problem, rng)
    result = solve(build_problem(measured_at(known, x_truth)), cv_folds=0)
    assert result.converged and not result.unidentifiable
    assert np.max(np.abs(result.x - x_truth)) < 1e-9


@pytest.mark.parametrize("model", [WorldPoint, WorldPose])
def test_monte_carlo_spread_matches_the_reported_sigma(model: Any) -> None:
    rng = np.random.default_rng(9)
    example = model.example(rng)
    x_truth = random_truth(build_problem(example), rng)
    estimates, sigmas = [], []
    for _ in range(120):
        result = solve(build_problem(measured_at(example, x_truth, rng)), cv_folds=0)
        assert result.converged
        estimates.append(result.x)
        sigmas.append(result.std)
    names = result.problem.layout.names
    spread = np.std(np.array(estimates), axis=0, ddof=1)
    reported = np.median(np.array(sigmas), axis=0)
    for j in (2, 3, 4, 5):
        k = names.index(f"joint_offsets.q{j}")
        assert 0.8 < spread[k] / reported[k] < 1.2, (names[k], spread[k], reported[k])


def test_world_point_file_round_trip_with_markers_mask_and_units(tmp_path: Path) -> None:
    dataset = WorldPoint.example(np.random.default_rng(1))
    path = tmp_path / "tracker.json"
    save_dataset(dataset, path)
    assert load_dataset(path) == dataset
    doc = dataset_to_dict(dataset)
    assert doc["samples"][5]["mask"] == [1, 1, 0] and doc["samples"][0]["marker"] == "a"
    mm = copy.deepcopy(doc)
    mm["units"] = {"length": "mm", "angle": "deg", "time": "s"}
    mm["frames"]["markers"]["a"] = [50.0, 0.0, 30.0]
    assert np.allclose(dataset_from_dict(mm).frames["markers"]["a"], [0.05, 0.0, 0.03])


def test_world_pose_file_takes_a_6x6_covariance_or_two_sigmas() -> None:
    doc = dataset_to_dict(WorldPose.example(np.random.default_rng(2)))
    sample = doc["samples"][0]
    assert len(sample["cov"]) == 6
    mm = copy.deepcopy(doc)
    mm["units"] = {"length": "mm", "angle": "deg", "time": "s"}
    for s in mm["samples"]:
        s["q"] = list(np.rad2deg(s["q"]))
        s["rpy"] = list(np.rad2deg(s["rpy"]))
        s["p"] = [1000 * v for v in s["p"]]
        del s["cov"]
        s["sigma"] = 0.01
        s["sigma_angle"] = 0.005
    loaded = dataset_from_dict(mm)
    cov = loaded.samples.fields["pose_cov"][0]
    assert np.allclose(np.diag(cov), [1e-10] * 3 + [np.deg2rad(0.005) ** 2] * 3)
    assert np.allclose(loaded.samples.fields["rpy"], dataset_from_dict(doc).samples.fields["rpy"])


def _broken(doc: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    target = out
    for key in path[:-1]:
        target = target[key]
    if value is None:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return out


POINT_DOC = dataset_to_dict(WorldPoint.example(np.random.default_rng(3)))
POSE_DOC = dataset_to_dict(WorldPose.example(np.random.default_rng(3)))


@pytest.mark.parametrize(("doc", "path", "value", "message"), [
    (POINT_DOC, ("samples", 0, "marker"), None, r"samples\[0\]\.marker: required field missing"),
    (POINT_DOC, ("samples", 1, "marker"), "z", r"samples\[1\]\.marker: no marker 'z'"),
    (POINT_DOC, ("samples", 2, "mask"), [1, 2, 0], r"samples\[2\]\.mask\[1\]: expected 0 or 1"),
    (POINT_DOC, ("samples", 2, "mask"), [0, 0, 0], r"samples\[2\]\.mask: no axis measured"),
    (POINT_DOC, ("frames", "markers"), {}, r"frames\.markers: expected at least one"),
    (POINT_DOC, ("samples", 0, "uv"), [[1, 2], [3, 4]], r"samples\[0\]\.uv: not a field"),
    (POSE_DOC, ("samples", 0, "rpy"), None, r"samples\[0\]\.rpy: required field missing"),
    (POSE_DOC, ("samples", 0, "cov"), [[1e-8, 0, 0], [0, 1e-8, 0], [0, 0, 1e-8]],
     r"samples\[0\]\.cov: expected a 6x6 matrix"),
    (POSE_DOC, ("samples", 0, "cov"), None, r"samples\[0\]\.cov: required field missing"),
    (POSE_DOC, ("samples", 0, "rpy"), [0, "x", 0], r"samples\[0\]\.rpy\[1\]: expected a number"),
])
def test_bad_world_files_name_the_sample_and_field(doc: dict[str, Any], path: tuple[Any, ...],
                                                   value: Any, message: str) -> None:
    with pytest.raises(DatasetError, match=message):
        dataset_from_dict(_broken(doc, path, value))


def test_a_stereo_sample_with_a_6x6_covariance_is_refused() -> None:
    doc = stereo()
    doc["samples"][0]["cov"] = (np.eye(6) * 1e-8).tolist()
    with pytest.raises(DatasetError, match=r"samples\[0\]\.cov: expected a 3x3 matrix"):
        dataset_from_dict(doc)


def test_the_world_point_example_in_the_format_docs_loads() -> None:
    import json
    import re

    text = (Path(__file__).resolve().parents[2] / "docs" / "dataset-format.md").read_text()
    blocks = [b for b in re.findall(r"```json\n(.*?)```", text, re.S) if "world_point" in b]
    dataset = dataset_from_dict(json.loads(blocks[0]))
    assert list(dataset.samples.fields["marker"]) == ["a", "b"]
    assert np.allclose(dataset.frames["markers"]["b"], [-0.02, 0.06, 0.05])
    assert np.array_equal(dataset.samples.fields["mask"][1], [1.0, 1.0, 0.0])


@pytest.mark.parametrize("model", [WorldPoint, WorldPose])
def test_diagnose_with_every_candidate_and_the_ladder(model: Any) -> None:
    from hostpc.diagnostics import diagnose

    rng = np.random.default_rng(10)
    example = model.example(rng)
    dataset = measured_at(example, random_truth(build_problem(example), rng), rng)
    found = diagnose(dataset, ladder=True, cv_folds=3, rank_cv_folds=0)
    tried = {c.effect for c in found.candidates}
    assert {"geometry", "joint_compliance", "backlash", "encoder_scale"} <= tried
    assert found.adequate and found.ladder is not None
    assert "depth" not in found.check.fit.problem.context.variables
    document = found.to_dict()
    assert document["fit"]["method"] == model.name
