"""Is one sample an outlier? A Bonferroni-corrected test of the largest leave-one-out
residual, so one bad measurement is named instead of being blamed on a missing effect.

For sample i with whitened residual r_i (m,) and the block H_ii (m, m) of the hat matrix of
the (robust-weighted) whitened Jacobian, the residual it would have if the fit had not seen
it is e_i = (I - H_ii)^-1 r_i (exact for a linear model), and

    d_i^2 = r_i^T (I - H_ii)^-1 r_i

is chi-square with m degrees of freedom in units of the stated noise. The test is
scale-free, like the candidate tests: the noise level is estimated from the other samples
(``S_(i) = chi2 - d_i^2`` over ``dof - m``), and ``F_i = (d_i^2 / m) / (S_(i) / (dof - m))``
is F(m, dof - m) distributed if sample i is as good as the rest. A covariance that is wrong
by a constant factor therefore flags no sample. A sample is an outlier when its p-value is
below ``alpha / N`` (Bonferroni over the N samples, so ``alpha`` is family-wise).

A pose measured twice is tested directly first (``repeats``): a pair of repeats that
disagrees beyond the stated noise names its worse-fitted sample, and a sample whose repeats
agree is never flagged by the leave-one-out test (its misfit is the model's, not a glitch).
Outliers are found one at a time: the most significant sample is set aside, the model is
refitted without it, and the test is repeated on the rest (a gross outlier drags the fit and
would otherwise hide, or fake, others), at most ``max(1, N // 10)`` times.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import f_sf
from hostpc.diagnostics.repeats import check_repeats
from hostpc.fitting import FitResult
from hostpc.fitting.solver import evaluate
from hostpc.json_object import JsonObject

#: directions of a sample's residual that its own leverage fixes (1 - h below this) are
#: not testable: the fit reproduces them whatever the measurement says
LEVERAGE_TOLERANCE = 1e-6
#: at most this fraction of the samples is set aside as outliers (at least one)
MAX_OUTLIER_FRACTION = 0.1


@dataclass(frozen=True)
class Outlier:
    """One outlier: ``sample`` its index in the dataset; ``sigma`` the whitened norm of its
    leave-one-out residual (units of the stated noise, sqrt of chi-square with m dof);
    ``p_value`` of its scale-free test before the Bonferroni correction."""

    sample: int
    sigma: float
    p_value: float
    #: which test named it: "leave-one-out", or "repeat" (a pose measured twice whose
    #: measurements disagree beyond the noise: ``repeats``; the sample of the pair the fit
    #: explains worse)
    test: str = "leave-one-out"

    def to_dict(self) -> JsonObject:
        return {"sample": self.sample, "sigma": self.sigma, "p_value": self.p_value,
                "test": self.test}


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class DeletionStatistics:
    """Per-sample leave-one-out statistics of one fit (arrays of length N).

    d2: r_i^T (I - H_ii)^-1 r_i (chi-square, stated-noise units); dfn: the testable
    dimensions of each sample (m unless its own leverage fixes some); p_value: the
    scale-free F-test (1 where not testable)."""

    d2: np.ndarray
    dfn: np.ndarray
    p_value: np.ndarray


def deletion_statistics(result: FitResult) -> DeletionStatistics:
    """Leave-one-out statistics of every sample of a fit (see the module doc)."""
    problem = result.problem
    n_samples, m = problem.measured.shape
    evaluation = evaluate(problem, result.x)
    J = evaluation.jacobian
    assert J is not None
    weights = np.asarray(result.weights, dtype=float)
    row_weight = np.repeat(np.sqrt(weights), m)
    J_free = J[:, ~result.fixed] * row_weight[:, None]
    whitened = evaluation.whitened
    untestable = DeletionStatistics(np.zeros(n_samples), np.zeros(n_samples, dtype=int),
                                    np.ones(n_samples))
    if not (np.all(np.isfinite(J_free)) and np.all(np.isfinite(whitened))):
        return untestable
    if J_free.shape[1]:
        Q = np.linalg.qr(J_free)[0].reshape(n_samples, m, -1)
        H = np.einsum("nik,njk->nij", Q, Q)
    else:
        H = np.zeros((n_samples, m, m))
    h, V = np.linalg.eigh(H)  # (N, m), (N, m, m)
    keep = (1.0 - h) > LEVERAGE_TOLERANCE
    projected = np.einsum("nji,nj->ni", V, whitened)  # V^T r per sample
    d2 = np.sum(np.where(keep, projected**2 / np.where(keep, 1.0 - h, 1.0), 0.0), axis=1)
    dfn = keep.sum(axis=1)
    weighted_chi2 = float(np.sum(weights * np.sum(whitened**2, axis=1)))
    dof = whitened.size - J_free.shape[1]
    dfd = dof - dfn
    rest = weighted_chi2 - weights * d2
    testable = (dfn > 0) & (dfd > 0) & (rest > 1e-12 * max(weighted_chi2, 1e-300))
    statistic = np.where(testable, (d2 / np.maximum(dfn, 1))
                         / (np.maximum(rest, 1e-300) / np.maximum(dfd, 1)), 0.0)
    p_value = np.where(testable, f_sf(statistic, np.maximum(dfn, 1), np.maximum(dfd, 1)), 1.0)
    return DeletionStatistics(d2=d2, dfn=dfn, p_value=p_value)


def find_outliers(result: FitResult, alpha: float,
                  refit: Callable[[FitResult, np.ndarray], FitResult]
                  ) -> tuple[tuple[Outlier, ...], FitResult]:
    """The outliers of a fit, most significant first, and the fit without them.

    refit(fit, keep): the fit's model refitted on the samples ``keep`` (indices into the
    fit's own samples). Returns the input fit unchanged when no sample is an outlier.
    """
    n_samples = result.problem.measured.shape[0]
    threshold = alpha / max(n_samples, 1)
    limit = max(1, int(MAX_OUTLIER_FRACTION * n_samples))
    kept = np.arange(n_samples)  # dataset indices of the current fit's samples
    current = result
    found: list[Outlier] = []
    # repeats first: a pair that disagrees names its worse-fitted sample; a sample whose
    # repeats agree is never a glitch (its misfit is the model's)
    repeats = check_repeats(result.problem, alpha)
    if repeats.pairs.size:
        d2 = deletion_statistics(result).d2
        bad = np.flatnonzero(repeats.disagreeing)
        for k in bad[np.argsort(repeats.p_value[bad])][:limit]:
            pair = repeats.pairs[k]
            sample = int(pair[np.argmax(d2[pair])])
            if all(o.sample != sample for o in found):
                found.append(Outlier(sample, float(np.sqrt(repeats.statistic[k])),
                                     float(repeats.p_value[k]), test="repeat"))
        if found:
            keep_local = np.setdiff1d(kept, [o.sample for o in found])
            current = refit(current, keep_local)
            kept = kept[keep_local]
    protected = repeats.agreeing_samples()
    while len(found) < limit:
        stats = deletion_statistics(current)
        stats = DeletionStatistics(stats.d2, stats.dfn, np.where(
            np.isin(kept, protected), 1.0, stats.p_value))
        worst = int(np.argmin(stats.p_value))
        p_value = float(stats.p_value[worst])
        if not p_value < threshold:
            break
        found.append(Outlier(sample=int(kept[worst]), sigma=float(np.sqrt(stats.d2[worst])),
                             p_value=p_value))
        keep_local = np.delete(np.arange(kept.size), worst)
        current = refit(current, keep_local)
        kept = kept[keep_local]
    return tuple(found), current
