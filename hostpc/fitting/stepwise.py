"""The stepwise dual_loop baseline, and a truth expressed in a fit's gauge.

Traditional hand-eye style calibration of a two-armed robot solves one loop at a time:

1. the LEFT loop alone (left samples): camera, left_base, left_target and the head and left
   arm offsets;
2. the RIGHT loop alone (right samples) with the camera and the head offsets FIXED at their
   step-1 values: right_base, right_target and the right arm offsets.

The camera (shared by both loops) is thus estimated from half the data, and its error is
frozen into step 2. :func:`fit_stepwise` does exactly that, on the same parameter layout as
the joint solve (``build_problem`` of the whole dataset) and with the same gauge: in each
step the parameters that step cannot see are held at nominal by
:func:`hostpc.fitting.identifiability.analyse` (the pan and tilt offsets and each arm's first
and last offsets, the frames absorbing them), so its estimates compare one to one with the
joint solve's.

:func:`gauge_equivalent` maps a true parameter vector to the one a perfect fit would return
under a given gauge (the unidentifiable parameters held at nominal): compare estimates with
it, never with the raw truth.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hostpc.dataset import Dataset
from hostpc.fitting.identifiability import analyse
from hostpc.fitting.solver import SolverOutcome, evaluate, levenberg_marquardt
from hostpc.model.joint_offsets import chain_prefix
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

__all__ = ["StepwiseResult", "fit_stepwise", "gauge_equivalent"]

STEP_PARAMETERS = {
    "left": (chain_prefix("head"), chain_prefix("left"), "camera.", "left_base.",
             "left_target."),
    "right": (chain_prefix("right"), "right_base.", "right_target."),
}
"""Name prefixes of the parameters each step estimates (the rest stay where they are)."""


@dataclass(frozen=True)
class StepwiseResult:
    """The two steps' outcome on the joint problem's layout.

    problem: the joint problem (whole dataset, same effects); x: (P,) estimates;
    fixed: (P,) True where a parameter was held (gauge, or not part of any step);
    steps: the solver outcome of each step, left first.
    """

    problem: Problem
    x: np.ndarray
    fixed: np.ndarray
    steps: tuple[SolverOutcome, SolverOutcome]

    def value(self, name: str) -> float:
        return float(self.x[self.problem.layout.index(name)])


def _step_mask(names: Iterable[str], prefixes: tuple[str, ...]) -> np.ndarray:
    return np.array([name.startswith(prefixes) for name in names])


def _free_in(problem: Problem, x: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Candidates minus the gauge that `analyse` picks among them (P,) bool."""
    J = evaluate(problem, x).jacobian
    assert J is not None
    index = np.flatnonzero(candidates)
    layout = problem.layout
    ident = analyse(J[:, index], [layout.names[k] for k in index],
                    [layout.units[k] for k in index], frames=problem.frame_names)
    free = np.zeros(layout.size, dtype=bool)
    free[index[~ident.fixed]] = True
    return free


def fit_stepwise(dataset: Dataset, effects: str | Iterable[str] | None = None, *,
                 max_iterations: int = 100, unweighted: bool = False) -> StepwiseResult:
    """Calibrate the left loop, then the right loop with the camera and head fixed.

    Args:
        dataset: a dual_loop dataset with samples of both arms.
        effects: as for ``build_problem`` (default: joint offsets and every unknown frame).
        max_iterations: per step.
        unweighted: identity weights instead of each point's covariance (for comparison).

    Returns:
        :class:`StepwiseResult` on the layout of the joint problem.
    """
    problem = build_problem(dataset, effects)
    chain = dataset.samples.chain
    assert chain is not None
    x = np.zeros(problem.layout.size)
    outcomes = []
    estimated = np.zeros(problem.layout.size, dtype=bool)
    for side in ("left", "right"):
        rows = np.flatnonzero(chain == side)
        step = problem.subset(rows)
        if unweighted:
            step = identity_weighted(step)
        candidates = _step_mask(problem.layout.names, STEP_PARAMETERS[side])
        free = _free_in(step, x, candidates)
        outcome = levenberg_marquardt(step, x, free, max_iterations=max_iterations)
        x = outcome.x
        estimated |= free
        outcomes.append(outcome)
    return StepwiseResult(problem=problem, x=x, fixed=~estimated,
                          steps=(outcomes[0], outcomes[1]))


def identity_weighted(problem: Problem) -> Problem:
    """The same problem with plain least squares: every coordinate weighted alike
    (``1 / median sigma`` of the data, so whitened units stay comparable)."""
    cov_diag = np.linalg.inv(np.einsum("nji,njk->nik", problem.sqrt_information,
                                       problem.sqrt_information))
    sigma = float(np.sqrt(np.median(np.diagonal(cov_diag, axis1=1, axis2=2))))
    m = problem.measured.shape[1]
    W = np.broadcast_to(np.eye(m) / sigma, problem.sqrt_information.shape).copy()
    return dataclasses.replace(problem, sqrt_information=W)


def gauge_equivalent(problem: Problem, x_truth: np.ndarray, fixed: np.ndarray,
                     max_iterations: int = 50) -> np.ndarray:
    """The parameter vector that reproduces the truth's predictions exactly with the
    ``fixed`` parameters held at 0 (nominal): the truth in that gauge.

    Args:
        problem: any problem with the layout (its samples set the poses; the equivalence of
            a true null direction does not depend on them).
        x_truth: (P,) true parameter values.
        fixed: (P,) bool, the gauge of the fit to compare with.

    Returns:
        (P,) equivalent parameters (a noise-free fit started at the truth).
    """
    clean, _ = predict(problem, x_truth, jacobian=False)
    exact = dataclasses.replace(problem, measured=clean)
    x0 = np.where(fixed, 0.0, x_truth)
    outcome = levenberg_marquardt(exact, x0, ~fixed, max_iterations=max_iterations)
    return outcome.x
