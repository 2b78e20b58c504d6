"""Levenberg-Marquardt on whitened residuals, with an optional robust loss (IRLS).

Residuals are ``r = W (measured - predicted)`` per sample (W = whitening matrix, W^T W =
cov^-1), so the objective is the Mahalanobis distance. Only the parameters in ``free`` move;
the others stay at their start values. Pure numpy, no I/O. One cache: a small problem's
latest evaluation with its Jacobian is kept on the problem (``problem.memo``, a
``hostpc.model.memo.ProblemMemo``; read-only arrays), since a fit, its held-out
residuals, the candidate ranking and the interaction search each evaluate the same fit at
the same x.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from hostpc.fitting.priors import Constraints, problem_constraints
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict

Loss = Literal["linear", "huber", "cauchy"]


@dataclass(frozen=True)
class Evaluation:
    """Residuals and Jacobian at one parameter vector.

    raw: (N, m) measured - predicted (SI units); whitened: (N, m);
    jacobian: (N*m, P) derivative of the flattened whitened residuals by x, or None.
    """

    x: np.ndarray
    raw: np.ndarray
    whitened: np.ndarray
    jacobian: np.ndarray | None


@dataclass(frozen=True)
class SolverOutcome:
    x: np.ndarray
    evaluation: Evaluation
    weights: np.ndarray
    converged: bool
    iterations: int
    message: str
    cost: float


#: samples per chunk of a large problem's Jacobian evaluation: a model's intermediates (the
#: per-pose derivative of the kinematic deltas, (N, 5n, P)) stay bounded (~35 MB at P = 34)
#: instead of growing with N; problems up to twice this are evaluated in one piece
CHUNK_SAMPLES = 8192

#: a problem's latest evaluation is kept if its Jacobian has at most this many values (2 MB)
REUSE_ELEMENTS = 1 << 18


def evaluate(problem: Problem, x: np.ndarray, jacobian: bool = True) -> Evaluation:
    """Raw and whitened residuals at x, and d(whitened)/dx flattened to (N*m, P).

    A large problem (N > 2 * CHUNK_SAMPLES) with a Jacobian is evaluated in chunks of
    samples (``Problem.subset``: a view of the built rows), so that a measurement model's
    per-pose intermediates never exist for all N at once; every prediction depends on its
    own sample only, so the result is the same."""
    n_samples = problem.measured.shape[0]
    if jacobian and n_samples > 2 * CHUNK_SAMPLES:
        return _evaluate_in_chunks(problem, x)
    reuse = problem.measured.size * np.size(x) <= REUSE_ELEMENTS
    if reuse:
        latest = problem.memo.recall("latest evaluation")
        if latest is not None and np.array_equal(latest.x, x):
            return latest
    evaluation = _evaluate(problem, x, jacobian)
    if reuse and jacobian:
        evaluation = Evaluation(np.array(x, dtype=float), evaluation.raw, evaluation.whitened,
                                evaluation.jacobian)
        for array in (evaluation.x, evaluation.raw, evaluation.whitened, evaluation.jacobian):
            if array is not None:
                array.setflags(write=False)
        problem.memo.remember("latest evaluation", evaluation)
    return evaluation


def _evaluate_in_chunks(problem: Problem, x: np.ndarray) -> Evaluation:
    n_samples, m = problem.measured.shape
    raw = np.empty((n_samples, m))
    whitened = np.empty((n_samples, m))
    J = np.empty((n_samples * m, x.size))
    for start in range(0, n_samples, CHUNK_SAMPLES):
        stop = min(start + CHUNK_SAMPLES, n_samples)
        part = _evaluate(problem.subset(np.arange(start, stop)), x, True)
        raw[start:stop] = part.raw
        whitened[start:stop] = part.whitened
        assert part.jacobian is not None
        J[start * m:stop * m] = part.jacobian
    return Evaluation(x=x, raw=raw, whitened=whitened, jacobian=J)


def _evaluate(problem: Problem, x: np.ndarray, jacobian: bool) -> Evaluation:
    predicted, d_predicted = predict(problem, x, jacobian)
    raw = problem.measured - predicted
    W = problem.sqrt_information
    whitened = (W @ raw[:, :, None])[:, :, 0]
    J = None
    if d_predicted is not None:
        J = -(W @ d_predicted).reshape(-1, x.size)
    return Evaluation(x=x, raw=raw, whitened=whitened, jacobian=J)


def robust_weights(whitened: np.ndarray, loss: Loss, scale: float) -> np.ndarray:
    """Per-sample IRLS weights (N,) from the whitened residual norm of each sample."""
    if loss == "linear":
        return np.ones(whitened.shape[0])
    e = np.linalg.norm(whitened, axis=1) / scale
    if loss == "huber":
        return np.where(e <= 1.0, 1.0, 1.0 / np.maximum(e, 1e-300))
    if loss == "cauchy":
        return 1.0 / (1.0 + e**2)
    raise ValueError(f"unknown loss {loss!r}; use linear, huber or cauchy")


def robust_cost(whitened: np.ndarray, loss: Loss, scale: float) -> float:
    """Sum over samples of rho(|r_i|), with rho(e) = e^2 / 2 for the linear loss."""
    e = np.linalg.norm(whitened, axis=1)
    if loss == "linear":
        return float(0.5 * np.sum(e**2))
    s = e / scale
    if loss == "huber":
        rho = np.where(s <= 1.0, 0.5 * s**2, s - 0.5)
    else:
        rho = 0.5 * np.log1p(s**2)
    return float(scale**2 * np.sum(rho))


def levenberg_marquardt(
    problem: Problem,
    x0: np.ndarray,
    free: np.ndarray,
    *,
    loss: Loss = "linear",
    loss_scale: float = 3.0,
    max_iterations: int = 100,
    step_tolerance: float = 1e-12,
    cost_tolerance: float = 1e-10,
    initial: Evaluation | None = None,
) -> SolverOutcome:
    """Minimise the (robust) whitened cost over the free parameters, starting at x0.

    free: (P,) bool mask of the parameters that may move. Uses Marquardt's diagonal scaling
    and Nielsen's damping update.
    """
    x = np.array(x0, dtype=float)
    constraints = problem_constraints(problem)  # priors (extra residuals) and holds
    if constraints is not None:
        free = np.asarray(free, bool) & ~constraints.held
    free_index = np.flatnonzero(free)
    m = problem.measured.shape[1]
    if initial is not None and initial.jacobian is not None and np.array_equal(initial.x, x):
        current = initial
    else:
        current = evaluate(problem, x)
    weights = robust_weights(current.whitened, loss, loss_scale)
    cost = robust_cost(current.whitened, loss, loss_scale) + _prior_cost(constraints, x)
    if free_index.size == 0:
        return SolverOutcome(x, current, weights, True, 0, "nothing to fit", cost)
    # residuals below this are rounding noise of the predictions: an exact fit
    round_off_cost = problem.memo.value("round-off cost", lambda: _round_off_cost(problem))
    mu = 1e-6
    nu = 2.0
    message = "maximum iterations reached"
    converged = False
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        assert current.jacobian is not None
        J = current.jacobian[:, free_index]
        r = current.whitened.ravel()
        if loss != "linear":  # the linear loss's weights are all 1: nothing to multiply
            row_weight = np.repeat(np.sqrt(weights), m)
            J = J * row_weight[:, None]
            r = r * row_weight
        if not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
            message = "failed: the model gives non-finite residuals or derivatives"
            break
        A, g = normal_equations(J, r, constraints, x, free_index)
        diag = np.maximum(np.diag(A), 1e-30)
        diagonal = np.diag(diag)
        # converged when even an undamped Gauss-Newton step would gain (almost) nothing
        try:
            gauss_newton_gain = 0.5 * float(g @ np.linalg.solve(A + 1e-12 * diagonal, g))
        except np.linalg.LinAlgError:
            gauss_newton_gain = np.inf
        if cost <= round_off_cost:
            message, converged = "converged: exact fit (residuals at rounding level)", True
            break
        if gauss_newton_gain <= cost_tolerance * cost:
            message, converged = "converged: no step can decrease the cost further", True
            break
        accepted = False
        while mu <= 1e16:
            try:
                step = -np.linalg.solve(A + mu * diagonal, g)
            except np.linalg.LinAlgError:
                mu *= nu
                nu *= 2.0
                continue
            predicted_gain = 0.5 * float(step @ (mu * diag * step - g))
            x_trial = x.copy()
            x_trial[free_index] += step
            trial = evaluate(problem, x_trial)
            trial_cost = (robust_cost(trial.whitened, loss, loss_scale)
                          + _prior_cost(constraints, x_trial))
            actual_gain = cost - trial_cost
            if actual_gain > 0.0 and np.isfinite(trial_cost):
                rho = actual_gain / max(predicted_gain, 1e-300)
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                accepted = True
                break
            mu *= nu
            nu *= 2.0
        if not accepted:
            if cost <= 1e6 * round_off_cost:
                message, converged = "converged: exact fit (residuals at rounding level)", True
            else:
                message = ("stalled: no step along the model's gradient decreases the cost "
                           "(an effect's Jacobian may be wrong)")
            break
        x, current, cost = x_trial, trial, trial_cost  # trial_cost: the cost at x_trial
        weights = robust_weights(current.whitened, loss, loss_scale)
        small = np.linalg.norm(step) <= step_tolerance * (np.linalg.norm(x) + step_tolerance)
        if small and mu < 1.0:  # a tiny step that damping did not force: at the minimum
            message, converged = "converged: step below tolerance", True
            break
    return SolverOutcome(x, current, weights, converged, iterations, message, cost)


def normal_equations(J: np.ndarray, r: np.ndarray, constraints: Constraints | None,
                     x: np.ndarray, free_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(J^T J, J^T r) of the free parameters, the prior rows of ``constraints`` at x added.
    J: (rows, F) whitened Jacobian of the free columns; r: (rows,); x: (P,) all parameters;
    free_index: (F,) the free columns' indices in x."""
    A = J.T @ J
    g = J.T @ r
    if constraints is not None and constraints.index.size:
        J_prior = constraints.jacobian(x.size)[:, free_index]
        A = A + J_prior.T @ J_prior
        g = g + J_prior.T @ constraints.residuals(x)
    return A, g


def _round_off_cost(problem: Problem) -> float:
    """The cost of residuals at the predictions' rounding level (64 eps of the whitened
    measurements): below it the fit is exact."""
    measured = (problem.sqrt_information @ problem.measured[:, :, None])[:, :, 0]
    return 0.5 * float(np.sum(measured**2)) * (64 * np.finfo(float).eps) ** 2


def _prior_cost(constraints: Constraints | None, x: np.ndarray) -> float:
    """0.5 * sum of squared whitened prior residuals (0 without priors)."""
    return 0.0 if constraints is None else constraints.cost(x)
