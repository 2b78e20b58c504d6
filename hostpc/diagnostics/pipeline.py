"""diagnose(): fit the model, judge it, find where it fails and what is missing."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, load_dataset
from hostpc.diagnostics.adequacy import assess, held_out_residuals
from hostpc.diagnostics.advice import advise
from hostpc.diagnostics.auto_effects import generate, unexplained
from hostpc.diagnostics.candidates import (
    Candidate,
    candidate_effects,
    check_candidate_names,
    forget_candidate_fits,
    rank_candidates,
    try_candidate,
    warm_start,
)
from hostpc.diagnostics.detectable import candidate_sizes
from hostpc.diagnostics.diagnosis import Diagnosis, LadderStep, ModelCheck
from hostpc.diagnostics.interactions import Interaction, search_interactions
from hostpc.diagnostics.ladder import DEFAULT_MAX_STEPS, climb
from hostpc.diagnostics.law_candidates import law_effects
from hostpc.diagnostics.outliers import Outlier, find_outliers
from hostpc.diagnostics.residual_analysis import (
    ResidualAnalysis,
    analyse_residuals,
    analysis_variables,
)
from hostpc.diagnostics.separation import confounded_pairs
from hostpc.errors import InputError
from hostpc.fitting import FitResult, solve
from hostpc.fitting.solver import Loss
from hostpc.model.effect import Effect
from hostpc.model.layout import Problem
from hostpc.model.problem import build_problem, extend_problem
from hostpc.model.registry import available_effects

#: family-wise significance of each family of tests (chi-square band, candidates,
#: interactions, binned patterns); Bonferroni-corrected inside each family
DEFAULT_ALPHA = 1e-3
DEFAULT_CV_FOLDS = 5
#: significant unexplained patterns the ladder turns into effects and tries, per step
MAX_PROPOSALS = 3


def variables_of(result: FitResult) -> dict[str, np.ndarray]:
    """The contract variables of a fit's dataset, as the residual analysis uses them."""
    problem = result.problem
    return analysis_variables(problem.context.variables, problem.measured, result.residuals_raw)


class _Checker:
    """Checks fitted models with fixed options (used for the start and every ladder step).

    detect_outliers: test every sample (``outliers.find_outliers``) and, when some are
    outliers, rank the candidates and run the search on the fit without them.
    """

    def __init__(self, registry: dict[str, type[Effect]], only: Sequence[str] | None,
                 alpha: float, cv_folds: int, rank_cv_folds: int, loss: Loss,
                 interactions: bool, detect_outliers: bool = True) -> None:
        self.registry = registry
        self.only = only
        self.alpha = alpha
        self.cv_folds = cv_folds
        self.rank_cv_folds = rank_cv_folds
        self.loss = loss
        self.interactions = interactions
        self.detect_outliers = detect_outliers

    def without_outlier_detection(self) -> _Checker:
        """The same checker, not testing for outliers (the ladder's, which climbs on data
        already cleaned of them)."""
        return _Checker(self.registry, self.only, self.alpha, self.cv_folds,
                        self.rank_cv_folds, self.loss, self.interactions,
                        detect_outliers=False)

    def refit(self, result: FitResult, keep: np.ndarray) -> FitResult:
        """The fit's model refitted on its samples ``keep``, warm-started at its solution."""
        return solve(result.problem.subset(keep), x0=result.x, loss=self.loss, cv_folds=0)

    def __call__(self, result: FitResult) -> ModelCheck:
        outliers: tuple[Outlier, ...] = ()
        clean = result
        if self.detect_outliers:
            outliers, clean = find_outliers(result, self.alpha, self.refit)
        if not outliers:
            return self.check(result)
        cleaned = self.check(clean)
        held = held_out_residuals(result.problem, result.x, ~result.fixed, self.cv_folds)
        if held is not None:
            result = replace(result, cv_rms=held.rms, cv_folds=held.folds)
        adequacy = assess(result, held, self.alpha,
                          missing_sentences(cleaned.candidates, cleaned.interactions),
                          outliers)
        return ModelCheck(result, held, adequacy, cleaned.candidates, cleaned.skipped,
                          cleaned.interactions, cleaned.n_interaction_tests, outliers, cleaned)

    def check(self, result: FitResult) -> ModelCheck:
        """Held-out residuals, candidates, interactions and the verdict of one fit."""
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
        adequacy = assess(result, held, self.alpha, missing_sentences(candidates, found))
        return ModelCheck(result, held, adequacy, candidates, skipped, found, n_tests)


    def propose(self, check: ModelCheck) -> Candidate | None:
        """The interaction effect of the strongest significant pattern no built-in effect
        models, fitted as a candidate, when it is significant; else None."""
        variables = variables_of(check.fit)
        tried = {c.effect for c in check.candidates}
        context = check.fit.problem.context
        for interaction in unexplained(check.interactions, tried, context)[:MAX_PROPOSALS]:
            # a per-group difference is written only on a frame (frame_candidates); on a
            # joint or table entry it is named in the advice, not made a linear effect
            generated = generate(interaction, variables[interaction.variable], check.fit)
            if generated is None or generated.name in check.effects:
                continue
            try:
                candidate = try_candidate(check.fit, generated.effect_class(),
                                          cv_folds=0, loss=self.loss, threshold=self.alpha)
            except InputError:
                continue
            if candidate.taken:
                return candidate
        return None


    def prune(self, check: ModelCheck, start: Problem, keep: str
              ) -> tuple[FitResult, str] | None:
        """The fit without the least needed effect the ladder added to ``start`` (``keep``
        aside), and its name, when as a candidate on the model without it that effect
        would not be significant (threshold and held-out test of the ranking); else None."""
        added = check.fit.problem.terms[len(start.terms):]
        least: tuple[float, FitResult, str] | None = None
        for term in added:
            name = term.effect.name
            if name == keep:
                continue
            reduced_problem = extend_problem(start, [t.effect for t in added if t is not term])
            reduced = solve(reduced_problem, x0=warm_start(check.fit, reduced_problem),
                            loss=self.loss, cv_folds=0)
            held = held_out_residuals(reduced.problem, reduced.x, ~reduced.fixed,
                                      self.rank_cv_folds)
            family = max(len(candidate_effects(reduced_problem, self.registry, self.only)), 1)
            try:
                candidate = try_candidate(reduced, term.effect, cv_folds=self.rank_cv_folds,
                                          loss=self.loss, threshold=self.alpha / family,
                                          base_cv=None if held is None else held.whitened_rms)
            except InputError:
                continue
            p_value = 1.0 if candidate.p_value is None else candidate.p_value
            if not candidate.significant and (least is None or p_value > least[0]):
                least = (p_value, reduced, name)
        return None if least is None else (least[1], least[2])


def missing_sentences(candidates: Sequence[Candidate], found: Sequence[Interaction]
                      ) -> tuple[str, ...]:
    """The reasons a model is not adequate that name what is missing: the best significant
    candidate and the strongest significant interaction."""
    missing = []
    best = next((c for c in candidates if c.significant), None)
    if best is not None:
        missing.append(f"adding {best.effect} is significant (p = {best.p_value:.2g}, "
                       f"delta BIC {best.delta_bic:.1f})")
    strong = [i for i in found if i.significant]
    if strong:
        missing.append(f"the residuals say {strong[0].sentence} "
                       f"(p = {strong[0].p_value:.2g})")
    return tuple(missing)


def residual_analysis(check: ModelCheck, alpha: float) -> ResidualAnalysis:
    """The residual analysis of a check: per-sample norms and the worst samples of its fit;
    the binned patterns of the fit the candidates were ranked on (without the outliers, whose
    residuals would make every variable look patterned)."""
    fit = check.fit
    analysis = analyse_residuals(fit.residuals_raw, fit.residuals_whitened, variables_of(fit),
                                 alpha, length_columns=fit.problem.length_columns,
                                 categorical=fit.problem.context.categorical)
    if check.cleaned is None:
        return analysis
    clean = check.cleaned.fit
    patterns = analyse_residuals(clean.residuals_raw, clean.residuals_whitened,
                                 variables_of(clean), alpha,
                                 categorical=clean.problem.context.categorical)
    return replace(analysis, patterns=patterns.patterns, threshold=patterns.threshold)


def diagnose(
    dataset: Dataset | str | Path,
    effects: str | Iterable[str] | None = None,
    *,
    plugins: Iterable[str | Path] = (),
    ladder: bool = False,
    candidates: Sequence[str] | None = None,
    alpha: float = DEFAULT_ALPHA,
    cv_folds: int = DEFAULT_CV_FOLDS,
    rank_cv_folds: int | None = None,
    loss: Loss = "linear",
    interactions: bool = True,
    max_ladder_steps: int = DEFAULT_MAX_STEPS,
    source: str | None = None,
    data_options: str = "",
    auto_effects: bool = True,
) -> Diagnosis:
    """Fit the model to the dataset and diagnose it.

    dataset: a Dataset or the path of a dataset file. effects: as for ``hostpc.fit`` (None:
    joint_offsets plus the unknown frames; ``"+joint_compliance"`` adds to that). plugins:
    Python files defining extra effects (their effects become candidates too). ladder: also
    fit the nested models, adding the best candidate while it is significant and lowers the
    held-out whitened RMS (without the outlier samples, if any). candidates:
    the effects to try (default: every registered effect that applies). alpha: family-wise
    significance of each family of tests. cv_folds: folds of the held-out residuals (0 to
    skip); rank_cv_folds: None (the default) or cv_folds judges each candidate on the
    current model's folds (one fold assignment per table: every held-out figure and star
    comparable), 0 skips the candidates' held-out RMS (the p-value alone decides); no other
    value. interactions: run the
    effect-agnostic search. source: the dataset's path, used in the suggested commands;
    data_options: the options that read it as this diagnosis did (" --robot FILE.urdf
    --base-link L --tip-link L"), carried into them so that they run as printed.
    auto_effects: let the ladder build the interaction effect of a significant pattern no
    built-in effect models (``auto_effects``; ``Diagnosis.generated_effects`` holds their
    plugin sources).
    """
    plugin_paths = tuple(str(p) for p in plugins)
    if isinstance(dataset, str | Path):
        source = source or str(dataset)
        dataset = load_dataset(dataset, plugins=plugin_paths)
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha {alpha}: must be between 0 and 1")
    if cv_folds < 0:
        raise InputError("cv_folds must not be negative")
    if rank_cv_folds is None:
        rank_cv_folds = cv_folds
    elif rank_cv_folds not in (0, cv_folds):
        raise InputError(f"rank_cv_folds {rank_cv_folds}: must be 0 or cv_folds "
                         f"({cv_folds}): candidates are held out on the current model's folds")
    registry = available_effects(plugin_paths)
    if candidates is not None:
        check_candidate_names(candidates, registry)
    problem = build_problem(dataset, effects, plugins=plugin_paths)
    if candidates is None:  # physical laws of the logged variables (law_candidates)
        registry = {**registry, **law_effects(problem.context)}
    checker = _Checker(registry, candidates, alpha, cv_folds, rank_cv_folds, loss, interactions)
    start = checker(solve(problem, loss=loss, cv_folds=0))
    residuals = residual_analysis(start, alpha)
    steps: tuple[LadderStep, ...] | None = None
    stop: str | None = None
    if ladder:
        climber = checker.without_outlier_detection()
        base = start.ranked.fit.problem
        steps, stop = climb(start.ranked, climber, max_ladder_steps,
                            propose=climber.propose if auto_effects else None,
                            prune=lambda check, keep: climber.prune(check, base, keep))
    advice = advise(start, residuals, steps, source + data_options if source else None,
                    plugin_paths, ladder_stop=stop)
    ranked = start.ranked
    # at the noise of the samples the candidates were ranked on: without the named outliers
    detectable = candidate_sizes(ranked.fit, registry, [c.effect for c in start.candidates],
                                 alpha)
    confounded = confounded_pairs(ranked.fit, ranked.candidates, registry, alpha=alpha,
                                  cv_folds=rank_cv_folds, loss=loss, plugins=plugin_paths)
    _forget_candidate_fits([start, *(step.check for step in steps or ())])
    return Diagnosis(check=start, residuals=residuals, ladder=steps, advice=advice,
                     alpha=alpha, source=source, plugins=plugin_paths, ladder_stop=stop,
                     detectable=detectable, confounded=confounded)


def _forget_candidate_fits(checks: list[ModelCheck]) -> None:
    """Drop the candidate fits kept on the memos of every problem the diagnosis holds (its
    checks' fits, their cleaned checks', their candidates'): they served its rankings and
    nested tests, and a retained diagnosis would carry every candidate's fit twice over."""
    while checks:
        check = checks.pop()
        if check.cleaned is not None:
            checks.append(check.cleaned)
        for fit in (check.fit, *(candidate.fit for candidate in check.candidates)):
            forget_candidate_fits(fit.problem)
