"""The shared error's scale from the fit's own residuals (hostpc.fitting.shared_errors)."""

from __future__ import annotations

import numpy as np

from hostpc.fitting.shared_errors import residual_scale


def _trial(rng: np.random.Generator, k_true: float) -> float:
    """A linear whitened problem y = J x + e + D delta, Cov(delta) = k_true S; the scale
    residual_scale estimates from the least-squares residuals."""
    rows, free, shared = 300, 6, 8
    J = rng.normal(size=(rows, free))
    D = rng.normal(size=(rows, shared)) * 0.3
    L = rng.normal(size=(shared, shared)) * 0.5
    S = L @ L.T + 0.1 * np.eye(shared)
    delta = np.linalg.cholesky(k_true * S) @ rng.normal(size=shared)
    y = J @ rng.normal(size=free) + rng.normal(size=rows) + D @ delta
    x, *_ = np.linalg.lstsq(J, y, rcond=None)
    return residual_scale(J, D, S, y - J @ x)


def test_scale_recovers_an_inflated_shared_covariance_on_average() -> None:
    rng = np.random.default_rng(7)
    estimates = np.array([_trial(rng, 10.0) for _ in range(400)])
    # the estimate is unbiased where it is not clipped (k = 10 is rarely clipped at 1)
    assert abs(np.mean(estimates) / 10.0 - 1.0) < 0.12


def test_scale_is_one_when_the_shared_covariance_is_right_or_absent() -> None:
    rng = np.random.default_rng(8)
    estimates = np.array([_trial(rng, 1.0) for _ in range(200)])
    assert np.all(estimates >= 1.0)
    assert np.median(estimates) < 2.5  # noise-only excess: small, clipped at 1
    J = rng.normal(size=(50, 3))
    assert residual_scale(J, np.zeros((50, 4)), np.eye(4), rng.normal(size=50)) == 1.0
