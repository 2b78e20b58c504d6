"""The chi-square and F tails without scipy, checked against scipy.special and mpmath.

Over grids of the degrees of freedom the diagnostics meet (1 to 10^4 for chi-square, 1 to
10^5 for F's denominator) the functions agree with scipy.special to 1e-12 relative. Where
scipy.special itself is off (very large a, far tails, log B(1/2, 5e4)), the reference is
mpmath at 40 digits, written down here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

from hostpc.diagnostics import distributions, special_functions
from hostpc.fitting.identifiability import pivoted_columns

TOLERANCE = 1e-12
DOFS = (1, 2, 3, 4, 5, 7, 10, 11, 17, 31, 50, 99, 100, 101, 333, 997, 1000, 2500, 10001)


def relative(ours: np.ndarray | float, reference: np.ndarray | float) -> np.ndarray:
    ours, reference = np.asarray(ours, dtype=float), np.asarray(reference, dtype=float)
    same = ours == reference
    return np.where(same, 0.0, np.abs(ours - reference)
                    / np.maximum(np.abs(reference), 1e-300))


@pytest.mark.parametrize("dof", DOFS)
def test_chi2_tails_match_scipy(dof: int) -> None:
    a = dof / 2.0
    spread = math.sqrt(2.0 * dof)
    points = np.concatenate([dof * np.array([1e-6, 1e-3, 0.1, 0.5, 0.9, 1.0, 1.1, 2.0, 5.0,
                                             30.0]),
                             dof + spread * np.linspace(-6.0, 6.0, 13)])
    for x in points[points > 0]:
        upper = special.gammaincc(a, x / 2.0)
        lower = special.gammainc(a, x / 2.0)
        ours_lower, ours_upper = special_functions.gamma_tails(a, x / 2.0)
        if upper > 1e-100:
            assert relative(distributions.chi2_sf(x, dof), upper) < TOLERANCE, x
        if lower > 1e-100:
            assert relative(ours_lower, lower) < TOLERANCE, x
        if upper > 1e-100:
            assert relative(ours_upper, upper) < TOLERANCE, x


@pytest.mark.parametrize("dof", DOFS)
def test_chi2_quantiles_match_scipy(dof: int) -> None:
    a = dof / 2.0
    for q in (1e-100, 1e-20, 1e-10, 1e-6, 1e-3, 0.005, 0.01, 0.05, 0.1, 0.3, 0.5):
        assert relative(distributions.chi2_ppf(q, dof),
                        2.0 * special.gammaincinv(a, q)) < TOLERANCE, q
        assert relative(distributions.chi2_isf(q, dof),
                        2.0 * special.gammainccinv(a, q)) < TOLERANCE, q


def test_chi2_edges() -> None:
    assert distributions.chi2_sf(0.0, 3) == 1.0
    assert distributions.chi2_sf(-1.0, 3) == 1.0
    assert distributions.chi2_sf(math.inf, 3) == 0.0
    assert distributions.chi2_sf(1e6, 3) == 0.0  # underflows, as scipy's
    assert distributions.chi2_isf(0.0, 3) == math.inf
    assert distributions.chi2_ppf(0.0, 3) == 0.0
    assert math.isnan(distributions.chi2_sf(math.nan, 3))


def test_noncentral_chi2_tail_matches_scipy() -> None:
    """The verification's power (planning/verify_poses.py) without scipy: the Poisson
    mixture agrees with scipy's non-central chi-square over the plan's range and beyond."""
    from scipy import stats

    for x in (0.1, 1.0, 5.0, 20.0, 50.0, 100.0, 300.0, 1000.0):
        for dof in (1, 3, 6, 12, 30, 90, 300):
            for nc in (0.0, 0.5, 3.0, 20.0, 60.0, 200.0, 2000.0):
                ours = distributions.ncx2_sf(x, dof, nc)
                theirs = float(stats.ncx2.sf(x, dof, nc) if nc else stats.chi2.sf(x, dof))
                assert ours == pytest.approx(theirs, rel=1e-10, abs=1e-300), (x, dof, nc)


def test_f_tails_match_scipy() -> None:
    dfn = np.array([1, 2, 3, 4, 5, 6, 7, 9, 12, 15, 20, 27, 35, 60])
    dfd = np.array([1, 2, 3, 5, 10, 30, 57, 100, 237, 355, 700, 1001, 5000, 10000, 20000,
                    100000])  # above 1e4: scipy's own (BETA_SCIPY_FROM)
    statistic = np.array([0.0, 1e-8, 1e-4, 0.01, 0.1, 0.3, 0.5, 0.8, 0.9, 1.0, 1.1, 1.3, 1.5,
                          2.0, 3.0, 5.0, 10.0, 30.0, 100.0, 1e3, 1e4])
    n, d, s = (v.ravel().astype(float) for v in np.meshgrid(dfn, dfd, statistic,
                                                             indexing="ij"))
    # scipy's more accurate form for the same inputs: I_x(dfd/2, dfn/2) for small x, else
    # 1 - I_y(dfn/2, dfd/2) with y = 1 - x as its own ratio
    x = d / (d + n * s)
    reference = np.where(x < 0.5, special.betainc(d / 2.0, n / 2.0, x),
                         special.betaincc(n / 2.0, d / 2.0, n * s / (d + n * s)))
    error = relative(distributions.f_sf(s, n, d), reference)
    assert np.max(np.where(reference > 1e-100, error, 0.0)) < TOLERANCE
    ours = distributions.f_sf(s, n, d)
    assert np.all((ours >= 0.0) & (ours <= 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        log_reference = np.log(reference)
        log_error = (np.abs(distributions.f_logsf(s, n, d) - log_reference)
                     / np.maximum(1.0, np.abs(log_reference)))
    assert np.max(np.where(reference > 1e-300, log_error, 0.0)) < TOLERANCE


def test_incomplete_beta_and_log_beta_match_scipy() -> None:
    values = np.array([0.5, 1.0, 1.5, 2.0, 3.5, 5.0, 10.0, 17.5, 50.0, 118.5, 350.0, 1000.0,
                       5000.0])
    x = np.concatenate([np.linspace(0.5, 1.0, 21)[:-1], [1 - 1e-3, 1 - 1e-6],
                        np.geomspace(1e-12, 0.49, 15)])
    a, b, xx = (v.ravel() for v in np.meshgrid(values, values, x, indexing="ij"))
    reference = special.betainc(a, b, xx)
    error = relative(special_functions.beta_lower(a, b, xx, 1.0 - xx), reference)
    assert np.max(np.where(reference > 1e-100, error, 0.0)) < TOLERANCE
    assert np.max(relative(special_functions.log_beta(a, b), special.betaln(a, b))) < TOLERANCE


@pytest.mark.parametrize(("a", "x", "lower", "upper"), [
    (1e6, 995500.0, 3.2963040141976456275e-6, 0.99999670369598580235),  # scipy: 1e-5 off
    (5000.5, 7500.75, 1.0, 5.6424651308490204377e-208),
    (1250.0, 1875.0, 1.0, 1.0750170646189179396e-53),
])
def test_incomplete_gamma_against_mpmath(a: float, x: float, lower: float, upper: float
                                         ) -> None:
    ours_lower, ours_upper = special_functions.gamma_tails(a, x)
    assert relative(ours_lower, lower) < TOLERANCE
    assert relative(ours_upper, upper) < TOLERANCE


def test_incomplete_beta_against_mpmath() -> None:
    x = 30.0 / (30.0 + 60e6)
    assert relative(special_functions.beta_lower(15.0, 30.0, x, 60e6 / (30.0 + 60e6)),
                    7.0161977359105892173e-84) < TOLERANCE
    assert relative(special_functions.beta_lower(5000.0, 17.5, 0.8625, 0.1375),
                    5.0056889512636552265e-289) < TOLERANCE
    assert relative(special_functions.beta_lower(0.5, 0.5, 1 - 1e-9, 1 - (1 - 1e-9)),
                    0.99997986831543953137) < TOLERANCE  # scipy: 1.1e-12 off
    assert relative(special_functions.log_beta(np.array(0.5), np.array(50000.0)),
                    -4.8375216992804415099) < TOLERANCE
    assert relative(special_functions.log_beta(np.array(0.5), np.array(150000.5)),
                    -5.3868311769478296458) < TOLERANCE


def test_pivoted_columns_match_lapack() -> None:
    import scipy.linalg

    rng = np.random.default_rng(7)
    for _ in range(300):
        rows = int(rng.integers(1, 8))
        cols = int(rng.integers(rows + 1, 40))
        matrix = rng.normal(size=(rows, cols)) * 10.0 ** rng.uniform(-3, 3, size=cols)
        if rng.random() < 0.5:  # orthonormal rows, as a null basis
            matrix = (np.linalg.qr(rng.normal(size=(cols, rows)))[0].T
                      * 10.0 ** rng.uniform(0, 3, size=cols))
        expected = scipy.linalg.qr(matrix, pivoting=True)[2][:rows]
        assert pivoted_columns(matrix) == [int(k) for k in expected]


def test_pivoted_columns_take_the_first_of_tied_columns() -> None:
    # columns 1 and 3 equal: LAPACK would let round-off decide; the first listed wins
    matrix = np.array([[0.1, 2.0, 0.3, 2.0], [0.2, 1.0, 0.1, 1.0]])
    assert pivoted_columns(matrix)[0] == 1
    assert pivoted_columns(matrix[:, ::-1])[0] == 0


def test_fraction_element_by_element_gives_the_stacked_digits() -> None:
    """The continued fraction's last few elements go on in Python floats: every element's
    value is the one its own stacked steps give, digit for digit (an F test of an interaction
    search: dfd / 2 ~ 170, dfn / 2 of 0.5, 1 or 1.5, x from 1e-10 to 0.99)."""
    rng = np.random.default_rng(3)
    n = 600
    a = rng.choice([160.0, 171.0, 173.0, 1200.0], n)
    b = rng.choice([0.5, 1.0, 1.5, 40.0], n)
    x = rng.uniform(0.0, 1.0, n) ** rng.uniform(0.1, 12.0, n)
    direct = x < (a + 1.0) / (a + b + 2.0)
    p, r = np.where(direct, a, b), np.where(direct, b, a)
    u = np.where(direct, x, 1.0 - x)
    stacked, converged = special_functions._beta_fraction(p, r, u, 1.0 - u)
    assert np.count_nonzero(converged) == n
    alone = [special_functions._beta_fraction_scalar(*values)
             for values in zip(p.tolist(), r.tolist(), u.tolist(), (1.0 - u).tolist(),
                               strict=True)]
    assert stacked.tolist() == [value for value, _ in alone]
    one_each = [special_functions._beta_fraction(p[k:k + 1], r[k:k + 1], u[k:k + 1],
                                                 1.0 - u[k:k + 1])[0][0] for k in range(40)]
    assert stacked[:40].tolist() == one_each
