"""Held-out figures of a default dual_loop run keep each capture's two arms in one fold.

The default plan measures both arms at every pose (one move, one capture: the left and the
right sample share ``q_head`` and ``t``). Each sample holds only its own arm's joints, so a
grouping by joint state alone put the two samples of one pose in different folds (41 of 52
poses split): the fold holding one arm was predicted by a fit that had seen the other arm's
sample of the same head pose. The dataset is a real run of ``hostpc calibrate --robot sim
--method dual_loop`` (the simulated controller over loopback)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import Dataset, Samples, load_dataset
from hostpc.diagnostics.repeats import repeat_pairs
from hostpc.fitting.folds import fold_indices, pose_groups
from hostpc.model.problem import build_problem


@pytest.fixture(scope="module")
def dual_run(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    out = tmp_path_factory.mktemp("dual") / "run"
    code = main(["calibrate", "--robot", "sim", "--method", "dual_loop", "--out", str(out),
                 "--no-push", "--no-report"])
    assert code == 0
    return load_dataset(out / "dataset.json")


def captures(samples: Samples) -> np.ndarray:
    """(N,) the capture of each sample: its head state and time."""
    assert samples.q_head is not None
    keys = np.column_stack([samples.q_head, samples.t])
    _, index = np.unique(keys, axis=0, return_inverse=True)
    return np.ravel(index)


def test_both_arms_of_one_capture_share_a_pose_and_a_fold(dual_run: Dataset) -> None:
    samples = dual_run.samples
    capture = captures(samples)
    n_captures = int(capture.max()) + 1
    assert samples.n >= 1.9 * n_captures  # both arms at (nearly) every pose
    groups = pose_groups(samples)
    assert int(groups.max()) + 1 == n_captures
    for c in range(n_captures):
        assert np.unique(groups[capture == c]).size == 1
    folds = fold_indices(samples, 5)
    assert folds is not None
    fold = np.empty(samples.n, dtype=np.int64)
    for k, indices in enumerate(folds):
        fold[indices] = k
    split = [c for c in range(n_captures) if np.unique(fold[capture == c]).size > 1]
    assert not split, f"{len(split)} of {n_captures} poses split across folds"
    # the two arms of one pose are two measurements, not one measured twice
    assert repeat_pairs(build_problem(dual_run, "joint_offsets")).size == 0


def test_one_arm_per_pose_folds_each_sample_alone(dual_run: Dataset) -> None:
    """An older dataset (one arm per pose, each pose its own head state and time) folds as
    before: every sample its own pose. A pose measured again (same joints, later time)
    joins its first measurement, and its repeat pair is the same arm's."""
    samples = dual_run.samples
    assert samples.chain is not None
    capture = captures(samples)
    first = np.flatnonzero(np.r_[True, capture[1:] != capture[:-1]])
    one_arm = samples.subset(first)
    assert np.array_equal(np.sort(pose_groups(one_arm)), np.arange(one_arm.n))
    # the first capture measured again a minute later, both arms
    again = np.flatnonzero(capture == capture[0])
    both = samples.subset(np.r_[np.arange(samples.n), again])
    t = both.t.copy()
    t[samples.n:] += 60.0
    both = replace(both, t=t)
    groups = pose_groups(both)
    assert int(groups.max()) + 1 == int(capture.max()) + 1
    assert np.unique(groups[np.r_[again, samples.n + np.arange(again.size)]]).size == 1
    pairs = repeat_pairs(build_problem(replace(dual_run, samples=both), "joint_offsets"))
    assert {tuple(sorted(p)) for p in pairs.tolist()} == {
        (int(i), samples.n + k) for k, i in enumerate(again)}


def test_one_time_and_head_for_every_sample_names_no_capture(dual_run: Dataset) -> None:
    """A file with a fixed head and the same ``t`` on every sample (a user's export without
    times) does not become one pose: its key holds each arm many times, so it names no
    capture and the samples group by their joints alone, as before captures were known."""
    samples = dual_run.samples
    assert samples.q_head is not None
    flat = replace(samples, t=np.zeros(samples.n),
                   q_head=np.repeat(samples.q_head[:1], samples.n, axis=0))
    groups = pose_groups(flat)
    assert int(groups.max()) + 1 == samples.n
    folds = fold_indices(flat, 5)
    assert folds is not None and len(folds) == 5
