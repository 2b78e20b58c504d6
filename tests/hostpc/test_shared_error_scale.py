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


def test_scale_stays_one_without_a_significant_excess() -> None:
    """With the stated S right, a chance excess of the noise does not scale S up (the
    gate): k = 1 in nearly all trials (without the gate, about half were above 1)."""
    rng = np.random.default_rng(9)
    estimates = np.array([_trial(rng, 1.0) for _ in range(200)])
    assert np.mean(estimates == 1.0) > 0.9


def test_gate_false_alarms_at_its_level_with_one_dominant_shared_direction() -> None:
    """The humanoid head camera's geometry: one shared direction carries most of the
    residual excess (mu = 9 against 0.1-0.4), a heavy-tailed chi-square(1). With the stated
    S right, S must be scaled up in about SCALE_ALPHA (2 %) of the worlds. The earlier
    gate (2 Gaussian standard deviations) scaled it in about 4 % (61 of 1500 here), by
    k = 6-10 each: the elbows' MSE / sigma^2 fell to 0.87-0.89 on average."""
    from hostpc.fitting.shared_errors import SCALE_ALPHA

    rng = np.random.default_rng(12)
    rows, free = 225, 34
    J = rng.normal(size=(rows, free))
    D = rng.normal(size=(rows, 5)) * np.array([0.2, 0.04, 0.035, 0.02, 0.01])
    S = np.eye(5)
    U = D  # S = I
    Q, _ = np.linalg.qr(J)
    draws = 1500
    scaled = 0
    for _ in range(draws):
        e = rng.normal(size=rows) + U @ rng.normal(size=5)
        if residual_scale(J, D, S, e - Q @ (Q.T @ e)) > 1.0:
            scaled += 1
    # binomial(1500, 0.02): 30 +- 5.4
    assert scaled <= draws * SCALE_ALPHA + 3.0 * np.sqrt(draws * SCALE_ALPHA), scaled
    assert scaled >= 10  # and the gate still opens


def test_scale_with_a_noise_covariance_below_the_whitening() -> None:
    """With a pixel floor in the weights the whitened noise is M < I: the scale is
    estimated against M (noise_blocks), so a right S stays 1 and an inflated one is
    found, where testing against I would miss the excess the floor hides."""
    rng = np.random.default_rng(13)
    n, m, free, shared = 100, 3, 6, 8
    J = rng.normal(size=(n * m, free))
    D = rng.normal(size=(n * m, shared)) * 0.3
    S = np.eye(shared)
    M = np.broadcast_to(np.diag([0.5, 0.5, 0.6]), (n, m, m)).copy()
    Q, _ = np.linalg.qr(J)
    noise = np.sqrt(np.diag(M[0]))

    def trial(k_true: float) -> tuple[float, float]:
        e = (rng.normal(size=(n, m)) * noise).ravel() + D @ (np.sqrt(k_true)
                                                             * rng.normal(size=shared))
        r = e - Q @ (Q.T @ e)
        return residual_scale(J, D, S, r, M), residual_scale(J, D, S, r)

    right = np.array([trial(1.0) for _ in range(100)])
    assert np.mean(right[:, 0] > 1.0) < 0.08
    inflated = np.array([trial(10.0) for _ in range(100)])
    assert abs(np.median(inflated[:, 0]) / 10.0 - 1.0) < 0.25
    assert np.median(inflated[:, 1]) < np.median(inflated[:, 0])  # against I: too small
