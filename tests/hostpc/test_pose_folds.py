"""Cross-validation grouped by pose (hostpc.fitting.folds): the samples of one pose never
straddle folds, and the held-out figures do not depend on the order of the rows."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hostpc import fit
from hostpc.dataset import Dataset
from hostpc.fitting import fold_indices, pose_groups
from hostpc.fitting.folds import POSE_TOLERANCE_RAD
from tests.hostpc.diagnose_support import hidden_world_point


def _shuffled(dataset: Dataset, seed: int) -> Dataset:
    order = np.random.default_rng(seed).permutation(dataset.n_samples)
    return dataset.with_samples(dataset.samples.subset(order))


@pytest.fixture(scope="module")
def three_markers_per_pose() -> Dataset:
    """A laser tracker following three reflectors, all three seen in each of 24 poses."""
    return hidden_world_point({}, seed=4, n_samples=72, markers_per_pose=3).dataset


def test_the_markers_of_one_pose_share_a_fold(three_markers_per_pose: Dataset) -> None:
    samples = three_markers_per_pose.samples
    groups = pose_groups(samples)
    assert groups.max() + 1 == 24
    assert np.array_equal(groups[0::3], groups[1::3]) and np.array_equal(groups[0::3],
                                                                         groups[2::3])
    folds = fold_indices(samples, 5)
    assert folds is not None
    fold_of = np.empty(samples.n, dtype=int)
    for k, rows in enumerate(folds):
        fold_of[rows] = k
    for pose in range(24):
        assert np.unique(fold_of[groups == pose]).size == 1
    # whole poses are dealt evenly: 24 poses in 5 folds hold 4 or 5 poses each
    assert sorted(np.unique(groups[rows]).size for rows in folds) == [4, 5, 5, 5, 5]
    # three folds on a three-marker set: every fold still holds whole poses, not one marker
    three = fold_indices(samples, 3)
    assert three is not None
    assert all(len(set(samples.fields["marker"][rows])) == 3 for rows in three)


def test_shuffled_rows_give_the_same_held_out_figures(three_markers_per_pose: Dataset
                                                      ) -> None:
    original = fit(three_markers_per_pose)
    for seed in (1, 2):
        shuffled = fit(_shuffled(three_markers_per_pose, seed))
        assert original.cv_rms is not None and shuffled.cv_rms is not None
        assert shuffled.cv_rms == pytest.approx(original.cv_rms, rel=1e-9)
        assert shuffled.chi2 == pytest.approx(original.chi2, rel=1e-9)


def test_repeated_poses_read_back_with_encoder_noise_are_one_pose() -> None:
    dataset = hidden_world_point({}, seed=5, n_samples=40, markers_per_pose=2).dataset
    jitter = np.random.default_rng(0).uniform(-0.2, 0.2, dataset.samples.q.shape)
    samples = dataclasses.replace(dataset.samples,
                                  q=dataset.samples.q + jitter * POSE_TOLERANCE_RAD)
    groups = pose_groups(samples)
    assert groups.max() + 1 == 20
    assert np.array_equal(groups[0::2], groups[1::2])
    # the numbering is a function of the poses, not of the row order
    order = np.random.default_rng(3).permutation(samples.n)
    assert np.array_equal(pose_groups(samples.subset(order)), groups[order])


def test_too_few_poses_for_the_folds_gives_no_held_out_figure() -> None:
    dataset = hidden_world_point({}, seed=6, n_samples=27, markers_per_pose=3).dataset
    assert fold_indices(dataset.samples, 5) is None  # 9 poses < 2 per fold
    assert fit(dataset).cv_rms is None
    assert fold_indices(dataset.samples, 4) is not None


def test_a_candidate_row_takes_both_held_out_figures_from_one_model() -> None:
    """The star (whitened held-out RMS), the held-out mm column, the RMS and chi2/dof of a
    candidate, and the fit the ladder adopts, all come from one model: the whole effect, the
    model its advice (`--effects +geometry`) fits (before: the star and the mm from the
    selected subset on 3 folds, the RMS and chi2/dof from the whole effect). A subset with
    the rest held at nominal is not the row's model: holding parameters the data determine
    biases the zero offsets (tests/hostpc/test_diagnose_multi_effects.py)."""
    from pathlib import Path

    from hostpc.dataset import load_dataset
    from hostpc.diagnostics.candidates import try_candidate, with_held_out
    from hostpc.model.registry import available_effects

    example = Path(__file__).parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"
    dataset = load_dataset(example)
    base = fit(dataset)
    _, base_cv = with_held_out(base, 3)
    candidate = try_candidate(base, available_effects(())["geometry"](), cv_folds=3,
                              loss="linear", threshold=0.01, base_cv=base_cv)
    whole = fit(dataset, "+geometry", cv_folds=0)
    _, whole_whitened = with_held_out(whole, 3)
    assert candidate.cv_whitened_rms == pytest.approx(whole_whitened, rel=1e-9)
    _, row_whitened = with_held_out(candidate.fit, 3)
    assert candidate.cv_whitened_rms == row_whitened
    assert (candidate.rms, candidate.chi2_dof, candidate.cv_rms) == (
        candidate.fit.rms, candidate.fit.chi2_dof, candidate.fit.cv_rms)
    assert candidate.chi2_dof == pytest.approx(whole.chi2_dof, rel=1e-9)


def test_a_pose_measured_twice_with_read_back_noise_is_one_pose_in_the_held_out_figures(
) -> None:
    """A pose measured twice (its rows repeated) and read back with 1e-4 rad of noise per joint
    (3e-4 at most): the folds, and so the held-out figures, are those of the exact repeats.
    At the former 1e-4 rad tolerance the repeats split into two poses and the held-out RMS
    came out optimistic (review of the ninth stop)."""
    base = hidden_world_point({}, seed=7, n_samples=60, markers_per_pose=3).dataset
    twice = base.with_samples(base.samples.subset(np.concatenate([np.arange(base.n_samples)] * 2)))
    noise = np.clip(np.random.default_rng(1).normal(0.0, 1e-4, twice.samples.q.shape),
                    -3e-4, 3e-4)
    read_back = twice.with_samples(dataclasses.replace(twice.samples, q=twice.samples.q + noise))
    assert pose_groups(read_back.samples).max() + 1 == 20
    assert np.array_equal(pose_groups(read_back.samples), pose_groups(twice.samples))
    exact_folds, noisy_folds = fold_indices(twice.samples, 5), fold_indices(read_back.samples, 5)
    assert exact_folds is not None and noisy_folds is not None
    assert [sorted(f) for f in exact_folds] == [sorted(f) for f in noisy_folds]
