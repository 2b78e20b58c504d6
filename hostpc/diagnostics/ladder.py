"""The ladder: fit the sequence of models - the current one, then with the best
significant candidate added, and so on - until the model is adequate, the evidence for any
further effect runs out, or a step would predict held-out samples worse. After each
addition an effect an earlier step added that is no longer needed is dropped (stepwise
selection), so the models are nested except where a step says what it removed; a drop that
would leave the step predicting held-out samples no better than the step before is not
made, so every step taken lowers the held-out error.

"Worse" is judged on the whitened held-out RMS (every axis of every sample in units of its
own stated noise, which is what the fit minimises): the RMS in mm is dominated by the
noisiest axis (a stereo camera's depth) and may move a little either way when an effect
that is really there is added. Without held-out residuals (``cv_folds`` 0, or too few
samples for the folds) no step can be judged on them and the significance alone decides.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from hostpc.diagnostics.candidates import Candidate
from hostpc.diagnostics.diagnosis import LadderStep, ModelCheck, free_parameters
from hostpc.fitting import FitResult

DEFAULT_MAX_STEPS = 5


def step_of(index: int, check: ModelCheck, added: str | None,
            delta_bic: float | None, removed: tuple[str, ...] = ()) -> LadderStep:
    a = check.adequacy
    return LadderStep(step=index, effects=check.effects, added=added, rms=a.rms, max=a.max,
                      cv_rms=a.cv_rms, cv_max=a.cv_max,
                      cv_whitened_rms=a.cv_whitened_rms, chi2_dof=a.chi2_dof,
                      delta_bic=delta_bic, free_parameters=free_parameters(check.fit),
                      adequate=a.adequate, check=check, removed=removed)


def held_out_worse(before: ModelCheck, after: ModelCheck) -> str | None:
    """Why ``after`` predicts held-out samples no better than ``before`` (a sentence), or
    None when it does better or either lacks held-out residuals."""
    a, b = before.adequacy, after.adequacy
    if a.cv_whitened_rms is None or b.cv_whitened_rms is None:
        return None
    if b.cv_whitened_rms < a.cv_whitened_rms:
        return None
    mm = "" if a.cv_rms is None or b.cv_rms is None else (
        f"; held-out RMS {a.cv_rms * 1e3:.4f} mm -> {b.cv_rms * 1e3:.4f} mm")
    return (f"the whitened held-out RMS would not fall ({a.cv_whitened_rms:.3f} -> "
            f"{b.cv_whitened_rms:.3f} sigma{mm})")


def _bic(candidate: Candidate) -> float:
    return 0.0 if candidate.delta_bic is None else candidate.delta_bic


def search_penalty(check: ModelCheck) -> float:
    """Extended-BIC cost (Chen & Chen 2008) of a generated effect: it is the one pattern
    picked out of the search's ``n_interaction_tests``, ``2 ln n``. A built-in effect is a
    hypothesis named before the data were seen; a generated one must beat it by this much
    (thermal expansion and "q3's zero linear in temperature" fit warming-up data almost
    equally well: the physical effect is taken unless the pattern is clearly better)."""
    return 2.0 * math.log(max(check.n_interaction_tests, 1))


def climb(start: ModelCheck, check_model: Callable[[FitResult], ModelCheck],
          max_steps: int = DEFAULT_MAX_STEPS,
          propose: Callable[[ModelCheck], Candidate | None] | None = None,
          prune: Callable[[ModelCheck, str], tuple[FitResult, str] | None] | None = None,
          ) -> tuple[tuple[LadderStep, ...], str | None]:
    """The ladder from ``start``; ``check_model`` checks a fit (held-out residuals, candidates
    not yet in it, interactions). Each step adds the best significant candidate, unless the
    model with it predicts the held-out samples no better (then the ladder stops there).

    ``propose`` (if given) may offer one more candidate: the interaction effect the search
    suggests (``auto_effects``); it is taken instead of the best built-in candidate when its
    delta BIC plus ``search_penalty`` is lower, and must win on held-out samples too.
    A candidate that would make an identifiable parameter unidentifiable is never taken:
    when it is the only significant one the ladder stops and says so.

    ``prune`` (if given; stepwise selection, forward then backward) looks, after each
    addition, at the effects earlier steps added (not the one just added): it returns the
    model without one that is no longer needed (as a candidate on the model without it, it
    would not be significant) and its name, or None. With several effects hidden at once,
    the first pick can be a flexible effect that mimics the sum of the others (a
    transmission harmonic standing in for compliance and backlash); once those are in, it
    is dropped and the step records it (``LadderStep.removed``), unless the model without
    it would predict the held-out samples no better than the step before (then it stays:
    a step is taken only when it lowers the held-out error).

    Returns the steps and, when the ladder stopped for one of these reasons, a sentence
    saying which effect was not added and why (else None).
    """
    steps = [step_of(0, start, None, None)]
    check = start
    while not check.adequacy.adequate and len(steps) <= max_steps:
        best = check.best_candidate
        proposal = propose(check) if propose is not None else None
        if proposal is not None and (
                best is None or _bic(proposal) + search_penalty(check) < _bic(best)):
            best = proposal
        if best is None:
            costly = check.costly_candidate
            if costly is not None and costly.not_taken is not None:
                return tuple(steps), (f"{costly.effect} is significant but was not added: "
                                      f"{costly.not_taken}")
            break
        extended = check_model(best.fit)
        worse = held_out_worse(check, extended)
        if worse is not None:
            return tuple(steps), (f"{best.effect} is significant in-sample but was not added: "
                                  f"{worse}")
        before, check = check, extended
        removed: list[str] = []
        while prune is not None and len(removed) < len(check.effects):
            dropped = prune(check, best.effect)
            if dropped is None:
                break
            pruned = check_model(dropped[0])
            if held_out_worse(before, pruned) is not None:
                break  # every step predicts the held-out samples better than the last
            check = pruned
            removed.append(dropped[1])
        steps.append(step_of(len(steps), check, best.effect, best.delta_bic, tuple(removed)))
    return tuple(steps), None
