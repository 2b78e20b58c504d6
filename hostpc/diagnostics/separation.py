"""Separating experiments: two candidates the data cannot tell apart, and what would.

Two significant candidates A and B are *confounded* when neither is significant added to
the model that already has the other (``nested_test``: A given B, B given A, each judged
like any candidate, ``try_candidate``): the data explain the residuals with either. Single
sphere probe data are the usual case: joint compliance, encoder scale, a transmission
harmonic and geometry bend the contacts alike.

What separates them is the test of one given the other. Linearised at the current fit,
with J the whitened Jacobian of the model with both (rows: samples) and a the fitted
values of A's parameters, the chi-square that A buys on top of the model with B when A is
what is there is the noncentrality

    lambda(A | B) = |(I - P_[model, B]) J_A a|^2 / s^2

(P: the projection on the columns of the model and B's free parameters; s^2 the fit's
chi2/dof when above 1), and the same for B given A. A separating plan adds the poses of
the kind's reachable pool that raise both (``hostpc.planning.separate``) until each test
has the power ``DEFAULT_POWER`` at its threshold: the fewest extra poses after which the
right candidate is significant given the wrong one and not the other way round. The
re-diagnosis after measuring them is ``nested_test`` again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from hostpc.dataset import Dataset
from hostpc.diagnostics.candidates import Candidate, try_candidate
from hostpc.diagnostics.detectable import DEFAULT_POWER, power, required_noncentrality
from hostpc.diagnostics.distributions import chi2_isf
from hostpc.errors import InputError
from hostpc.fitting import FitResult
from hostpc.fitting.solver import Loss, evaluate
from hostpc.model.effect import Effect
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem, extend_problem

#: significant candidates (best first) among which confounded pairs are looked for
MAX_CONFOUNDED = 3


@dataclass(frozen=True)
class NestedTest:
    """``effect`` added to the model with ``given``: its p-value and whether it is
    significant (``Candidate.significant`` at ``threshold``)."""

    effect: str
    given: str
    p_value: float | None
    significant: bool
    threshold: float

    @property
    def sentence(self) -> str:
        p = "untestable" if self.p_value is None else f"p = {self.p_value:.2g}"
        verdict = "significant" if self.significant else "not significant"
        return f"{self.effect} given {self.given}: {verdict} ({p}, threshold {self.threshold:.2g})"

    def to_dict(self) -> dict[str, object]:
        p = self.p_value if self.p_value is not None and math.isfinite(self.p_value) else None
        return {"effect": self.effect, "given": self.given, "p_value": p,
                "significant": self.significant, "threshold": self.threshold}


@dataclass(frozen=True)
class PairTest:
    """Both nested tests of a pair: ``first`` is A given B, ``second`` B given A;
    noncentrality: the chi-square gain each test would see on these data if that
    candidate were what is there (``noncentralities``), and needed: the gain each needs to
    find it with ``DEFAULT_POWER`` (None when not computed)."""

    first: NestedTest
    second: NestedTest
    noncentrality: tuple[float, float] | None = None
    needed: tuple[float, float] | None = None
    sizes: tuple[int, int] = (1, 1)

    def gain(self, k: int) -> tuple[float | None, float]:
        """Test ``k``'s (0: A given B, 1: B given A) observed chi-square gain and the gain at
        which it passes its threshold, on the one-parameter scale of ``pair_threshold``
        (the p-value's doubling and Bonferroni over the effect's ``sizes[k]`` parameters
        undone alike): the gain passes exactly when the p-value passes the threshold. The
        observed gain is None when the test was untestable."""
        test = (self.first, self.second)[k]
        passing = chi2_isf(test.threshold / 2.0 / self.sizes[k], 1)
        if test.p_value is None:
            return None, passing
        if test.p_value >= 1.0:  # no chi-square drop at all (the p-value is capped at 1)
            return 0.0, passing
        one = max(test.p_value / 2.0 / self.sizes[k], 1e-300)
        return chi2_isf(min(one, 1.0), 1), passing

    @property
    def gain_sentence(self) -> str | None:
        """The observed and predicted separation in words, on one scale, or None."""
        if self.noncentrality is None or self.needed is None:
            return None
        parts = []
        for k, (a, b) in enumerate((self.names, self.names[::-1])):
            seen, passing = self.gain(k)
            observed = "" if seen is None else f"gains {seen:.3g} on these data, "
            parts.append(f"{a} given {b} {observed}passes its threshold at {passing:.3g}; "
                         f"{a} at its fitted size would give {self.noncentrality[k]:.3g} on "
                         f"average (needs {self.needed[k]:.3g} for {DEFAULT_POWER:.0%} power)")
        return "chi-square gains (one-parameter scale of the p-values): " + "; ".join(parts)

    @property
    def names(self) -> tuple[str, str]:
        return self.first.effect, self.second.effect

    @property
    def confounded(self) -> bool:
        """Neither is significant given the other: the data cannot tell them apart."""
        return not self.first.significant and not self.second.significant

    @property
    def winner(self) -> str | None:
        """The one significant given the other while the other is not, else None."""
        if self.first.significant != self.second.significant:
            return self.first.effect if self.first.significant else self.second.effect
        return None

    @property
    def sentence(self) -> str:
        a, b = self.names
        if self.winner is not None:
            loser = b if self.winner == a else a
            what = f"the data choose {self.winner}: it is significant given {loser}, not " \
                   f"the other way round"
        elif self.confounded:
            what = f"the data cannot tell {a} from {b}: neither is significant given the other"
        else:
            what = f"{a} and {b} are both significant given the other: both are there"
        return f"{what} ({self.first.sentence}; {self.second.sentence})"

    def to_dict(self) -> dict[str, object]:
        document: dict[str, object] = {
            "effects": list(self.names), "confounded": self.confounded,
            "winner": self.winner, "tests": [self.first.to_dict(), self.second.to_dict()]}
        if self.noncentrality is not None and self.needed is not None:
            document["noncentrality"] = list(self.noncentrality)
            document["needed"] = list(self.needed)
        return document


def nested_test(with_given: FitResult, effect: Effect, given: str, *, alpha: float,
                cv_folds: int, loss: Loss) -> NestedTest:
    """``effect`` tried on the fit that already has ``given`` (threshold ``alpha``)."""
    candidate = try_candidate(with_given, effect, cv_folds=cv_folds, loss=loss,
                              threshold=alpha)
    return NestedTest(effect.name, given, candidate.p_value, candidate.significant, alpha)


def pair_test(a: Candidate, b: Candidate, registry: Mapping[str, type[Effect]], *,
              alpha: float, cv_folds: int, loss: Loss) -> PairTest:
    """A given B and B given A, each at ``alpha / 2`` (two tests)."""
    threshold = alpha / 2.0
    return PairTest(
        nested_test(b.fit, registry[a.effect](), b.effect, alpha=threshold,
                    cv_folds=cv_folds, loss=loss),
        nested_test(a.fit, registry[b.effect](), a.effect, alpha=threshold,
                    cv_folds=cv_folds, loss=loss))


def confounded_pairs(base: FitResult, candidates: Sequence[Candidate],
                     registry: Mapping[str, type[Effect]], *, alpha: float,
                     cv_folds: int, loss: Loss, plugins: Sequence[str] = ()
                     ) -> tuple[PairTest, ...]:
    """The confounded pairs of the best significant candidate (of ``base``) with the next
    ones (up to ``MAX_CONFOUNDED`` significant candidates in all), with the chi-square
    gain each nested test sees on ``base``'s samples and the gain it needs."""
    significant = [c for c in candidates if c.significant][:MAX_CONFOUNDED]
    pairs = []
    for other in significant[1:]:
        try:
            test = pair_test(significant[0], other, registry, alpha=alpha,
                             cv_folds=cv_folds, loss=loss)
        except InputError:
            continue
        if not test.confounded:
            continue
        try:
            model = pair_model(base, significant[0], other, registry, plugins)
            rows = measured_rows(base, model)
        except InputError:
            pairs.append(test)
            continue
        pairs.append(replace(test, noncentrality=noncentralities(model, rows),
                             needed=needed_noncentralities(model, alpha), sizes=model.sizes))
    return tuple(pairs)


# ---------------------------------------------------------------- the predicted separation

@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class PairModel:
    """A confounded pair on one dataset, linearised for planning: the model with both
    effects (its parameter names ``layout``), the point of linearisation ``x``, the signal of each
    candidate (its fitted values, zero elsewhere), the columns that absorb it (the model
    and the other candidate's free parameters) and the noise scale of each fit."""

    names: tuple[str, str]
    effects: tuple[Effect, Effect]
    effect_names: tuple[str, ...]
    plugins: tuple[str, ...]
    layout: tuple[str, ...]
    x: np.ndarray
    signals: tuple[np.ndarray, np.ndarray]
    absorb: tuple[np.ndarray, np.ndarray]
    scales: tuple[float, float]
    sizes: tuple[int, int] = (1, 1)

    def blocks(self, dataset: Dataset) -> np.ndarray:
        """(N, m, P) whitened Jacobian blocks of the model with both at ``dataset``'s
        samples (P: ``layout``)."""
        base = build_problem(dataset, list(self.effect_names), plugins=self.plugins)
        problem = extend_problem(base, list(self.effects))
        index = {name: k for k, name in enumerate(problem.layout.names)}
        x = np.zeros(problem.layout.size)
        for name, value in zip(self.layout, self.x, strict=True):
            if name in index:
                x[index[name]] = value
        _, J = predict(problem, x, jacobian=True)
        assert J is not None
        A = np.einsum("nij,njp->nip", problem.sqrt_information, J)
        out = np.zeros((A.shape[0], A.shape[1], len(self.layout)))
        for k, name in enumerate(self.layout):
            if name in index:
                out[:, :, k] = A[:, :, index[name]]
        return out


def pair_model(base: FitResult, a: Candidate, b: Candidate,
               registry: Mapping[str, type[Effect]], plugins: Sequence[str] = ()
               ) -> PairModel:
    """The pair (A, B) of candidates of ``base`` linearised at ``base``'s solution."""
    effects = (registry[a.effect](), registry[b.effect]())
    problem = extend_problem(base.problem, list(effects))
    names = problem.layout.names
    values = dict(zip(base.names, base.x, strict=True))
    x = np.array([values.get(name, 0.0) for name in names])
    free_base = {n for n, fixed in zip(base.names, base.fixed, strict=True) if not fixed}
    signals, absorb, scales, sizes = [], [], [], []
    for own, other in ((a, b), (b, a)):
        fitted = dict(zip(own.fit.names, own.fit.x, strict=True))
        span = problem.layout.effect_slices[own.effect]
        signal = np.zeros(len(names))
        signal[span] = [fitted.get(n, 0.0) for n in names[span]]
        other_free = {n for n, fixed in zip(other.fit.names, other.fit.fixed, strict=True)
                      if not fixed}
        absorb.append(np.array([n in free_base or (n in other_free and
                                                   n.split(".", 1)[0] == other.effect)
                                for n in names]))
        signals.append(signal)
        scales.append(max(own.fit.chi2_dof, 1.0) if own.fit.dof > 0 else 1.0)
        # the effect's parameters the data determine: the Bonferroni of its p-value
        # (try_candidate) counts all of them
        sizes.append(max(1, int(np.count_nonzero(~own.fit.fixed[span]))))
    return PairModel((a.effect, b.effect), effects, base.problem.effect_names,
                     tuple(str(p) for p in plugins), names, x,
                     (signals[0], signals[1]), (absorb[0], absorb[1]),
                     (scales[0], scales[1]), (sizes[0], sizes[1]))


def measured_rows(base: FitResult, model: PairModel) -> np.ndarray:
    """(R, P) the whitened Jacobian of the model with both on ``base``'s samples."""
    problem = extend_problem(base.problem, list(model.effects))
    J = evaluate(problem, model.x).jacobian
    assert J is not None and problem.layout.names == model.layout
    return J


def noncentralities(model: PairModel, rows: np.ndarray) -> tuple[float, float]:
    """(lambda(A | B), lambda(B | A)) on the whitened Jacobian rows (R, P)."""
    out = []
    for signal, absorb, scale in zip(model.signals, model.absorb, model.scales, strict=True):
        s = rows @ signal
        X = rows[:, absorb]
        if X.shape[1]:
            coefficients = np.linalg.lstsq(X, s, rcond=1e-10)[0]
            s = s - X @ coefficients
        out.append(float(s @ s) / scale)
    return out[0], out[1]


def pair_threshold(alpha: float, size: int = 1) -> float:
    """The level a nested test's signal must reach, as a one-parameter test: ``pair_test``'s
    alpha / 2, halved because a candidate's p-value is doubled and divided by the
    candidate's ``size`` free parameters (its best single parameter is picked out of them,
    Bonferroni, ``try_candidate``)."""
    return alpha / 4.0 / max(size, 1)


def predicted_power(noncentrality: float, alpha: float, size: int = 1) -> float:
    """The probability a nested test at ``alpha`` finds a signal of this noncentrality
    (along the fitted direction: one degree of freedom)."""
    return power(noncentrality, chi2_isf(pair_threshold(alpha, size), 1))


def needed_noncentralities(model: PairModel, alpha: float, target: float = DEFAULT_POWER
                           ) -> tuple[float, float]:
    """The noncentrality each of the pair's nested tests needs for power ``target``."""
    a, b = (required_noncentrality(pair_threshold(alpha, k), target) for k in model.sizes)
    return a, b
