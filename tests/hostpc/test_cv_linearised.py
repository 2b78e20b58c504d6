"""Cross-validation by the linearised leave-fold-out update (hostpc.fitting.fitting) against
full refits of each fold: the approximation it states holds on real fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import load_dataset
from hostpc.fitting.fitting import (
    _leave_out_steps,
    cross_validated_rms,
    solve,
)
from hostpc.fitting.folds import fold_indices
from hostpc.fitting.solver import evaluate, levenberg_marquardt
from hostpc.model.problem import build_problem

EXAMPLES = Path(__file__).parents[2] / "examples"


@pytest.mark.parametrize(("name", "effects"), [
    ("ur5e_stereo.json", None),
    ("ur5e_stereo_hidden_compliance.json", "joint_offsets,tool,target,geometry"),
])
def test_linearised_folds_match_full_refits(name: str, effects: str | None) -> None:
    problem = build_problem(load_dataset(EXAMPLES / name), effects)
    result = solve(problem, cv_folds=0)
    free = ~result.fixed
    final = evaluate(problem, result.x)
    folds = fold_indices(problem.dataset.samples, 5)
    assert folds is not None
    steps = _leave_out_steps(problem, final, free, folds)
    n = problem.measured.shape[0]
    for test, step in zip(folds, steps, strict=True):
        assert step is not None
        refit = levenberg_marquardt(problem.subset(np.setdiff1d(np.arange(n), test)),
                                    result.x, free, max_iterations=100, cost_tolerance=1e-16)
        moved = refit.x - result.x
        # leaving a fold out moves the solution by ~1-4 standard deviations (norm over the
        # parameters); the linearised step gets every parameter of that move right to
        # 5e-3 of its standard deviation (measured: <= 1.4e-3, the curvature term)
        error = np.abs((result.x + step - refit.x)[free]) / result.std[free]
        assert np.all(error <= 5e-3)
        assert np.linalg.norm(moved[free] / result.std[free]) > 0.5  # a real move
    refitted = cross_validated_rms(problem, result.x, free, 5, "huber", 1e9)  # forces refits
    linearised = cross_validated_rms(problem, result.x, free, 5, "linear", 3.0, final)
    assert refitted is not None and linearised is not None
    assert linearised == pytest.approx(refitted, rel=1e-5)


def test_folds_batched_give_the_steps_of_each_fold_alone_and_none_where_singular() -> None:
    from hostpc.fitting.solver import Evaluation

    problem = build_problem(load_dataset(EXAMPLES / "ur5e_stereo.json"))
    result = solve(problem, cv_folds=0)
    free = ~result.fixed
    final = evaluate(problem, result.x)
    n, m = problem.measured.shape
    folds = fold_indices(problem.dataset.samples, 5)
    assert folds is not None
    batched = _leave_out_steps(problem, final, free, folds)
    for fold, step in zip(folds, batched, strict=True):
        alone = _leave_out_steps(problem, final, free, [fold])[0]
        assert step is not None and alone is not None
        np.testing.assert_array_equal(step, alone)
    # one parameter seen by fold 0 only: without that fold it is undetermined
    assert final.jacobian is not None
    jacobian = np.array(final.jacobian)
    outside = np.setdiff1d(np.arange(n), folds[0])
    jacobian[(outside[:, None] * m + np.arange(m)).ravel(), np.flatnonzero(free)[0]] = 0.0
    degenerate = Evaluation(final.x, final.raw, final.whitened, jacobian)
    steps = _leave_out_steps(problem, degenerate, free, folds)
    assert steps[0] is None
    assert all(step is not None for step in steps[1:])
