"""Which built-in (or plugin) effect is missing? Fit the model with each candidate added and
rank the candidates by the evidence the data give for it.

Evidence is measured with the noise level profiled out, so a wrong overall scale of the
stated covariances does not matter (n = scalar residual rows, k = free parameters, i.e. the
ones the fit could identify: unidentifiable geometry parameters cost nothing):

- ``delta_bic_full``: BIC(with the effect) - BIC(current), ``BIC = n ln(chi2 / n) + k ln n``.
- ``delta_bic`` (the ranking): the same for the effect's best subset of parameters, chosen by
  forward selection with the extended BIC (Chen & Chen 2008), which adds
  ``2 ln C(K, k)`` for picking k of its K parameters. An effect with many parameters of which
  the data need few (one joint's transmission harmonic, one link's length) then competes
  fairly with a small effect; with nothing selected it is 0.
- ``p_value``: F-test of the chi-square drop, ``F = (dchi2 / dk) / (chi2_new / dof_new)``,
  for the whole effect and for its selected subset (Bonferroni over the C(K, k) subsets),
  the smaller of the two doubled. A candidate is significant when ``p_value`` is below
  ``alpha`` divided by the number of candidates tried (Bonferroni) *and* the model with it
  predicts held-out samples better (lower whitened held-out RMS, same folds as the current
  model's). A candidate with no parameter selected is never significant.
- The row's model: the whole effect, the model its advice (``--effects +E``) fits. Every
  figure of the row (RMS, chi2/dof, held-out RMS, the star) and the fit the ladder adopts
  are that one model's. The selected subset only ranks: held at nominal, the parameters the
  data determine but did not select would bias the zero offsets.
  The p-value takes the better of the two forms (doubled, as above).
- ``unidentifiable``: parameters the current model identifies that the model with the
  candidate cannot (the fit holds them at nominal): adding backlash to probe data whose
  joint 4 always arrives from one side hides joint 4's offset in the backlash. Such a
  candidate is never taken silently: ``not_taken`` says why, and the ladder skips it.

A candidate is *not testable* when the data leave the model with it no degrees of freedom:
the current model or the extended one (or its selected subset) has at least as many free
parameters as scalar residual rows. Its chi-square is then ~0 and ``ln(chi2)`` runs to minus
infinity, so its BIC and p-value mean nothing: they are None, it is never significant and it
ranks after every testable candidate.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hostpc.diagnostics.adequacy import held_out_residuals
from hostpc.diagnostics.distributions import f_sf
from hostpc.errors import InputError
from hostpc.fitting import FitResult, solve
from hostpc.fitting.priors import with_constraints
from hostpc.fitting.solver import REUSE_ELEMENTS, Evaluation, Loss, evaluate
from hostpc.json_object import JsonObject
from hostpc.model import joint_offsets
from hostpc.model.effect import Effect
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import extend_problem


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class Candidate:
    """One effect tried on top of the current model.

    delta_bic: extended BIC of its best parameter subset minus the current model's (negative
    is better; the ranking; None when not testable); delta_bic_full: the BIC change with all
    its parameters (None when not testable);
    selected: the parameters of that subset; delta_chi2: the chi-square drop with all its
    parameters; added_parameters: free parameters it added; rms, max, cv_rms: in-sample and
    held-out residual norms with it (m); chi2_dof with it; p_value: see the module doc;
    significant: p_value below the corrected threshold; strongest: its most telling
    parameter (the first selected, else the largest |value / sigma|) and its value / sigma;
    fit: the fit with it added (not serialised); testable: False when the samples leave no
    degrees of freedom to judge it (then delta_bic, delta_bic_full and p_value are None);
    held: the effect's parameters held at nominal in the row's model (its selected subset
    predicts better held out than all of them; see ``try_candidate``), empty when the row is
    the full effect's. Every figure of the row (rms, max, chi2_dof, cv_rms, the star) and
    ``fit`` belong to that one model.
    """

    effect: str
    delta_bic: float | None
    delta_bic_full: float | None
    selected: tuple[str, ...]
    delta_chi2: float
    added_parameters: int
    rms: float
    max: float
    cv_rms: float | None
    cv_folds: int
    chi2_dof: float
    p_value: float | None
    significant: bool
    strongest: tuple[str, float] | None
    fit: FitResult
    testable: bool = True
    cv_whitened_rms: float | None = None
    unidentifiable: tuple[str, ...] = ()
    not_taken: str | None = None

    @property
    def taken(self) -> bool:
        """Whether the ladder would add it: significant and no identifiable parameter lost."""
        return self.significant and not self.unidentifiable

    def to_dict(self) -> JsonObject:
        return {
            "effect": self.effect,
            "delta_bic": _finite(self.delta_bic),
            "rms": self.rms,
            "cv_rms": _finite(self.cv_rms),
            "max": self.max,
            "chi2_dof": _finite(self.chi2_dof),
            "delta_bic_full": _finite(self.delta_bic_full),
            "selected": list(self.selected),
            "delta_chi2": _finite(self.delta_chi2),
            "added_parameters": self.added_parameters,
            "p_value": _finite(self.p_value),
            "significant": self.significant,
            "strongest_parameter": None if self.strongest is None else self.strongest[0],
            "strongest_z": None if self.strongest is None else _finite(self.strongest[1]),
            "cv_folds": self.cv_folds,
            "testable": self.testable,
            "cv_whitened_rms": _finite(self.cv_whitened_rms),
            "unidentifiable": list(self.unidentifiable),
            "not_taken": self.not_taken,
        }


@dataclass(frozen=True)
class SkippedCandidate:
    """An effect that could not be tried on this dataset, and why (e.g. no mass data)."""

    effect: str
    reason: str


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def free_count(result: FitResult) -> int:
    return int(np.count_nonzero(~result.fixed))


def bic(result: FitResult) -> float:
    """n ln(chi2 / n) + k ln(n) with n scalar rows and k free parameters."""
    n_rows = result.residuals_whitened.size
    chi2 = max(result.chi2, 1e-300)
    return float(n_rows * math.log(chi2 / n_rows) + free_count(result) * math.log(n_rows))


def f_test(base: FitResult, extended: FitResult) -> tuple[float, float, int]:
    """(delta chi2, p-value, added free parameters) of the extended model against base."""
    added = free_count(extended) - free_count(base)
    delta = base.chi2 - extended.chi2
    if added <= 0 or extended.dof <= 0 or delta <= 0:
        return delta, 1.0, max(added, 0)
    statistic = (delta / added) / (extended.chi2 / extended.dof)
    return delta, float(f_sf(statistic, added, extended.dof)), added


def candidate_effects(problem: Problem, registry: Mapping[str, type[Effect]],
                      only: Sequence[str] | None = None) -> list[str]:
    """Names of the effects that could be added: not in the model, not a frame, and applying
    to the dataset's method. ``only`` restricts (and orders) the list; naming an unknown
    effect or a frame in it is an InputError (a frame is part of the model, chosen with
    ``effects``, never a candidate)."""
    names = list(registry) if only is None else list(only)
    if only is not None:
        check_candidate_names(names, registry)
    chosen = []
    for name in names:
        cls = registry[name]
        if name in problem.effect_names or cls.hook == "frame":
            continue
        if not problem.measurement.accepts(cls):
            continue
        chosen.append(name)
    return chosen


def check_candidate_names(names: Sequence[str], registry: Mapping[str, type[Effect]]
                          ) -> None:
    """Raise one InputError naming every unknown effect and every frame among ``names``."""
    unknown = [n for n in names if n not in registry]
    if unknown:
        known = ", ".join(sorted(n for n, c in registry.items() if c.hook != "frame"))
        listed = ", ".join(repr(n) for n in unknown)
        verb = "effect {} is" if len(unknown) == 1 else "effects {} are"
        raise InputError(f"candidate {verb.format(listed)} unknown; known effects: {known}")
    frames = [n for n in names if registry[n].hook == "frame"]
    if frames:
        listed = ", ".join(repr(n) for n in frames)
        what = ("{} is a frame, not a candidate effect" if len(frames) == 1
                else "{} are frames, not candidate effects").format(listed)
        raise InputError(f"--candidates: {what}; frames are part of the model (choose them "
                         f"with --effects): remove {listed} from the candidates")


def warm_start(base: FitResult, problem: Problem) -> np.ndarray:
    """The base fit's values placed in the extended layout (new parameters at zero)."""
    values = dict(zip(base.names, base.x, strict=True))
    return np.array([values.get(name, 0.0) for name in problem.layout.names])


def with_held_out(result: FitResult, folds: int) -> tuple[FitResult, float | None]:
    """The fit with its cross-validated RMS filled in (from ``held_out_residuals``), and its
    whitened held-out RMS (None without held-out residuals)."""
    held = held_out_residuals(result.problem, result.x, ~result.fixed, folds)
    if held is None:
        return result, None
    return replace(result, cv_rms=held.rms, cv_folds=folds), held.whitened_rms


def lost_parameters(base: FitResult, extended: FitResult) -> tuple[str, ...]:
    """Parameters free (identifiable) in ``base`` that ``extended`` holds fixed (leaving out
    those of effects whose parameters are ``traded_freely``)."""
    held = {name for name, fixed in zip(extended.names, extended.fixed, strict=True) if fixed}
    return tuple(name for name, fixed in zip(base.names, base.fixed, strict=True)
                 if not fixed and name in held
                 and not _traded_freely(base, name.split(".", 1)[0]))


def _traded_freely(result: FitResult, effect: str) -> bool:
    term = result.problem.term(effect)
    return term is not None and term.effect.traded_freely




def remedy(effect: str, lost: Sequence[str], effect_names: Sequence[str],
           approach_dependent: bool = False) -> str:
    """What to do when adding ``effect`` makes ``lost`` unidentifiable (a sentence part);
    effect_names: the effect's parameter names (full), to name the one each trades with;
    approach_dependent: the effect's (``Effect.approach_dependent``): reaching the joints
    from both sides tells it apart."""
    joints, partners = [], []
    for name in lost:
        offset = joint_offsets.match(name)
        if offset is None:
            continue
        joints.append(f"{offset.branch}{offset.joint}")
        # a per-joint parameter (backlash.b4, backlash.left.b4) or a per-joint term
        # (transmission_harmonic.sin1_q4, transmission_harmonic.sin1_left.q4)
        branch = re.escape(offset.branch)
        own = re.compile(rf"{re.escape(effect)}\.({branch}[a-z]+{offset.joint}"
                         rf"|[a-z]+\d+_{branch}q{offset.joint})$")
        partners += [n for n in effect_names if own.match(n)]
    plural = "s" if len(joints) > 1 else ""
    if approach_dependent and joints:
        how = (f"approach joint{plural} {', '.join(joints)} from both sides in the measured "
               f"poses (hostpc calibrate plans that when {effect} is in the model)")
    elif joints:
        how = f"vary joint{plural} {', '.join(joints)} more widely"
    else:
        how = "vary the poses so the data can tell them apart"
    held = ",".join(partners) if partners else f"{effect}.NAME"
    return (f"adding {effect} makes {', '.join(lost)} unidentifiable: {how}, or add it with "
            f"--hold {held} (or a --prior on it)")


def not_taken_reason(candidate: Candidate, p_significant: bool, threshold: float,
                     base_cv: float | None) -> str | None:
    """Why a candidate is not taken (a sentence part), or None when it is."""
    if not candidate.testable:
        return "too few samples to test it"
    if not candidate.fit.converged:
        return (f"the fit with it did not converge ({candidate.fit.message}): never adopted; "
                "add poses that move its parameters, or hold the weak ones with --hold")
    if not candidate.selected:
        return "the data select none of its parameters (delta BIC 0): nothing to add"
    if not p_significant:
        return f"not significant (p = {candidate.p_value:.2g}, threshold {threshold:.2g})"
    if candidate.cv_whitened_rms is not None and base_cv is not None \
            and candidate.cv_whitened_rms >= base_cv:
        return (f"significant in-sample (p = {candidate.p_value:.2g}) but predicts held-out "
                f"samples worse ({base_cv:.3f} -> {candidate.cv_whitened_rms:.3f} sigma)")
    if candidate.unidentifiable:
        span = candidate.fit.problem.layout.effect_slices[candidate.effect]
        term = candidate.fit.problem.term(candidate.effect)
        return remedy(candidate.effect, candidate.unidentifiable,
                      list(candidate.fit.names[span]),
                      term is not None and term.effect.approach_dependent)
    return None


def _strongest(result: FitResult, effect: str, selected: tuple[str, ...]
               ) -> tuple[str, float] | None:
    span = result.problem.layout.effect_slices[effect]
    best: tuple[str, float] | None = None
    for k in range(span.start, span.stop):
        if result.fixed[k] or not np.isfinite(result.std[k]) or result.std[k] <= 0:
            continue
        z = float(result.x[k] / result.std[k])
        if selected and result.names[k] == selected[0]:
            return (result.names[k], z)
        if best is None or abs(z) > abs(best[1]):
            best = (result.names[k], z)
    return best


def _log_choose(n: int, k: int) -> float:
    return math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)


def select_subset(base: FitResult, extended: FitResult, x0: np.ndarray,
                  evaluation: Evaluation | None = None) -> tuple[list[int], float]:
    """Forward selection of the new effect's parameters by the extended BIC, linearised at
    the current solution x0 (in the extended layout). Returns the chosen parameter indices
    (extended layout) and the extended BIC penalty of choosing them. evaluation: the
    extended problem at x0, if already evaluated."""
    problem = extended.problem
    n_base = base.x.size
    free = ~extended.fixed
    new = [k for k in range(n_base, free.size) if free[k]]
    if not new:
        return [], 0.0
    if evaluation is None or evaluation.jacobian is None:
        evaluation = evaluate(problem, x0)
    J = evaluation.jacobian
    assert J is not None
    r = evaluation.whitened.ravel()
    B = J[:, :n_base][:, free[:n_base]]
    basis = np.linalg.qr(B)[0] if B.shape[1] else np.zeros((r.size, 0))
    C = J[:, new]
    sizes = np.maximum(np.linalg.norm(C, axis=0), 1e-300)
    C = C - basis @ (basis.T @ C)
    e = r - basis @ (basis.T @ r)
    n_rows = r.size
    chi2 = float(e @ e)
    n_new = len(new)
    chosen: list[int] = []
    score = n_rows * math.log(max(chi2, 1e-300) / n_rows)
    while len(chosen) < n_new:
        norms = np.linalg.norm(C, axis=0)
        usable = norms > 1e-6 * sizes
        usable[chosen] = False
        if not np.any(usable):
            break
        gains = np.where(usable, (C.T @ e) ** 2 / np.maximum(norms**2, 1e-300), -1.0)
        pick = int(np.argmax(gains))
        k = len(chosen) + 1
        trial_chi2 = max(chi2 - float(gains[pick]), 1e-300)
        trial = (n_rows * math.log(trial_chi2 / n_rows) + k * math.log(n_rows)
                 + 2.0 * _log_choose(n_new, k))
        previous = (score + (k - 1) * math.log(n_rows) + 2.0 * _log_choose(n_new, k - 1))
        if trial >= previous:
            break
        u = C[:, pick] / norms[pick]
        C = C - np.outer(u, u @ C)
        e = e - u * (u @ e)
        chi2 = trial_chi2
        score = n_rows * math.log(chi2 / n_rows)
        chosen.append(pick)
    indices = [new[c] for c in chosen]
    return indices, (len(indices) * math.log(n_rows) + 2.0 * _log_choose(n_new, len(indices)))


def try_candidate(base: FitResult, effect: Effect, *, cv_folds: int, loss: Loss,
                  threshold: float, base_cv: float | None = None) -> Candidate:
    """Fit the base model plus ``effect``, warm-started at the base solution; find the
    subset of its parameters the data need and the evidence for it (not testable, see the
    module doc, when the samples leave no degrees of freedom).

    The candidate's figures (RMS, max, chi2/dof, held-out RMS, the star) and its ``fit``
    all belong to one model, the whole effect: the model its advice (``--effects +E``)
    fits. The selected subset ranks it (delta BIC, its p) but is not the
    row's model: holding at nominal parameters the data determine biases the zero offsets
    (a 4 sigma error with compliance and geometry hidden together). Held out on the same
    pose-grouped folds (``cv_folds``) as ``base_cv``.

    The fits depend on the base fit, the effect, ``cv_folds`` and ``loss`` only, not on
    ``threshold`` or ``base_cv``: they are kept on the base problem's memo, so the same
    effect tried again on the same fit (a ladder step's candidate, then a confounded
    pair's nested test) is judged afresh without being fitted again."""
    candidate = _fitted_candidate(base, effect, cv_folds, loss)
    # nothing selected: the data need none of its parameters, so it is never starred
    p_significant = bool(candidate.testable and candidate.selected
                         and candidate.p_value is not None and candidate.p_value < threshold)
    cv_whitened = candidate.cv_whitened_rms
    held_out_better = (cv_whitened is None or base_cv is None or cv_whitened < base_cv)
    candidate = replace(candidate, significant=p_significant and held_out_better
                        and candidate.fit.converged)
    return replace(candidate, not_taken=not_taken_reason(candidate, p_significant, threshold,
                                                         base_cv))


CANDIDATE_SLOT = "candidate "
"""How the memo keys of ``try_candidate``'s kept fits begin (``forget_candidate_fits``)."""


def forget_candidate_fits(problem: Problem) -> None:
    """Drop the candidate fits kept on ``problem``'s memo: once a diagnosis is done, nothing
    judges them again, and a retained result would carry every candidate's fit."""
    problem.memo.forget(CANDIDATE_SLOT)


def _fitted_candidate(base: FitResult, effect: Effect, cv_folds: int, loss: Loss
                      ) -> Candidate:
    """``try_candidate``'s fits and figures, not yet judged (``significant`` False,
    ``not_taken`` None), computed once per base fit, effect class, folds and loss."""
    key = f"{CANDIDATE_SLOT}{effect.name} {cv_folds} {loss}"
    kept: Candidate | None = _recall(base, key, effect)
    if kept is None:
        kept = _fit_candidate(base, effect, cv_folds, loss)
        _keep(base, key, effect, kept)
    return kept


CandidateStart = tuple[Problem, np.ndarray, Evaluation, np.ndarray | None]
"""``candidate_start``'s (the base model plus the effect, the warm start x0 in it, the
evaluation at x0, and the raw derivative of the predictions at x0, (N, m, P), or None for
a problem too large to keep)."""


def candidate_start(base: FitResult, effect: Effect) -> CandidateStart:
    """The base model plus ``effect`` (``extend_problem``) evaluated at the warm start
    (``warm_start``), from one prediction. The candidate's fit starts there
    (``try_candidate``), its detectable sizes are linearised there (``hostpc.diagnostics.
    detectable``) and the interaction search takes geometry's columns there: kept on the
    base problem's memo like the candidate fits (``forget_candidate_fits`` drops it), so
    they share one prediction; a problem whose Jacobian ``evaluate`` would not keep
    (``REUSE_ELEMENTS``) is not kept either, and each asks for it again. The evaluation is
    ``evaluate``'s: the same operations on the same prediction, so the same values."""
    key = f"{CANDIDATE_SLOT}{effect.name} start"
    kept: CandidateStart | None = _recall(base, key, effect)
    if kept is not None:
        return kept
    problem = extend_problem(base.problem, [effect])
    x0 = warm_start(base, problem)
    if problem.measured.size * x0.size > REUSE_ELEMENTS:  # large: not kept (as ``evaluate``)
        return problem, x0, evaluate(problem, x0), None
    evaluation, d_predicted = evaluated_with_derivative(problem, x0)
    for array in (x0, evaluation.raw, evaluation.whitened, evaluation.jacobian, d_predicted):
        if array is not None:
            array.setflags(write=False)  # shared by the fit, the sizes and the search
    start = (problem, x0, evaluation, d_predicted)
    _keep(base, key, effect, start)
    return start


def evaluated_with_derivative(problem: Problem, x: np.ndarray
                              ) -> tuple[Evaluation, np.ndarray]:
    """``evaluate``'s evaluation at x with its Jacobian (the same operations on the same
    prediction, so the same values) and the raw derivative of the predictions (N, m, P),
    from one prediction, in one piece."""
    predicted, d_predicted = predict(problem, x, True)
    assert d_predicted is not None
    raw = problem.measured - predicted
    W = problem.sqrt_information
    return Evaluation(x=x, raw=raw, whitened=(W @ raw[:, :, None])[:, :, 0],
                      jacobian=-(W @ d_predicted).reshape(-1, x.size)), d_predicted


def _recall(base: FitResult, key: str, effect: Effect) -> Any:
    """The value kept under ``key`` on the base problem's memo for this effect (its class
    and state) at this base fit (its x and fixed mask), or None."""
    recalled = base.problem.memo.recall(key)
    if recalled is None:
        return None
    identity, x, fixed, value = recalled
    if (identity == _identity(effect) and np.array_equal(x, base.x)
            and np.array_equal(fixed, base.fixed)):
        return value
    return None


def _keep(base: FitResult, key: str, effect: Effect, value: object) -> None:
    """Keep ``value`` for ``_recall``; an effect whose state does not compare is not kept."""
    identity = _identity(effect)
    if identity is not None:
        base.problem.memo.remember(key, (identity, base.x.copy(), base.fixed.copy(), value))


def _identity(effect: Effect) -> tuple[type, tuple[tuple[str, Any], ...]] | None:
    """The effect's class and state, or None if its state is not plain values."""
    state = vars(effect)
    if not all(isinstance(v, str | int | float | bool | None) for v in state.values()):
        return None
    return type(effect), tuple(sorted(state.items()))


def _fit_candidate(base: FitResult, effect: Effect, cv_folds: int, loss: Loss) -> Candidate:
    # shared by the fit, the subset choice and the subset fit (and the detectable sizes)
    problem, x0, start, _ = candidate_start(base, effect)
    extended = solve(problem, x0=x0, loss=loss, cv_folds=0, max_iterations=50, initial=start)
    extended, cv_whitened = with_held_out(extended, cv_folds)
    delta_chi2, p_full, added = f_test(base, extended)
    testable = base.dof > 0 and extended.dof > 0
    chosen, penalty = select_subset(base, extended, x0, start) if testable else ([], 0.0)
    n_rows = base.residuals_whitened.size
    delta_bic = 0.0
    p_subset = 1.0
    dof_subset = 0
    if chosen:
        free = np.zeros(problem.layout.size, dtype=bool)
        free[: base.x.size] = ~extended.fixed[: base.x.size]
        free[chosen] = True
        dof_subset = n_rows - int(np.count_nonzero(free))
        testable = dof_subset > 0
    if chosen and testable:
        # held: the effect's parameters left out of the subset, and the base model's
        # parameters the full effect left undetermined (its subset is judged on the same
        # base parameters as the full effect: ``unidentifiable`` says which)
        hold = tuple(problem.layout.names[k] for k in np.flatnonzero(~free)
                     if not extended.fixed[k] or (k < base.x.size and not base.fixed[k]))
        subset = _subset_fit(problem, hold, x0, loss, start)
        chi2_subset = subset.chi2
        delta_bic = (n_rows * math.log(max(chi2_subset, 1e-300) / max(base.chi2, 1e-300))
                     + penalty)
        drop = base.chi2 - chi2_subset
        if drop > 0:
            statistic = (drop / len(chosen)) / (chi2_subset / dof_subset)
            n_new = int(np.count_nonzero(~extended.fixed[base.x.size:]))
            p_subset = min(1.0, float(f_sf(statistic, len(chosen), dof_subset))
                           * math.exp(_log_choose(n_new, len(chosen))))
    p_value = min(1.0, 2.0 * min(p_full, p_subset))
    selected = tuple(problem.layout.names[k] for k in chosen) if testable else ()
    return Candidate(
        effect=effect.name, delta_bic=delta_bic if testable else None,
        delta_bic_full=bic(extended) - bic(base) if testable else None,
        selected=selected, delta_chi2=delta_chi2, added_parameters=added, rms=extended.rms,
        max=extended.max, cv_rms=extended.cv_rms, cv_folds=extended.cv_folds,
        chi2_dof=extended.chi2_dof, p_value=p_value if testable else None,
        significant=False, strongest=_strongest(extended, effect.name, selected),
        fit=extended, testable=testable, cv_whitened_rms=cv_whitened,
        unidentifiable=lost_parameters(base, extended),
    )


def _subset_fit(problem: Problem, hold: Sequence[str], x0: np.ndarray, loss: Loss,
                start: Evaluation) -> FitResult:
    """The extended model fitted with ``hold`` (the effect's parameters the subset leaves
    out) held at nominal: a dataset-level hold (``hostpc.fitting.priors``), so the fit, its
    held-out residuals and every model built on it (a ladder step) keep them held, exactly
    as ``--hold`` does."""
    held = replace(problem, dataset=with_constraints(problem.dataset, hold=list(hold)))
    return solve(held, x0=x0, loss=loss, cv_folds=0, max_iterations=50, initial=start)


def ranking_key(candidate: Candidate) -> tuple[bool, bool, float, float]:
    """Best first: significant ones, then testable ones by delta BIC, then the rest."""
    def value(v: float | None) -> float:
        return math.inf if v is None else v

    return (not candidate.significant, not candidate.testable, value(candidate.delta_bic),
            value(candidate.delta_bic_full))


def rank_candidates(base: FitResult, registry: Mapping[str, type[Effect]],
                    names: Sequence[str], *, alpha: float, cv_folds: int, loss: Loss
                    ) -> tuple[tuple[Candidate, ...], tuple[SkippedCandidate, ...]]:
    """Try every named candidate; return them best first (significant ones, then by delta
    BIC, the not testable ones last) and the ones that could not be tried."""
    threshold = alpha / max(len(names), 1)
    base_held = held_out_residuals(base.problem, base.x, ~base.fixed, cv_folds) \
        if names else None
    base_cv = None if base_held is None else base_held.whitened_rms
    tried: list[Candidate] = []
    skipped: list[SkippedCandidate] = []
    for name in names:
        try:
            tried.append(try_candidate(base, registry[name](), cv_folds=cv_folds, loss=loss,
                                       threshold=threshold, base_cv=base_cv))
        except InputError as exc:
            skipped.append(SkippedCandidate(name, str(exc)))
    tried.sort(key=ranking_key)
    return tuple(tried), tuple(skipped)
