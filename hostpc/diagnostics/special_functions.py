"""The regularised incomplete gamma and beta functions, in Python floats and numpy.

Why not scipy.special: importing it costs ~0.2 s (its array-API layer clones the numpy
namespace), more than the whole `hostpc diagnose --ladder` at 120 poses, and the
diagnostics need only these two functions (chi-square and F tails). The methods are the
classical ones (Numerical Recipes 6.2 and 6.4: a power series and Lentz's continued
fraction, each where it converges fast), with the prefactors x^a e^-x / Gamma(a) and
x^a (1 - x)^b / B(a, b) computed without cancellation for large a and b (Stirling's series
for the log-gamma remainder, log1p(t) - t by its own series). Checked against
scipy.special (gammaincc, gammaincinv, gammainccinv, betainc, betaln) to 1e-12 relative
over grids of the degrees of freedom the diagnostics meet (tests/hostpc/
test_special_functions.py).

An incomplete beta with a or b above `BETA_SCIPY_FROM`, or whose continued fraction has
not converged after `BETA_MAX_TERMS` terms, is handed to scipy.special, imported then:
that happens only for datasets far larger than the import.
"""

from __future__ import annotations

import functools
import math

import numpy as np

EPSILON = 1e-16
_TINY = 1e-300
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_STIRLING_FROM = 10.0  # Stirling's remainder series is exact to ~1e-16 from here on
_STIRLING = (1.0 / 12.0, -1.0 / 360.0, 1.0 / 1260.0, -1.0 / 1680.0, 1.0 / 1188.0,
             -691.0 / 360360.0, 1.0 / 156.0)
GAMMA_MAX_TERMS = 100_000
BETA_MAX_TERMS = 2_000
SCALAR_BELOW = 24
"""`_beta_fraction`'s stacked state goes on element by element (Python floats) once this
few elements are unfinished: a stacked step (~60 numpy calls) costs about what 24
elements' steps in Python do (the best of 12, 24, 64 and 160 for the interaction search)."""
BETA_SCIPY_FROM = 5e3
"""Above this a or b (an F test's dfd above 1e4, some 3300 stereo poses) the incomplete
beta is scipy's: near x = 1 each step of the fraction cancels, and its error grows as
~1e-16 a (5e-13 at a = 5e3, 1e-12 at 1e4, 4e-12 at 5e4); such a dataset takes longer to
diagnose than scipy.special to import."""


def stirling_remainder(a: np.ndarray | float) -> np.ndarray:
    """lgamma(a) - ((a - 1/2) log a - a + log(2 pi) / 2), for a >= 10 (array)."""
    a = np.asarray(a, dtype=float)
    inverse_square = 1.0 / (a * a)
    total = np.zeros_like(a)
    for coefficient in reversed(_STIRLING):
        total = total * inverse_square + coefficient
    return np.asarray(total / a)


def _stirling_remainder_scalar(a: float) -> float:
    if a < _STIRLING_FROM:
        return math.lgamma(a) - ((a - 0.5) * math.log(a) - a + _HALF_LOG_2PI)
    inverse_square, total = 1.0 / (a * a), 0.0
    for coefficient in reversed(_STIRLING):  # the same steps as stirling_remainder
        total = total * inverse_square + coefficient
    return total / a


def _log1pmx_scalar(t: float) -> float:
    if abs(t) >= 0.5:
        return math.log1p(t) - t
    total, power, k = 0.0, t * t, 2
    while True:
        term = power / k
        total = total - term if k % 2 == 0 else total + term
        if abs(term) <= EPSILON * abs(total) * 0.01:
            return total
        power *= t
        k += 1


def log_gamma_prefix(a: float, x: float) -> float:
    """log(x^a e^-x / Gamma(a)) for a > 0, x > 0, accurate for large a (x near a)."""
    if a < _STIRLING_FROM:
        return a * math.log(x) - x - math.lgamma(a)
    t = (x - a) / a
    core = math.log(x / a) - t if t < -0.5 else _log1pmx_scalar(t)
    return a * core + 0.5 * math.log(a) - _HALF_LOG_2PI - _stirling_remainder_scalar(a)


def _lower_series(a: float, x: float) -> float:
    """sum_n x^n / ((a+1)...(a+n)) (NR gser), for x < a + 1."""
    term = total = 1.0 / a
    denominator = a
    for _ in range(GAMMA_MAX_TERMS):
        denominator += 1.0
        term *= x / denominator
        total += term
        if term < total * EPSILON:
            return total
    raise ArithmeticError(f"incomplete gamma series did not converge (a={a}, x={x})")


def _upper_fraction(a: float, x: float) -> float:
    """The continued fraction of Q(a, x) e^x x^-a Gamma(a) (NR gcf, Lentz), x >= a + 1."""
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, GAMMA_MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = _TINY if abs(d) < _TINY else d
        c = b + an / c
        c = _TINY if abs(c) < _TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < EPSILON:
            return h
    raise ArithmeticError(f"incomplete gamma fraction did not converge (a={a}, x={x})")


def gamma_tails(a: float, x: float) -> tuple[float, float]:
    """(P(a, x), Q(a, x)): the regularised lower and upper incomplete gamma functions."""
    if not (a > 0.0) or math.isnan(x):
        return (math.nan, math.nan)
    if x <= 0.0:
        return (0.0, 1.0)
    if math.isinf(x):
        return (1.0, 0.0)
    log_prefix = log_gamma_prefix(a, x)
    if x < a + 1.0:
        lower = math.exp(log_prefix) * _lower_series(a, x)
        return (lower, 1.0 - lower)
    upper = math.exp(log_prefix) * _upper_fraction(a, x)
    return (1.0 - upper, upper)


@functools.lru_cache(maxsize=4096)  # a diagnosis asks for the same few bands again and again
def gamma_inverse(a: float, q: float, upper: bool) -> float:
    """The x with Q(a, x) = q (upper) or P(a, x) = q (not upper), 0 <= q <= 1.

    Newton's method for log(tail) against u = log(x) (the derivative: x times the density
    over the tail; nearly linear in both tails), safeguarded by a bracket that every step
    narrows; ends when the step is below the double's resolution."""
    if not (a > 0.0) or not (0.0 <= q <= 1.0):
        return math.nan
    if q == 0.0:
        return math.inf if upper else 0.0
    if q == 1.0:
        return 0.0 if upper else math.inf
    u = math.log(_wilson_hilferty(a, q, upper))
    low, high = -math.inf, math.inf
    expansion = 1.0
    target = math.log(q)
    for _ in range(400):
        x = math.exp(u)
        lower_tail, upper_tail = gamma_tails(a, x)
        tail = upper_tail if upper else lower_tail
        # the upper tail falls as x grows, the lower one rises
        beyond = (tail < q) if upper else (tail > q)
        if beyond:
            high = u
        else:
            low = u
        if tail > 0.0:
            density_x = math.exp(log_gamma_prefix(a, x))  # x times the density
            slope = (-density_x if upper else density_x) / tail  # d log(tail) / du
            new = u - (math.log(tail) - target) / slope if slope != 0.0 else math.nan
        else:
            new = math.nan  # underflow: bisect toward the bulk
        if abs(new - u) <= 4.0 * EPSILON * max(1.0, abs(u)):
            return math.exp(new)  # converged (round-off may put it just past the bracket)
        if not (low < new < high):
            if math.isfinite(low) and math.isfinite(high):
                new = 0.5 * (low + high)
            else:
                new = low + expansion if math.isfinite(low) else high - expansion
                expansion *= 2.0
        if abs(new - u) <= 2.0 * EPSILON * max(1.0, abs(new)) or new in (low, high):
            return math.exp(new)
        u = new
    return math.exp(u)


def _wilson_hilferty(a: float, q: float, upper: bool) -> float:
    """A starting point: the Wilson-Hilferty cube-root normal approximation."""
    z = _normal_quantile(1.0 - q if upper else q) if 1e-300 < q < 1.0 - 1e-16 else 0.0
    if upper and q < 1e-16:
        z = math.sqrt(-2.0 * math.log(q))
    dof = 2.0 * a
    root = 1.0 - 2.0 / (9.0 * dof) + z * math.sqrt(2.0 / (9.0 * dof))
    return max(0.5 * dof * root**3, 1e-3 * a, 1e-300)


def _normal_quantile(p: float) -> float:
    """A rough standard normal quantile (Tukey's lambda fit; starting value only)."""
    p = min(max(p, 1e-300), 1.0 - 1e-16)
    return 4.91 * (p**0.14 - (1.0 - p) ** 0.14)


def lgamma(values: np.ndarray) -> np.ndarray:
    """math.lgamma of each value (an array; few distinct values: degrees of freedom)."""
    values = np.asarray(values, dtype=float)
    if values.size <= 8:
        return np.array([math.lgamma(v) for v in values.ravel()]).reshape(values.shape)
    distinct, where = np.unique(values, return_inverse=True)
    return np.array([math.lgamma(v) for v in distinct])[where].reshape(values.shape)


def _log_beta_scalar(a: float, b: float) -> float:
    small, large = min(a, b), max(a, b)
    if large < _STIRLING_FROM:
        return math.lgamma(small) + math.lgamma(large) - math.lgamma(small + large)
    difference = (-(large - 0.5) * math.log1p(small / large) - small * math.log(large + small)
                  + small + _stirling_remainder_scalar(large)
                  - _stirling_remainder_scalar(large + small))
    return math.lgamma(small) + difference if small < _STIRLING_FROM else (
        (small - 0.5) * math.log(small) - small + _HALF_LOG_2PI
        + _stirling_remainder_scalar(small) + difference)


def log_beta(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """log B(a, b) for a, b > 0 (arrays), without cancellation when one is large."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    small, large = np.minimum(a, b), np.maximum(a, b)
    result = np.empty(small.shape)
    both_small = large < _STIRLING_FROM
    if np.any(both_small):
        s, g = small[both_small], large[both_small]
        result[both_small] = lgamma(s) + lgamma(g) - lgamma(s + g)
    rest = ~both_small
    if np.any(rest):
        s, g = small[rest], large[rest]
        # lgamma(g) - lgamma(g + s) by Stirling, the log terms regrouped (no cancellation)
        difference = (-(g - 0.5) * np.log1p(s / g) - s * np.log(g + s) + s
                      + stirling_remainder(g) - stirling_remainder(g + s))
        first = np.where(s < _STIRLING_FROM, lgamma(np.minimum(s, _STIRLING_FROM)),
                         (s - 0.5) * np.log(s) - s + _HALF_LOG_2PI
                         + stirling_remainder(np.maximum(s, _STIRLING_FROM)))
        result[rest] = first + difference
    return result


def beta_lower(a: np.ndarray, b: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """I_x(a, b), the regularised incomplete beta function, for arrays a, b > 0 and
    0 <= x <= 1 with y = 1 - x given separately (so a tail near x = 1 keeps its digits).

    The continued fraction (NR betacf) on the side where it converges fast: I_x(a, b) or
    1 - I_y(b, a)."""
    a, b, x, y = (np.asarray(v, dtype=float) for v in np.broadcast_arrays(a, b, x, y))
    if a.size == 1:  # one test: Python floats, ~20x faster than numpy on 1-element arrays
        return np.full(a.shape, _beta_lower_scalar(float(a.flat[0]), float(b.flat[0]),
                                                   float(x.flat[0]), float(y.flat[0])))
    result = np.full(a.shape, np.nan)
    result[(x <= 0.0) & (a > 0) & (b > 0)] = 0.0
    result[(y <= 0.0) & (a > 0) & (b > 0)] = 1.0
    inner = (x > 0.0) & (y > 0.0) & (a > 0) & (b > 0)
    if not np.any(inner):
        return result
    ai, bi, xi, yi = a[inner], b[inner], x[inner], y[inner]
    direct = xi < (ai + 1.0) / (ai + bi + 2.0)
    p = np.where(direct, ai, bi)  # evaluate I_u(p, r) with u < (p + 1) / (p + r + 2)
    r = np.where(direct, bi, ai)
    u = np.where(direct, xi, yi)
    v = np.where(direct, yi, xi)
    fraction, converged = _beta_fraction(p, r, u, v)
    with np.errstate(under="ignore"):
        value = np.exp(log_beta_prefix(p, r, u, v)) / p * fraction
    inner_result = np.where(direct, value, 1.0 - value)
    slow = ~converged | (np.maximum(ai, bi) > BETA_SCIPY_FROM)
    if np.any(slow):
        from scipy import special  # ~0.2 s to import: only for datasets that take longer

        a_, b_, x_, y_ = ai[slow], bi[slow], xi[slow], yi[slow]
        inner_result[slow] = np.where(x_ < 0.5, special.betainc(a_, b_, x_),
                                      special.betaincc(b_, a_, y_))
    result[inner] = inner_result
    return result


def _beta_lower_scalar(a: float, b: float, x: float, y: float) -> float:
    """`beta_lower` for one element (the same steps, in Python floats)."""
    if not (a > 0.0 and b > 0.0) or math.isnan(x) or math.isnan(y):
        return math.nan
    if x <= 0.0 or y <= 0.0:
        return 0.0 if x <= 0.0 else 1.0
    direct = x < (a + 1.0) / (a + b + 2.0)
    p, r, u, v = (a, b, x, y) if direct else (b, a, y, x)
    fraction, converged = _beta_fraction_scalar(p, r, u, v)
    if not converged or max(a, b) > BETA_SCIPY_FROM:
        return float(beta_lower(np.array([a, a]), np.array([b, b]), np.array([x, x]),
                                np.array([y, y]))[0])  # the array path hands it to scipy
    log_u = math.log(u) if u <= v else math.log1p(-v)
    log_v = math.log(v) if v <= u else math.log1p(-u)
    if p >= _STIRLING_FROM and r >= _STIRLING_FROM:
        total = p + r
        d = u * r - v * p
        log_prefix = (p * _log1pmx_ratio_scalar(d / p, u * total / p)
                      + r * _log1pmx_ratio_scalar(-d / r, v * total / r)
                      + 0.5 * math.log(p * r / total) - _HALF_LOG_2PI
                      + _stirling_remainder_scalar(total) - _stirling_remainder_scalar(p)
                      - _stirling_remainder_scalar(r))
    else:
        log_prefix = p * log_u + r * log_v - _log_beta_scalar(p, r)
    try:
        value = math.exp(log_prefix) / p * fraction
    except OverflowError:
        value = math.inf
    return value if direct else 1.0 - value


def _log1pmx_ratio_scalar(t: float, ratio: float) -> float:
    return _log1pmx_scalar(t) if abs(t) < 0.5 else math.log(ratio) - t


def log_beta_prefix(a: np.ndarray, b: np.ndarray, x: np.ndarray, y: np.ndarray
                    ) -> np.ndarray:
    """log(x^a y^b / B(a, b)) with y = 1 - x (arrays), without the cancellation of its
    large terms: the log of the larger of x and y from the smaller one (log1p), and where
    a and b are both large, Stirling's form (Boost's ibeta_power_terms): with
    d = x b - y a, a log1p(d / a) + b log1p(-d / b) = a l(d / a) + b l(-d / b), l(t) =
    log(1 + t) - t, plus log(ab / (a + b)) / 2 - log(2 pi) / 2 and the remainders."""
    log_x = np.where(x <= y, np.log(x), np.log1p(-y))
    log_y = np.where(y <= x, np.log(y), np.log1p(-x))
    result = a * log_x + b * log_y - log_beta(a, b)
    large = (a >= _STIRLING_FROM) & (b >= _STIRLING_FROM)
    if np.any(large):
        al, bl, xl, yl = a[large], b[large], x[large], y[large]
        total = al + bl
        d = xl * bl - yl * al
        result[large] = (al * _log1pmx_ratio(d / al, xl * total / al)
                         + bl * _log1pmx_ratio(-d / bl, yl * total / bl)
                         + 0.5 * np.log(al * bl / total) - _HALF_LOG_2PI
                         + stirling_remainder(total) - stirling_remainder(al)
                         - stirling_remainder(bl))
    return np.asarray(result)


def _log1pmx_ratio(t: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """log(1 + t) - t for arrays, ratio = 1 + t given separately (accurate near t = -1)."""
    small = np.abs(t) < 0.5
    with np.errstate(divide="ignore"):
        result = np.log(ratio) - t
    if np.any(small):
        ts = t[small]
        power = ts * ts
        series = np.zeros_like(ts)
        for k in range(2, 64):  # |t| < 1/2: the terms fall below 2^-62 / 62
            series += -power / k if k % 2 == 0 else power / k
            power = power * ts
        result[small] = series
    return result


def _beta_fraction(a: np.ndarray, b: np.ndarray, x: np.ndarray, y: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """NR's continued fraction for I_x(a, b) (modified Lentz), vectorised, y = 1 - x;
    (value, converged). Each element leaves the loop when its own factor is 1 to the
    double's resolution (one stacked state, compressed as they finish). The first
    denominator 1 - (a + b) x / (a + 1) is written ((a + 1) y + (1 - b) x) / (a + 1): it
    keeps its digits for x near 1 (large a, small b: an F test's dfd). The last
    ``SCALAR_BELOW`` unfinished elements go on in Python floats (`_continue_fraction`, the
    same operations, so the same digits): a step of the stacked state costs ~60 numpy
    calls whatever its width, and the slowest few elements of an interaction search's
    ~500 take ten times the median's steps."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    d = (qap * y + (1.0 - b) * x) / qap
    d = 1.0 / np.where(np.abs(d) < _TINY, _TINY, d)
    value = d.copy()
    converged = np.zeros(x.shape, dtype=bool)
    # the unfinished elements' state, one row each: index, a, b, x, a+b, a+1, a-1, c, d, h
    state = np.stack([np.arange(x.size, dtype=float), a, b, x, qab, qap, qam,
                      np.ones_like(x), d, d.copy()])
    for m in range(1, BETA_MAX_TERMS + 1):
        _, aa_, bb_, xx_, qab_, qap_, qam_, c, d, h = state
        m2 = 2.0 * m
        for aa in (m * (bb_ - m) * xx_ / ((qam_ + m2) * (aa_ + m2)),
                   -(aa_ + m) * (qab_ + m) * xx_ / ((aa_ + m2) * (qap_ + m2))):
            d = 1.0 + aa * d
            d = 1.0 / np.where(np.abs(d) < _TINY, _TINY, d)
            c = 1.0 + aa / c
            c = np.where(np.abs(c) < _TINY, _TINY, c)
            delta = d * c
            h = h * delta
        state[7], state[8], state[9] = c, d, h
        finished = np.abs(delta - 1.0) < EPSILON
        if finished.any():
            index = state[0, finished].astype(int)
            value[index] = h[finished]
            converged[index] = True
            state = state[:, ~finished]
            if state.shape[1] <= SCALAR_BELOW:
                for k, a_k, b_k, x_k, _, _, _, c_k, d_k, h_k in state.T.tolist():
                    h_k, done = _continue_fraction(a_k, b_k, x_k, c_k, d_k, h_k, m + 1)
                    if done:  # an unfinished one keeps its start value, as above
                        value[int(k)], converged[int(k)] = h_k, True
                break
    return value, converged


def _beta_fraction_scalar(a: float, b: float, x: float, y: float) -> tuple[float, bool]:
    """`_beta_fraction` for one element, in Python floats (the same steps)."""
    qap = a + 1.0
    d = (qap * y + (1.0 - b) * x) / qap
    d = 1.0 / (_TINY if abs(d) < _TINY else d)
    return _continue_fraction(a, b, x, 1.0, d, d, 1)


def _continue_fraction(a: float, b: float, x: float, c: float, d: float, h: float,
                       first: int) -> tuple[float, bool]:
    """The fraction's steps ``first`` to ``BETA_MAX_TERMS`` of one element from its state
    (c, d, h), in Python floats: each operation the one `_beta_fraction` makes on the
    element's column (IEEE double either way), so the same digits. (value, converged)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    for m in range(first, BETA_MAX_TERMS + 1):
        m2 = 2.0 * m
        for aa in (m * (b - m) * x / ((qam + m2) * (a + m2)),
                   -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (_TINY if abs(d) < _TINY else d)
            c = 1.0 + aa / c
            c = _TINY if abs(c) < _TINY else c
            delta = d * c
            h *= delta
        if abs(delta - 1.0) < EPSILON:
            return h, True
    return h, False
