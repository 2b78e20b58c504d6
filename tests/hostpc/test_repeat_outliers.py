"""Repeated poses as the direct test of measurement consistency (hostpc.diagnostics.repeats):
repeats that disagree beyond the noise are named; repeats that agree are one pose, tested as
one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hostpc import fit
from hostpc.diagnostics.outliers import find_outliers
from hostpc.diagnostics.repeats import check_repeats
from hostpc.fitting.fitting import solve
from hostpc.model.measurements.base import UR5E_HOME
from tests.hostpc.diagnose_support import hidden_world_point


def _refit(result, keep):
    return solve(result.problem.subset(keep), x0=result.x, cv_folds=0)


@pytest.fixture(scope="module")
def repeated():
    """20 tracker poses, each measured twice, three reflectors seen in each (120 samples)."""
    rng = np.random.default_rng(21)
    q = UR5E_HOME + rng.uniform(-1.0, 1.0, (20, 6)) * [0.8, 0.5, 0.5, 0.8, 0.8, 1.2]
    return hidden_world_point({}, seed=21, n_samples=120, markers_per_pose=3,
                              poses=np.repeat(q, 2, axis=0)).dataset


def _shifted(dataset, rows, shift):
    p = np.array(dataset.samples.p)
    p[rows] += shift
    return dataset.with_samples(dataclasses.replace(dataset.samples, p=p))


def test_clean_repeats_agree(repeated) -> None:
    result = fit(repeated)
    check = check_repeats(result.problem, 0.01)
    assert len(check.pairs) == 60  # 20 poses x 3 reflectors, one pair each
    assert not check.disagreeing.any()
    outliers, _ = find_outliers(result, 0.01, _refit)
    assert outliers == ()


def test_a_repeat_that_disagrees_is_named(repeated) -> None:
    # sample 31 (pose 5's second visit, reflector b) read 2 mm off: a glitch
    glitch = _shifted(repeated, [31], [0.0, 0.002, 0.0])
    outliers, _ = find_outliers(fit(glitch), 0.01, _refit)
    assert [o.sample for o in outliers] == [31]
    assert outliers[0].test == "repeat"


def test_a_pose_read_wrong_the_same_way_twice_is_named_as_that_pose(repeated) -> None:
    # both visits of pose 7 (rows 42-47) read 0.3 mm off the same way: the repeats agree,
    # which shows the instrument repeated its reading, not that the pose is good. Before,
    # agreeing repeats were never flagged, and the one-sample test could not see them (the
    # fit that saw one visit predicts the other); the pose is now tested as one
    consistent = _shifted(repeated, list(range(42, 48)), [0.0003, 0.0, 0.0])
    result = fit(consistent)
    assert not check_repeats(result.problem, 0.01).disagreeing.any()
    outliers, _ = find_outliers(result, 0.01, _refit)
    assert sorted(o.sample for o in outliers) == list(range(42, 48))
    assert {o.test for o in outliers} == {"pose"}
