"""The few distribution functions the diagnostics need, from scipy.special.

scipy.stats would give the same numbers but takes about a second to import, and every
``hostpc`` command imports the diagnostics. Arguments broadcast like numpy arrays.
"""

from __future__ import annotations

import numpy as np
from scipy import special

_LOG_TINY = -700.0  # below this betainc underflows: use its asymptotic form


def chi2_sf(x: float, dof: float) -> float:
    """P(X > x) for X ~ chi-square with dof degrees of freedom."""
    return float(special.gammaincc(dof / 2.0, max(x, 0.0) / 2.0))


def chi2_ppf(q: float, dof: float) -> float:
    """The x with P(X <= x) = q."""
    return float(2.0 * special.gammaincinv(dof / 2.0, q))


def chi2_isf(q: float, dof: float) -> float:
    """The x with P(X > x) = q."""
    return float(2.0 * special.gammainccinv(dof / 2.0, q))


def f_sf(statistic: np.ndarray | float, dfn: np.ndarray | float, dfd: np.ndarray | float
         ) -> np.ndarray:
    """P(F > statistic) for F ~ F(dfn, dfd)."""
    statistic = np.maximum(np.asarray(statistic, dtype=float), 0.0)
    dfn = np.asarray(dfn, dtype=float)
    dfd = np.asarray(dfd, dtype=float)
    return np.asarray(special.betainc(dfd / 2.0, dfn / 2.0, dfd / (dfd + dfn * statistic)))


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
        a, b = dfd / 2.0, dfn / 2.0
        x = dfd / (dfd + dfn * statistic)
        approximate = (a * np.log(x) + b * np.log1p(-x) - np.log(a) - special.betaln(a, b))
    return np.where(np.isfinite(exact) & (exact > _LOG_TINY), exact, approximate)
