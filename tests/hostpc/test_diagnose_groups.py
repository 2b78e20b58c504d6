"""Per-group variables in the diagnosis: a group label (world_point's ``marker``,
sphere_probe's ``probe_group``, dual_loop's ``chain``) is tested per level, and a hidden
per-group offset (one laser-tracker marker surveyed 0.3 mm off) is found and named by its
group; nothing is flagged on clean data."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import hostpc
from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.diagnostics.interactions import modulators
from hostpc.diagnostics.residual_analysis import bin_pattern
from hostpc.kinematics import get_robot
from hostpc.model.context import group_variable
from hostpc.model.measurements.base import UR5E_HOME, example_poses
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.diagnose_support import sphere_contact_dataset

SIGMA = 2e-5  # m, a laser tracker
MARKERS = {"a": np.array([0.05, 0.0, 0.03]), "b": np.array([-0.02, 0.06, 0.05]),
           "c": np.array([0.0, -0.05, 0.08])}


def tracker_dataset(seed: int, marker_b_error: float,
                    marker_b_shifts: dict[str, float] | None = None) -> Dataset:
    """world_point, 30 poses x 3 markers, markers known (surveyed); the true marker b sits
    ``marker_b_error`` m off its surveyed position along the flange y axis, and marker b's
    samples are measured with the parameters ``marker_b_shifts`` (name: change in its SI
    unit) added to the truth (a setup that changed for that group)."""
    rng = np.random.default_rng(seed)
    q = np.repeat(example_poses(get_robot("ur5e"), UR5E_HOME, 30, rng, spread=0.6), 3, axis=0)
    n = q.shape[0]
    samples = Samples(q=q, p=np.zeros((n, 3)),
                      cov=np.broadcast_to(np.eye(3) * SIGMA**2, (n, 3, 3)),
                      fields={"marker": np.array(list(MARKERS) * (n // 3)),
                              "mask": np.ones((n, 3))})
    world = FramePose(xyz=np.array([1.5, -0.4, 0.2]), rpy=np.array([0.0, 0.0, 2.5]))
    dataset = Dataset(method="world_point", robot=RobotDescription(name="ur5e"),
                      frames={"world": world, "markers": dict(MARKERS)}, samples=samples)
    problem = build_problem(dataset)
    names = list(problem.layout.names)
    x = np.zeros(len(names))
    for k, name in enumerate(names):
        if name.startswith("joint_offsets."):
            x[k] = rng.uniform(-1, 1) * np.deg2rad(0.3)
        elif name.startswith("world."):
            x[k] = rng.uniform(-1, 1) * 0.002
    x[names.index("markers.b.y")] = marker_b_error
    y, _ = predict(problem, x, jacobian=False)
    if marker_b_shifts:
        shifted = x.copy()
        for name, shift in marker_b_shifts.items():
            shifted[names.index(name)] += shift
        rows = samples.fields["marker"] == "b"
        y[rows] = predict(problem, shifted, jacobian=False)[0][rows]
    measured = replace(samples, p=y + rng.normal(0, SIGMA, y.shape))
    return replace(dataset.with_samples(measured), known=("markers",))


def test_group_labels_become_level_indices() -> None:
    codes, levels = group_variable(["b", "a", None, "b", ""])
    assert levels == ("b", "a")
    np.testing.assert_array_equal(codes[[0, 1, 3]], [0.0, 1.0, 0.0])
    assert np.isnan(codes[2]) and np.isnan(codes[4])


def test_a_group_label_is_binned_per_level_even_with_many_levels() -> None:
    rng = np.random.default_rng(0)
    codes = np.repeat(np.arange(9.0), 8)
    residuals = rng.normal(size=(codes.size, 1))
    residuals[codes == 7] += 2.0  # group "h" is off
    levels = tuple("abcdefghi")
    pattern = bin_pattern("session", codes, residuals, residuals, 6, 1e-3, levels)
    assert pattern.levels == levels and pattern.counts.tolist() == [8] * 9
    assert pattern.significant
    strongest = pattern.strongest_level
    assert strongest is not None and strongest[0] == "h"
    numeric = bin_pattern("session", codes, residuals, residuals, 6, 1e-3)
    assert numeric.levels == () and numeric.counts.size == 6  # as a number: quantile bins
    F, basis = modulators("session", np.where(codes < 8, codes, np.nan), categorical=True)
    assert basis == "per level" and F.shape == (codes.size, 8)
    assert np.all(F[codes == 8] == 0.0)  # unlabelled samples: not in the test
    np.testing.assert_allclose(F[codes < 8].mean(axis=0), 0.0, atol=1e-12)


def test_the_contexts_declare_their_groups() -> None:
    tracker = build_problem(tracker_dataset(0, 0.0)).context
    assert tracker.categorical == {"marker": ("a", "b", "c")}
    sphere = build_problem(sphere_contact_dataset({}, n_samples=20)).context
    assert sphere.categorical["probe_group"] == ("0", "1", "2", "3")
    np.testing.assert_array_equal(sphere.variables["probe_group"], np.arange(20) // 5)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_mis_surveyed_marker_is_found_and_named(seed: int) -> None:
    diagnosis = hostpc.diagnose(tracker_dataset(seed, 3e-4))
    pattern = next(p for p in diagnosis.residuals.patterns if p.variable == "marker")
    assert pattern.significant and pattern.levels == ("a", "b", "c")
    assert pattern.strongest_level is not None and pattern.strongest_level[0] == "b"
    top = diagnosis.check.interactions[0]
    assert top.significant and top.variable == "marker" and top.basis == "per level"
    assert not diagnosis.check.adequacy.adequate
    advice = " ".join(diagnosis.advice)
    assert "the samples of marker b are off by" in advice
    assert "the samples of marker b disagree with the others" in advice


@pytest.mark.parametrize("shift", [5e-4, -5e-4])
def test_the_level_shifts_are_the_parameter_change_of_that_group(shift: float) -> None:
    """world.x off by ``shift`` on marker b's samples only: against the mean of the three
    markers, b's world.x is +2/3 shift and a's and c's -1/3 shift (the sign of the change
    that explains the data, not of the residuals)."""
    diagnosis = hostpc.diagnose(tracker_dataset(0, 0.0, {"world.x": shift}))
    top = diagnosis.check.significant_interactions[0]
    assert (top.parameter, top.variable, top.unit) == ("world.x", "marker", "m")
    shifts = dict(top.level_shifts)
    assert shifts["b"] == pytest.approx(2 * shift / 3, rel=0.1)
    assert shifts["a"] == pytest.approx(-shift / 3, rel=0.15)
    assert shifts["c"] == pytest.approx(-shift / 3, rel=0.15)
    advice = " ".join(diagnosis.advice)
    assert "the samples of marker b disagree with the others" in advice
    assert f"'b' {shifts['b'] * 1e3:+.3g} mm" in advice


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nothing_is_flagged_on_clean_tracker_data(seed: int) -> None:
    diagnosis = hostpc.diagnose(tracker_dataset(seed, 0.0))
    assert diagnosis.check.adequacy.adequate
    assert not any(p.significant for p in diagnosis.residuals.patterns)
    assert not any(i.significant for i in diagnosis.check.interactions)


def lobing_dataset(seed: int, group_error: float) -> Dataset:
    """sphere_probe contacts (12 probe orientations of 5) where the probe of orientation 3
    triggers ``group_error`` m late (touch-probe lobing): its contacts are that much
    closer to the sphere centre than the model says."""
    dataset = sphere_contact_dataset({}, seed=seed)
    problem = build_problem(dataset)
    _, J = predict(problem, np.zeros(problem.layout.size))
    assert J is not None
    dq = J[:, 0, problem.layout.effect_slices["joint_offsets"]]
    rows = np.asarray(dataset.samples.group) == 3
    step = np.zeros_like(dataset.samples.q)
    step[rows] = group_error * dq[rows] / np.sum(dq[rows] ** 2, axis=1, keepdims=True)
    return replace(dataset, samples=replace(dataset.samples, q=dataset.samples.q + step))


@pytest.mark.parametrize("seed", [0, 1])
def test_one_probe_orientation_off_is_named_by_its_group(seed: int) -> None:
    found = hostpc.diagnose(lobing_dataset(seed, 2e-5))
    pattern = next(p for p in found.residuals.patterns if p.variable == "probe_group")
    assert pattern.significant and pattern.strongest_level is not None
    assert pattern.strongest_level[0] == "3"
    assert "the samples of probe_group 3 are off by" in " ".join(found.advice)
    clean = hostpc.diagnose(lobing_dataset(seed, 0.0))
    assert not any(p.significant for p in clean.residuals.patterns)
