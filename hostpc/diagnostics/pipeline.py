"""diagnose(): fit the model, judge it, find where it fails and what is missing."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, load_dataset
from hostpc.diagnostics.adequacy import assess, held_out_residuals
from hostpc.diagnostics.advice import advise
from hostpc.diagnostics.candidates import candidate_effects, rank_candidates
from hostpc.diagnostics.diagnosis import Diagnosis, ModelCheck
from hostpc.diagnostics.interactions import search_interactions
from hostpc.diagnostics.ladder import DEFAULT_MAX_STEPS, climb
from hostpc.diagnostics.residual_analysis import analyse_residuals, analysis_variables
from hostpc.errors import InputError
from hostpc.fitting import FitResult, solve
from hostpc.fitting.solver import Loss
from hostpc.model.effect import Effect
from hostpc.model.problem import build_problem
from hostpc.model.registry import available_effects

#: family-wise significance of each family of tests (chi-square band, candidates,
#: interactions, binned patterns); Bonferroni-corrected inside each family
DEFAULT_ALPHA = 1e-3
DEFAULT_CV_FOLDS = 5
#: folds of the held-out RMS of each candidate while ranking (the ladder uses cv_folds)
DEFAULT_RANK_CV_FOLDS = 3


def variables_of(result: FitResult) -> dict[str, np.ndarray]:
    """The contract variables of a fit's dataset, as the residual analysis uses them."""
    problem = result.problem
    return analysis_variables(problem.context.variables, problem.measured, result.residuals_raw)


class _Checker:
    """Checks fitted models with fixed options (used for the start and every ladder step)."""

    def __init__(self, registry: dict[str, type[Effect]], only: Sequence[str] | None,
                 alpha: float, cv_folds: int, rank_cv_folds: int, loss: Loss,
                 interactions: bool) -> None:
        self.registry = registry
        self.only = only
        self.alpha = alpha
        self.cv_folds = cv_folds
        self.rank_cv_folds = rank_cv_folds
        self.loss = loss
        self.interactions = interactions

    def __call__(self, result: FitResult) -> ModelCheck:
        held = held_out_residuals(result.problem, result.x, ~result.fixed, self.cv_folds)
        if held is not None:
            result = replace(result, cv_rms=held.rms, cv_folds=held.folds)
        names = candidate_effects(result.problem, self.registry, self.only)
        candidates, skipped = rank_candidates(result, self.registry, names, alpha=self.alpha,
                                              cv_folds=self.rank_cv_folds, loss=self.loss)
        if self.interactions:
            found, n_tests = search_interactions(result, variables_of(result), self.alpha)
        else:
            found, n_tests = (), 0
        missing = []
        best = next((c for c in candidates if c.significant), None)
        if best is not None:
            missing.append(f"adding {best.effect} is significant (p = {best.p_value:.2g}, "
                           f"delta BIC {best.delta_bic:.1f})")
        strong = [i for i in found if i.significant]
        if strong:
            missing.append(f"the residuals say {strong[0].sentence} "
                           f"(p = {strong[0].p_value:.2g})")
        adequacy = assess(result, held, self.alpha, tuple(missing))
        return ModelCheck(result, held, adequacy, candidates, skipped, found, n_tests)


def diagnose(
    dataset: Dataset | str | Path,
    effects: str | Iterable[str] | None = None,
    *,
    plugins: Iterable[str | Path] = (),
    ladder: bool = False,
    candidates: Sequence[str] | None = None,
    alpha: float = DEFAULT_ALPHA,
    cv_folds: int = DEFAULT_CV_FOLDS,
    rank_cv_folds: int = DEFAULT_RANK_CV_FOLDS,
    loss: Loss = "linear",
    interactions: bool = True,
    max_ladder_steps: int = DEFAULT_MAX_STEPS,
    source: str | None = None,
) -> Diagnosis:
    """Fit the model to the dataset and diagnose it.

    dataset: a Dataset or the path of a dataset file. effects: as for ``hostpc.fit`` (None:
    joint_offsets plus the unknown frames; ``"+joint_compliance"`` adds to that). plugins:
    Python files defining extra effects (their effects become candidates too). ladder: also
    fit the nested models, adding the best candidate while it is significant. candidates:
    the effects to try (default: every registered effect that applies). alpha: family-wise
    significance of each family of tests. cv_folds: folds of the held-out residuals (0 to
    skip); rank_cv_folds: folds of each candidate's held-out RMS. interactions: run the
    effect-agnostic search. source: the dataset's path, used in the suggested commands.
    """
    if isinstance(dataset, str | Path):
        source = source or str(dataset)
        dataset = load_dataset(dataset)
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha {alpha}: must be between 0 and 1")
    if cv_folds < 0 or rank_cv_folds < 0:
        raise InputError("cv_folds and rank_cv_folds must not be negative")
    plugin_paths = tuple(str(p) for p in plugins)
    registry = available_effects(plugin_paths)
    problem = build_problem(dataset, effects, plugins=plugin_paths)
    checker = _Checker(registry, candidates, alpha, cv_folds, rank_cv_folds, loss, interactions)
    start = checker(solve(problem, loss=loss, cv_folds=0))
    residuals = analyse_residuals(start.fit.residuals_raw, start.fit.residuals_whitened,
                                  variables_of(start.fit), alpha)
    steps = climb(start, checker, max_ladder_steps) if ladder else None
    advice = advise(start, residuals, steps, source, plugin_paths)
    return Diagnosis(check=start, residuals=residuals, ladder=steps, advice=advice,
                     alpha=alpha, source=source, plugins=plugin_paths)
