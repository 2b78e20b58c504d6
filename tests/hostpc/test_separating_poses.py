"""The separating plan (hostpc.planning.separate) on a small linear world: two candidate
columns a and b that the measured rows cannot tell apart (equal there); pool poses where
they differ by known amounts. The plan takes the fewest groups that give both nested tests
their needed noncentrality, the most telling first, and says when the pool cannot."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.planning.separate import separating_poses

SIGNAL_A = np.array([0.0, 1.0, 0.0])  # columns: model, a, b; A's fitted value 1
SIGNAL_B = np.array([0.0, 0.0, 1.0])
ABSORB_A = np.array([True, False, True])  # A given B: the model and B absorb
ABSORB_B = np.array([True, True, False])


def _lambda(signal: np.ndarray, absorb: np.ndarray, rows: np.ndarray) -> float:
    s = rows @ signal
    X = rows[:, absorb]
    return float(np.sum((s - X @ np.linalg.lstsq(X, s, rcond=None)[0]) ** 2))


def criterion(rows: np.ndarray) -> tuple[float, float]:
    return _lambda(SIGNAL_A, ABSORB_A, rows), _lambda(SIGNAL_B, ABSORB_B, rows)


def _pose(model: float, a: float, b: float) -> np.ndarray:
    return np.array([[model, a, b]])


MEASURED = np.array([[1.0, 1.0, 1.0], [1.0, 2.0, 2.0], [0.5, 1.0, 1.0]])


def test_confounded_rows_give_no_separation() -> None:
    assert criterion(MEASURED) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_the_fewest_most_telling_poses_are_taken() -> None:
    pool = np.stack([_pose(1.0, 1.0, 1.0), _pose(1.0, 4.0, 0.0), _pose(1.0, 1.5, 1.4),
                     _pose(1.0, 0.0, 4.0), _pose(1.0, 2.0, 0.0)])
    members = [np.array([i]) for i in range(pool.shape[0])]
    plan = separating_poses(MEASURED, pool, members, criterion, (2.0, 2.0), 10)
    assert plan.reached and plan.before == pytest.approx((0.0, 0.0), abs=1e-12)
    assert len(plan.indices) == 2 and 1 in plan.indices  # two poses that set a, b apart
    assert min(plan.after) >= 2.0
    one = separating_poses(MEASURED, pool, members, criterion, (1.2, 1.2), 10)
    assert one.indices.tolist() == [1]  # one pose is enough: the fewest


def test_groups_are_taken_whole_and_a_short_pool_says_so() -> None:
    pool = np.stack([_pose(1.0, 1.0, 1.0), _pose(1.0, 1.2, 1.0), _pose(1.0, 1.0, 1.2),
                     _pose(1.0, 1.0, 1.0)])
    members = [np.array([0, 1]), np.array([2, 3])]
    plan = separating_poses(MEASURED, pool, members, criterion, (100.0, 100.0), 10)
    assert not plan.reached
    assert sorted(plan.indices.tolist()) == [0, 1, 2, 3]
    assert 0 < min(plan.after) < 100.0
