"""The ladder: fit the nested sequence of models - the current one, then with the best
significant candidate added, and so on - until the model is adequate or the evidence for
any further effect runs out."""

from __future__ import annotations

from collections.abc import Callable

from hostpc.diagnostics.diagnosis import LadderStep, ModelCheck, free_parameters
from hostpc.fitting import FitResult

DEFAULT_MAX_STEPS = 5


def step_of(index: int, check: ModelCheck, added: str | None,
            delta_bic: float | None) -> LadderStep:
    a = check.adequacy
    return LadderStep(step=index, effects=check.effects, added=added, rms=a.rms, max=a.max,
                      cv_rms=a.cv_rms, cv_max=a.cv_max,
                      cv_whitened_rms=a.cv_whitened_rms, chi2_dof=a.chi2_dof,
                      delta_bic=delta_bic, free_parameters=free_parameters(check.fit),
                      adequate=a.adequate, check=check)


def climb(start: ModelCheck, check_model: Callable[[FitResult], ModelCheck],
          max_steps: int = DEFAULT_MAX_STEPS) -> tuple[LadderStep, ...]:
    """The ladder from ``start``; ``check_model`` checks a fit (held-out residuals, candidates
    not yet in it, interactions). Each step adds the best significant candidate."""
    steps = [step_of(0, start, None, None)]
    check = start
    while not check.adequacy.adequate and len(steps) <= max_steps:
        best = check.best_candidate
        if best is None:
            break
        check = check_model(best.fit)
        steps.append(step_of(len(steps), check, best.effect, best.delta_bic))
    return tuple(steps)
