"""The few distribution functions the diagnostics need: chi-square and F tails.

From the incomplete gamma and beta functions of `special_functions` (pure Python and
numpy): scipy.stats would give the same numbers but takes about a second to import, and
scipy.special ~0.2 s, while every ``hostpc`` command imports the diagnostics. They agree
with scipy.special to 1e-12 relative (tests/hostpc/test_special_functions.py). Arguments
of the F functions broadcast like numpy arrays.
"""

from __future__ import annotations

import math

import numpy as np

from hostpc.diagnostics.special_functions import (
    beta_lower,
    gamma_inverse,
    gamma_tails,
    log_beta,
)

_LOG_TINY = -700.0  # below this the incomplete beta underflows: use its asymptotic form


def chi2_sf(x: float, dof: float) -> float:
    """P(X > x) for X ~ chi-square with dof degrees of freedom."""
    return gamma_tails(dof / 2.0, max(x, 0.0) / 2.0)[1]


def chi2_ppf(q: float, dof: float) -> float:
    """The x with P(X <= x) = q."""
    return 2.0 * gamma_inverse(dof / 2.0, q, upper=False)


def chi2_isf(q: float, dof: float) -> float:
    """The x with P(X > x) = q."""
    return 2.0 * gamma_inverse(dof / 2.0, q, upper=True)


def ncx2_sf(x: float, dof: float, nc: float) -> float:
    """P(X > x) for X ~ non-central chi-square (dof degrees of freedom, non-centrality nc):
    the Poisson(nc / 2) mixture of central chi-square tails with dof + 2 j degrees of
    freedom, summed over the weights that matter (out to 40 standard deviations of the
    Poisson either side of its mean, which leaves less than 1e-300 out)."""
    x, dof, nc = max(float(x), 0.0), float(dof), max(float(nc), 0.0)
    if nc == 0.0:
        return chi2_sf(x, dof)
    mean = nc / 2.0
    spread = 40.0 * math.sqrt(mean) + 40.0
    total = 0.0
    for j in range(max(0, int(mean - spread)), int(mean + spread) + 1):
        log_weight = -mean + j * math.log(mean) - math.lgamma(j + 1.0)
        if log_weight > -745.0:
            total += math.exp(log_weight) * chi2_sf(x, dof + 2.0 * j)
    return min(total, 1.0)


def f_sf(statistic: np.ndarray | float, dfn: np.ndarray | float, dfd: np.ndarray | float
         ) -> np.ndarray:
    """P(F > statistic) for F ~ F(dfn, dfd)."""
    statistic = np.maximum(np.asarray(statistic, dtype=float), 0.0)
    dfn = np.asarray(dfn, dtype=float)
    dfd = np.asarray(dfd, dtype=float)
    # I_x(dfd/2, dfn/2) at x = dfd / (dfd + dfn F); 1 - x computed as its own ratio
    with np.errstate(invalid="ignore", divide="ignore"):
        denominator = dfd + dfn * statistic
        x = dfd / denominator
        y = np.where(np.isinf(statistic), 1.0, dfn * statistic / denominator)
    return np.asarray(beta_lower(dfd / 2.0, dfn / 2.0, x, y))


def f_logsf(statistic: np.ndarray | float, dfn: np.ndarray | float, dfd: np.ndarray | float
            ) -> np.ndarray:
    """log P(F > statistic), finite even where the probability underflows: there by the
    leading term of the incomplete beta function for small x,
    I_x(a, b) ~ x^a (1 - x)^b / (a B(a, b)), which is accurate exactly there."""
    statistic = np.maximum(np.asarray(statistic, dtype=float), 0.0)
    dfn = np.asarray(dfn, dtype=float)
    dfd = np.asarray(dfd, dtype=float)
    with np.errstate(divide="ignore"):
        exact = np.log(f_sf(statistic, dfn, dfd))
    tiny = ~(np.isfinite(exact) & (exact > _LOG_TINY))
    if not np.any(tiny):
        return exact
    a, b, statistic = (np.broadcast_to(v, exact.shape)[tiny] for v in (dfd / 2.0, dfn / 2.0,
                                                                       statistic))
    with np.errstate(divide="ignore"):
        x = 2.0 * a / (2.0 * a + 2.0 * b * statistic)
        approximate = a * np.log(x) + b * np.log1p(-x) - np.log(a) - log_beta(a, b)
    result = np.array(exact, dtype=float)
    result[tiny] = approximate
    return result
