"""The verification verdict is a chi-square test with a stated false-FAIL rate.

Pure numerics on synthetic stereo_target data whose stated covariances are the true ones:
a correct model FAILs at the design rate (the prediction's own uncertainty included, or a
fit on few poses would FAIL too often), and a model missing an effect FAILs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from hostpc.calibrate.verify import chi_square_statistic, evaluate_verify
from hostpc.fitting import fit
from hostpc.synthesize import synthesize_stereo_target

OFFSETS = {f"joint_offsets.q{j}": 0.002 * (-1) ** j for j in range(1, 7)}
KNOWN = ("target",)


def test_statistic_is_the_mahalanobis_norm_with_the_prediction_covariance() -> None:
    rng = np.random.default_rng(0)
    K, m, P = 4, 3, 5
    r = rng.normal(size=(K, m))
    A = rng.normal(size=(K, m, m)) + 3 * np.eye(m)
    cov = A @ np.swapaxes(A, 1, 2)
    W = np.linalg.inv(np.linalg.cholesky(cov))  # W^T W = cov^-1
    J = rng.normal(size=(K, m, P))
    B = rng.normal(size=(P, P))
    sigma_x = B @ B.T * 0.1
    C = np.zeros((K * m, K * m))
    for k in range(K):
        C[k * m:(k + 1) * m, k * m:(k + 1) * m] = cov[k] * 1.5**2
    Jf = J.reshape(K * m, P)
    S = C + Jf @ sigma_x @ Jf.T
    expected = float(r.reshape(-1) @ np.linalg.solve(S, r.reshape(-1)))
    statistic, dof = chi_square_statistic(r, W, J, sigma_x, factor=1.5)
    assert dof == K * m
    assert statistic == pytest.approx(expected, rel=1e-10)


def test_false_fail_rate_matches_alpha_and_a_missing_effect_fails() -> None:
    # a fit on few poses: its prediction error is comparable with the noise
    data = synthesize_stereo_target(OFFSETS, n_samples=15, seed=1, known=KNOWN).dataset
    result = fit(data, "joint_offsets,tool", cv_folds=0)
    assert result.converged
    alpha = 0.1
    p_values = []
    for seed in range(100, 300):
        fresh = synthesize_stereo_target(OFFSETS, n_samples=3, seed=seed,
                                         known=KNOWN).dataset
        verdict = evaluate_verify(result, fresh, np.zeros(6), 3, alpha=alpha)
        assert verdict.dof == 9
        p_values.append(verdict.p_value)
    p = np.asarray(p_values)
    fails = int(np.sum(p < alpha))
    # binomial(200, 0.1): 99.9 % of outcomes within [7, 35]
    assert 7 <= fails <= 35, fails
    # the p-values of a correct model are uniform
    assert stats.kstest(p, "uniform").pvalue > 1e-3
    # a hidden encoder scale the model lacks: FAIL on 10 fresh poses
    hidden = {**OFFSETS, "encoder_scale.s2": 2e-3}
    fresh = synthesize_stereo_target(hidden, n_samples=10, seed=7, known=KNOWN).dataset
    verdict = evaluate_verify(result, fresh, np.zeros(6), 10)
    assert not verdict.passed and verdict.p_value < 1e-6 and verdict.verdict == "FAIL"
    assert "p = " in verdict.reason


def test_station_tolerance_fails_a_statistically_fine_verification() -> None:
    data = synthesize_stereo_target(OFFSETS, n_samples=30, seed=2, known=KNOWN).dataset
    result = fit(data, "joint_offsets,tool", cv_folds=0)
    fresh = synthesize_stereo_target(OFFSETS, n_samples=10, seed=3, known=KNOWN).dataset
    loose = evaluate_verify(result, fresh, np.zeros(6), 10, tolerance=1.0)
    assert loose.passed
    tight = evaluate_verify(result, fresh, np.zeros(6), 10, tolerance=loose.rms_after / 2)
    assert not tight.passed and "tolerance" in tight.reason
    doc = tight.to_dict()
    for key in ("verdict", "statistic", "dof", "p_value", "alpha", "rms_mm", "tolerance_mm",
                "n_poses"):
        assert key in doc
    assert doc["verdict"] == "FAIL" and doc["tolerance_mm"] == pytest.approx(
        loose.rms_after * 500)
