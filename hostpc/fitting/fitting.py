"""fit(): build the problem, fix the unidentifiable directions, solve, and measure the result
(covariance, correlations, cross-validated RMS)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset
from hostpc.errors import InputError
from hostpc.fitting.folds import fold_indices
from hostpc.fitting.identifiability import Identifiability, hold_weak_parameters
from hostpc.fitting.priors import (
    analyse_with_constraints,
    problem_constraints,
    with_constraints,
)
from hostpc.fitting.result import CORRELATION_THRESHOLD, FitResult
from hostpc.fitting.shared_errors import added_parameter_covariance
from hostpc.fitting.solver import (
    Evaluation,
    Loss,
    SolverOutcome,
    evaluate,
    levenberg_marquardt,
    normal_equations,
)
from hostpc.model.layout import Problem
from hostpc.model.memo import SharedValues
from hostpc.model.problem import build_problem

DEFAULT_CV_FOLDS = 5
PRELIMINARY_ITERATIONS = 30
"""The iterations of the fit that measures the noise before the weak parameters are chosen
(``_hold_weak``): the cost falls within a few; what is left is the walk along the weak
directions, which barely changes it."""


def measured_per_sample(problem: Problem) -> np.ndarray:
    """(N,) the measured components of each sample: m less the axes its ``mask`` field
    (N, m) marks unmeasured (world_point's; their rows are zero by construction and carry
    no information, so they are no degrees of freedom)."""
    mask = problem.dataset.samples.fields.get("mask")
    if mask is not None and np.shape(mask) == problem.measured.shape:
        return np.count_nonzero(mask, axis=1)
    return np.full(problem.measured.shape[0], problem.measured.shape[1])


def measured_components(problem: Problem) -> int:
    """The measured components of the problem's samples (``measured_per_sample``)."""
    return int(np.sum(measured_per_sample(problem)))


def _covariance(J_free: np.ndarray) -> np.ndarray:
    """Inverse of J^T J by SVD (J has full column rank after gauge fixing)."""
    _, s, Vt = np.linalg.svd(J_free, full_matrices=False)
    s_inv2 = np.where(s > s[0] * 1e-14, 1.0 / s**2, 0.0) if s.size else s
    return (Vt.T * s_inv2) @ Vt


def cross_validated_rms(problem: Problem, x: np.ndarray, free: np.ndarray, folds: int,
                        loss: Loss, loss_scale: float,
                        evaluation: Evaluation | None = None) -> float | None:
    """RMS over all samples of the residual norm, each predicted by a fit that did not see it
    (``held_out_by_fold``)."""
    held = held_out_by_fold(problem, x, free, folds, loss=loss, loss_scale=loss_scale,
                            evaluation=evaluation)
    if held is None:
        return None
    raw, _ = held
    return float(np.sqrt(np.mean(np.sum(raw[:, problem.length_columns]**2, axis=1))))


def held_out_by_fold(problem: Problem, x: np.ndarray, free: np.ndarray, folds: int, *,
                     loss: Loss = "linear", loss_scale: float = 3.0,
                     evaluation: Evaluation | None = None, max_iterations: int = 30
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """Raw and whitened residuals (N, m) of every sample, each predicted by the fit of the
    folds that do not hold it (``fold_indices``: whole poses per fold); None with too few
    poses for ``folds``.

    With the linear loss each fold's fit is the exact linearised leave-fold-out update of
    the solution ``x`` (``_leave_out_steps``; ``evaluation``: the Jacobian at ``x``, computed
    if not given): no refit, no new Jacobian, and the held-out residuals move to first order
    with it (``_moved_residuals``), no new prediction. Otherwise (a robust loss, whose
    weights a refit changes) each fold is refitted starting from ``x`` (it is a
    perturbation of it), as is a fold whose remaining samples do not determine the
    parameters."""
    n_samples, m = problem.measured.shape
    samples = problem.dataset.samples  # every model of one dataset: the same folds
    fold_sets = problem.shared.value(samples, ("fold_indices", folds),
                                     lambda: fold_indices(samples, folds))
    if fold_sets is None:
        return None
    steps: list[np.ndarray | None] = [None] * folds
    if loss == "linear":
        if evaluation is None or evaluation.jacobian is None or not np.array_equal(
                evaluation.x, x):
            evaluation = evaluate(problem, x)
        steps = _leave_out_steps(problem, evaluation, free, fold_sets)
    raw = np.empty((n_samples, m))
    whitened = np.empty((n_samples, m))
    moved = [(test, step) for test, step in zip(fold_sets, steps, strict=True)
             if step is not None]
    if moved:
        assert evaluation is not None
        _moved_residuals(problem, evaluation, moved, raw, whitened)
    for test, step in zip(fold_sets, steps, strict=True):
        if step is None:
            train = np.setdiff1d(np.arange(n_samples), test)
            x_fold = levenberg_marquardt(problem.subset(train), x, free, loss=loss,
                                         loss_scale=loss_scale,
                                         max_iterations=max_iterations).x
            held = evaluate(problem.subset(test), x_fold, jacobian=False)
            raw[test], whitened[test] = held.raw, held.whitened
    return raw, whitened


def _moved_residuals(problem: Problem, evaluation: Evaluation,
                     moved: list[tuple[np.ndarray, np.ndarray]], raw: np.ndarray,
                     whitened: np.ndarray) -> None:
    """Into ``raw`` and ``whitened``: per (test, step) of ``moved``, the residuals of the
    samples ``test`` after the parameters move by ``step``, to first order: whitened + J
    step, raw + W^-1 (J step) (J: whitened Jacobian, W: whitening), no new prediction.
    The W^-1 solves of all folds are one batched call (each sample's solve is the same
    LAPACK call as alone)."""
    assert evaluation.jacobian is not None
    m = problem.measured.shape[1]
    tests = np.concatenate([test for test, _ in moved])
    change = np.empty((tests.size, m))
    start = 0
    for test, step in moved:
        rows = (test[:, None] * m + np.arange(m)).ravel()
        change[start:start + test.size] = (evaluation.jacobian[rows] @ step).reshape(test.size, m)
        start += test.size
    raw_change = np.linalg.solve(problem.sqrt_information[tests], change[:, :, None])[:, :, 0]
    raw[tests] = evaluation.raw[tests] + raw_change
    whitened[tests] = evaluation.whitened[tests] + change


def _leave_out_steps(problem: Problem, evaluation: Evaluation, free: np.ndarray,
                     fold_sets: list[np.ndarray]) -> list[np.ndarray | None]:
    """Per fold, the Gauss-Newton step from the full solution to the fit without that fold.

    With J, r the whitened Jacobian and residuals at the full solution (prior rows
    included), and J_f, r_f the fold's rows: step = -(J^T J - J_f^T J_f)^-1 (J^T r - J_f^T
    r_f). It is exact for a model linear in its parameters and, for a non-linear one, off
    by the curvature times the step squared: the step is the fold's pull on the solution,
    ~sigma / sqrt(N), so the error is far below the cross-validated RMS's own noise
    (tests/hostpc/test_cv_linearised.py compares it with full refits). None for a fold
    whose remaining rows do not determine the parameters (that fold is refitted)."""
    constraints = problem_constraints(problem)
    if constraints is not None:
        free = np.asarray(free, bool) & ~constraints.held
    free_index = np.flatnonzero(free)
    x = evaluation.x
    assert evaluation.jacobian is not None
    m = problem.measured.shape[1]
    J = evaluation.jacobian[:, free_index]
    r = evaluation.whitened.ravel()
    A, g = normal_equations(J, r, constraints, x, free_index)
    scales, scaled, rhs = [], [], []
    for test in fold_sets:
        rows = (test[:, None] * m + np.arange(m)).ravel()
        J_fold = J[rows]
        A_train = A - J_fold.T @ J_fold
        g_train = g - J_fold.T @ r[rows]
        # Jacobi scaling: parameters in m and rad, conditioning judged without the units
        scale = 1.0 / np.sqrt(np.maximum(np.diag(A_train), 1e-300))
        scales.append(scale)
        scaled.append(A_train * scale[:, None] * scale[None, :])
        rhs.append(scale * g_train)
    if free_index.size == 0:
        return [_full_step(x.size, free_index, scale, np.zeros(0)) for scale in scales]
    # all folds' solves and eigenvalues in one batched call each (every fold's the same
    # LAPACK call as alone); a singular fold makes the batch fail: then fold by fold
    try:
        solutions = list(np.linalg.solve(np.stack(scaled), np.stack(rhs)[:, :, None])[:, :, 0])
        eigenvalues = list(np.linalg.eigvalsh(np.stack(scaled)))
    except np.linalg.LinAlgError:
        return [_fold_step(x.size, free_index, scale, A_scaled, b)
                for scale, A_scaled, b in zip(scales, scaled, rhs, strict=True)]
    reduced = [-scale * solution for scale, solution in zip(scales, solutions, strict=True)]
    return [_full_step(x.size, free_index, scale, step)
            if np.all(np.isfinite(step)) and not _ill_conditioned(values) else None
            for scale, step, values in zip(scales, reduced, eigenvalues, strict=True)]


def _fold_step(n_params: int, free_index: np.ndarray, scale: np.ndarray,
               scaled: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
    """One fold's step from its Jacobi-scaled normal equations; None where they are
    singular or ill-conditioned."""
    try:
        reduced = -scale * np.linalg.solve(scaled, rhs)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(reduced)) or _ill_conditioned(np.linalg.eigvalsh(scaled)):
        return None
    return _full_step(n_params, free_index, scale, reduced)


def _full_step(n_params: int, free_index: np.ndarray, scale: np.ndarray,
               reduced: np.ndarray) -> np.ndarray:
    step = np.zeros(n_params)
    step[free_index] = reduced
    return step


def _ill_conditioned(eigenvalues: np.ndarray) -> bool:
    """From the ascending eigenvalues of the scaled normal matrix."""
    if eigenvalues.size == 0:
        return False
    return not eigenvalues[0] > 1e-12 * eigenvalues[-1]


def solve(problem: Problem, *, x0: np.ndarray | None = None, loss: Loss = "linear",
          loss_scale: float = 3.0, cv_folds: int = DEFAULT_CV_FOLDS,
          max_iterations: int = 100, initial: Evaluation | None = None) -> FitResult:
    """Fit a built problem and return a frozen FitResult (never raises on poor data).

    initial: the problem already evaluated (with its Jacobian) at the start x0, if the
    caller has it (a candidate effect's warm start): not evaluated again."""
    if cv_folds < 0 or cv_folds == 1:
        raise InputError(f"cv_folds must be 0 (no cross-validation) or at least 2, got {cv_folds}")
    layout = problem.layout
    x_start = np.zeros(layout.size) if x0 is None else np.asarray(x0, dtype=float).copy()
    if x_start.shape != (layout.size,):
        raise InputError(f"x0 must have {layout.size} values, got {x_start.shape}")
    if initial is not None and initial.jacobian is not None and np.array_equal(initial.x,
                                                                                x_start):
        start = initial
    else:
        start = evaluate(problem, x_start)
    assert start.jacobian is not None
    constraints = problem_constraints(problem)  # priors and holds by name (priors.py)
    prior_rows = (constraints.jacobian(layout.size) if constraints is not None
                  else np.zeros((0, layout.size)))
    finite = bool(np.all(np.isfinite(start.jacobian)) and np.all(np.isfinite(start.whitened)))
    prior_notes: list[str] = []
    preliminary: SolverOutcome | None = None
    preliminary_free = np.zeros(0, dtype=bool)
    if finite:  # a prior is a row like any measurement: it can make a direction identifiable
        ident, prior_notes = analyse_with_constraints(start.jacobian, layout.names,
                                                      layout.units, constraints,
                                                      frames=problem.frame_names)
        preliminary_free = ~ident.fixed
        ident, preliminary = _hold_weak(problem, x_start, start, prior_rows, ident,
                                        loss=loss, loss_scale=loss_scale,
                                        max_iterations=max_iterations)
    else:  # reported through the solver's "failed" status; nothing can be analysed
        ident = Identifiability(0, np.zeros(layout.size), math.nan,
                                np.zeros(layout.size, dtype=bool), ())
    free = ~ident.fixed
    outcome = preliminary if preliminary is not None and np.array_equal(
        preliminary_free, free) else levenberg_marquardt(
        problem, x_start, free, loss=loss, loss_scale=loss_scale,
        max_iterations=max_iterations, initial=start)
    final = outcome.evaluation
    assert final.jacobian is not None
    m = problem.measured.shape[1]
    row_weight = np.repeat(np.sqrt(outcome.weights), m)
    J_free = final.jacobian[:, free]
    whitened_rows = final.whitened.ravel()
    if loss != "linear":  # the linear loss's weights are all 1: nothing to multiply
        J_free = J_free * row_weight[:, None]
        whitened_rows = whitened_rows * row_weight
    J_free_priors = np.vstack([J_free, prior_rows[:, free]]) if prior_rows.size else J_free
    covariance = np.zeros((layout.size, layout.size))
    if np.any(free) and np.all(np.isfinite(J_free)):
        covariance[np.ix_(free, free)] = _covariance(J_free_priors)
        shared = added_parameter_covariance(problem, J_free, covariance[np.ix_(free, free)],
                                            row_weight, whitened_rows,
                                            prior_rows[:, free] if prior_rows.size else None)
        if shared is not None:  # the rig's calibration error, shared by all samples
            covariance[np.ix_(free, free)] += shared
    elif np.any(free):
        covariance[np.ix_(free, free)] = np.nan
    std = np.sqrt(np.diag(covariance))
    std[~free] = np.nan
    correlations = _strong_correlations(covariance, std, free, layout.names)
    norms = np.linalg.norm(final.raw[:, problem.length_columns], axis=1)
    cv = (cross_validated_rms(problem, outcome.x, free, cv_folds, loss, loss_scale, final)
          if outcome.converged else None)
    return FitResult(
        problem=problem,
        x=outcome.x,
        std=std,
        fixed=ident.fixed,
        covariance=covariance,
        residuals_raw=final.raw,
        residuals_whitened=final.whitened,
        weights=outcome.weights,
        rms=float(np.sqrt(np.mean(norms**2))),
        max=float(np.max(norms)) if norms.size else 0.0,
        chi2=float(np.sum(final.whitened**2)),
        dof=int(measured_components(problem) + prior_rows.shape[0] - np.count_nonzero(free)),
        rank=ident.rank,
        singular_values=ident.singular_values,
        condition_number=ident.condition_number,
        unidentifiable=ident.null_directions,
        correlations=tuple(correlations),
        converged=outcome.converged,
        iterations=outcome.iterations,
        message="; ".join([outcome.message, *prior_notes]),
        cv_rms=cv,
        cv_folds=cv_folds if cv is not None else 0,
        loss=loss,
    )


def measured_noise(problem: Problem, whitened: np.ndarray, free: int) -> float | None:
    """The measured noise over the stated one, robustly: sqrt of the median per-sample
    whitened square norm over the median of a chi-square of as many rows (Wilson-Hilferty),
    times the rows over the degrees of freedom (the fitted parameters' share). The median,
    not chi2/dof: a few gross outliers (a 10 m slip in one sample) leave it alone, as they
    would not a mean; a model that misses an effect raises it as chi2/dof. Scale-invariant:
    a uniform stated sigma k times larger makes it k times smaller. None without degrees
    of freedom."""
    rows = measured_per_sample(problem)
    measured = int(np.sum(rows))
    dof = measured - free
    if dof <= 0 or not len(whitened):
        return None
    median_chi2 = rows * (1.0 - 2.0 / (9.0 * rows)) ** 3
    ratio = float(np.median(np.sum(whitened**2, axis=1) / median_chi2))
    return math.sqrt(max(ratio * measured / dof, 1e-300))


def _hold_weak(problem: Problem, x_start: np.ndarray, start: Evaluation,
               prior_rows: np.ndarray, ident: Identifiability, *, loss: Loss,
               loss_scale: float, max_iterations: int
               ) -> tuple[Identifiability, SolverOutcome | None]:
    """``ident`` with the weakly determined parameters held (``hold_weak_parameters``),
    judged at the measured noise (``measured_noise``) of the fit with only the exact gauge
    held, so that a uniform stated sigma (1 mm or 0.36 mm) never changes what is held, nor
    the fitted values (docs/fitting.md, "Weak directions"). That fit (its outcome is
    returned, to be reused when nothing more is held) runs only when the rule could hold
    something at the noise measured at the start."""
    assert start.jacobian is not None
    layout = problem.layout
    free = int(np.count_nonzero(~ident.fixed))
    at_start = measured_noise(problem, start.whitened, free)
    if at_start is None:  # no noise measured: the stated noise is the only scale
        return hold_weak_parameters(start.jacobian, prior_rows, ident, layout.names,
                                    layout.units), None
    if np.array_equal(hold_weak_parameters(start.jacobian, prior_rows, ident, layout.names,
                                           layout.units, noise_scale=at_start).fixed,
                      ident.fixed):
        return ident, None
    outcome = levenberg_marquardt(problem, x_start, ~ident.fixed, loss=loss,
                                  loss_scale=loss_scale,
                                  max_iterations=min(max_iterations, PRELIMINARY_ITERATIONS),
                                  initial=start)
    noise = measured_noise(problem, outcome.evaluation.whitened, free) or 1.0
    held = hold_weak_parameters(start.jacobian, prior_rows, ident, layout.names, layout.units,
                                noise_scale=noise)
    return held, outcome if outcome.converged else None


def _strong_correlations(covariance: np.ndarray, std: np.ndarray, free: np.ndarray,
                         names: Sequence[str]) -> list[tuple[str, str, float]]:
    """(name i, name j, rho) of the free pairs i < j with |rho| above
    ``CORRELATION_THRESHOLD``, strongest first (pairs of equal |rho| in index order)."""
    index = np.flatnonzero(free)
    first, second = np.triu_indices(index.size, k=1)
    i, j = index[first], index[second]
    rho = covariance[i, j] / np.maximum(std[i] * std[j], 1e-300)
    strong = np.flatnonzero(np.abs(rho) > CORRELATION_THRESHOLD)
    found = [(names[i[k]], names[j[k]], float(rho[k])) for k in strong]
    found.sort(key=lambda c: -abs(c[2]))
    return found


def fit(dataset: Dataset, effects: str | Iterable[str] | None = None, *,
        plugins: Iterable[str | Path] = (), priors: object = None, hold: object = None,
        shared: SharedValues | None = None, **options: object) -> FitResult:
    """Fit an error model to a dataset.

    effects: None for the default model (joint_offsets plus every frame not marked known),
    a list of effect names, or a spec string (``"joint_offsets,tool"``, ``"+backlash"``).
    plugins: Python files defining extra effects. options: see ``solve`` (loss, loss_scale,
    cv_folds, max_iterations, x0). priors: ["tool.x=0.045+-0.0005m", ...] or
    {"tool.x": {"value": 0.045, "sigma": 0.0005, "unit": "m"}}; hold: parameter names kept
    at their start value (both added to the dataset's own; hostpc.fitting.priors).
    shared: what other fits of this dataset computed (``result.problem.shared``: the chain,
    the rig's point sensitivity), reused; None computes them for this fit.
    """
    dataset = with_constraints(dataset, priors, hold)  # type: ignore[arg-type]
    problem = build_problem(dataset, effects, plugins=tuple(plugins), shared=shared)
    return solve(problem, **options)  # type: ignore[arg-type]


