"""The chi-square with the shared (rig / head camera) error inside
(hostpc.fitting.shared_chi2): Woodbury against the dense GLS form, its distribution over
draws (false alarms at alpha), and on a simulated dual_loop dataset."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy import stats

import hostpc
from hostpc.dataset import dataset_from_dict
from hostpc.fitting.shared_chi2 import (
    chi2_with_shared_error,
    covariance_factor,
    weighted_chi2_tail,
)
from hostpc.fitting.shared_errors import result_shared_chi2, shared_covariance
from hostpc.fitting.solver import evaluate
from hostpc.kinds.dual_loop.planning import plan_poses
from tests.hostpc.test_head_camera_uncertainty import world_documents


def dense_chi2(r: np.ndarray, J: np.ndarray, U: np.ndarray) -> float:
    """r^T V^-1 r - (J^T V^-1 r)^T (J^T V^-1 J)^-1 (J^T V^-1 r), V = I + U U^T, dense."""
    V_inv = np.linalg.inv(np.eye(r.size) + U @ U.T)
    a = J.T @ V_inv @ r
    return float(r @ V_inv @ r - a @ np.linalg.solve(J.T @ V_inv @ J, a))


def random_problem(rng: np.random.Generator, n: int = 40, F: int = 5, K: int = 6
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    J = rng.normal(size=(n, F)) * np.logspace(-3, 2, F)  # badly scaled columns, as in a fit
    D = rng.normal(size=(n, K))
    A = rng.normal(size=(K, K - 2))
    S = 4.0 * A @ A.T / K  # singular: two directions without variance
    return J, D, S


def test_covariance_factor_reproduces_a_singular_covariance() -> None:
    rng = np.random.default_rng(1)
    _, _, S = random_problem(rng)
    L = covariance_factor(S)
    assert L.shape == (6, 4)
    np.testing.assert_allclose(L @ L.T, S, atol=1e-12)
    assert covariance_factor(np.zeros((3, 3))).shape == (3, 0)


def test_woodbury_equals_the_dense_gls_chi2() -> None:
    rng = np.random.default_rng(2)
    for _ in range(5):
        J, D, S = random_problem(rng)
        U = D @ covariance_factor(S)
        r = rng.normal(size=J.shape[0]) + U @ rng.normal(size=U.shape[1])
        chi2, dof = chi2_with_shared_error(r, J, U)
        assert dof == J.shape[0] - J.shape[1]
        assert chi2 == pytest.approx(dense_chi2(r, J, U), rel=1e-9)
        # no shared error: the plain least-squares residual
        plain, _ = chi2_with_shared_error(r, J, np.zeros((r.size, 0)))
        projected = r - J @ np.linalg.lstsq(J, r, rcond=None)[0]
        assert plain == pytest.approx(float(projected @ projected), rel=1e-9)


def test_residuals_of_the_plain_fit_give_the_same_statistic_as_the_errors() -> None:
    """The GLS projector annihilates J: the C-weighted fit's residuals r = P e give the
    same T as the errors e themselves (the fit need not be the GLS one)."""
    rng = np.random.default_rng(3)
    J, D, S = random_problem(rng)
    U = D @ covariance_factor(S)
    e = rng.normal(size=J.shape[0]) + U @ rng.normal(size=U.shape[1])
    r = e - J @ np.linalg.lstsq(J, e, rcond=None)[0]
    assert chi2_with_shared_error(r, J, U)[0] == pytest.approx(
        chi2_with_shared_error(e, J, U)[0], rel=1e-9)


def test_false_alarm_rate_at_alpha_over_draws() -> None:
    """1000 draws of errors with covariance I + D S D^T, fitted by plain least squares:
    T above the chi-square upper alpha quantile in about alpha of them (the plain r^T r
    alarms far more often: the shared error is large here), and T's mean is the dof."""
    rng = np.random.default_rng(4)
    J, D, S = random_problem(rng, n=60)
    U = D @ covariance_factor(S)
    draws, alpha = 1000, 0.05
    errors = rng.normal(size=(draws, 60)) + rng.normal(size=(draws, U.shape[1])) @ U.T
    T, plain = [], []
    for e in errors:
        r = e - J @ np.linalg.lstsq(J, e, rcond=None)[0]
        chi2, dof = chi2_with_shared_error(r, J, U)
        T.append(chi2)
        plain.append(float(r @ r))
    edge = float(stats.chi2.ppf(1.0 - alpha, dof))
    alarms = int(np.sum(np.array(T) > edge))
    # binomial(1000, 0.05): mean 50, sd 6.9; 3 sd either side
    assert 29 <= alarms <= 71, alarms
    assert np.mean(np.array(plain) > edge) > 0.3  # without the shared error: not honest
    assert np.mean(T) == pytest.approx(dof, rel=0.03)
    assert stats.kstest(T, stats.chi2(dof).cdf).pvalue > 1e-3


def test_rank_deficient_jacobian_counts_its_rank() -> None:
    rng = np.random.default_rng(5)
    J, D, S = random_problem(rng)
    J = np.column_stack([J, J[:, 0] + J[:, 1]])
    U = D @ covariance_factor(S)
    r = rng.normal(size=J.shape[0])
    chi2, dof = chi2_with_shared_error(r, J, U)
    assert dof == J.shape[0] - 5
    assert chi2 == pytest.approx(dense_chi2(r, J[:, :5], U), rel=1e-8)


def test_fit_statistic_on_a_dual_loop_dataset_equals_the_dense_form() -> None:
    """On a simulated humanoid dataset (head camera calibration in the dataset):
    `result_shared_chi2` equals the dense form built from the fit's own rows, is below the
    plain chi2, and is None without the calibration block."""
    document, _ = world_documents(3, plan_poses(12, np.random.default_rng(6)), 0.3)
    result = hostpc.fit(dataset_from_dict(document), cv_folds=0)
    full = result_shared_chi2(result)
    assert full is not None
    problem = result.problem
    evaluation = evaluate(problem, result.x)
    assert evaluation.jacobian is not None
    D, S = shared_covariance(problem) or (None, None)
    assert D is not None and S is not None
    n, m = evaluation.whitened.shape
    Dw = np.einsum("nij,njk->nik", problem.sqrt_information, D).reshape(n * m, -1)
    J = evaluation.jacobian[:, ~result.fixed]
    expected = dense_chi2(evaluation.whitened.ravel(), J, Dw @ covariance_factor(S))
    assert full.chi2 == pytest.approx(expected, rel=1e-6)
    assert full.dof == result.dof
    assert full.plain_chi2 == pytest.approx(result.chi2, rel=1e-12)
    assert full.chi2 < result.chi2
    plain = copy.deepcopy(document)
    plain.pop("rig_uncertainty")
    assert result_shared_chi2(hostpc.fit(dataset_from_dict(plain), cv_folds=0)) is None


def test_weighted_chi2_tail_against_draws() -> None:
    """The saddlepoint tail of chi2(ones) + sum w_j chi2(1) against 200 000 draws, from
    the middle to the 0.5 % tail, one dominant weight (the humanoid head camera's case)
    and none of the plain part."""
    from hostpc.fitting.shared_chi2 import weighted_chi2_tail

    rng = np.random.default_rng(14)
    for ones, weights in ((190, [10.2, 1.35, 1.2]), (5, [30.0]), (0, [2.0, 3.0])):
        w = np.array(weights)
        Q = (stats.chi2.rvs(ones, size=200_000, random_state=rng) if ones
             else np.zeros(200_000)) + (rng.normal(size=(200_000, w.size)) ** 2) @ w
        for alpha in (0.5, 0.1, 0.02, 0.005):
            tail = weighted_chi2_tail(float(np.quantile(Q, 1.0 - alpha)), ones, w)
            assert tail == pytest.approx(alpha, rel=0.1), (ones, weights, alpha, tail)
    assert weighted_chi2_tail(-1.0, 3, np.zeros(0)) == 1.0


def test_robust_loss_does_not_soften_the_push_guards_chi2() -> None:
    """Under a robust loss the guard's chi2 with the calibration inside is the UNWEIGHTED
    one, as the fit's own chi2 and its band: with the calibration claimed exact it equals
    the plain chi2 for every loss (the review's case: cauchy tested 1.03 against a plain
    1.75 and pushed)."""
    document, _ = world_documents(1, plan_poses(40, np.random.default_rng(3)), 1.0)
    block = document["rig_uncertainty"]
    block["covariance"] = (np.asarray(block["covariance"]) * 1e-12).tolist()
    linear = hostpc.fit(dataset_from_dict(document), cv_folds=0)
    for loss in ("huber", "cauchy"):
        result = hostpc.fit(dataset_from_dict(document), cv_folds=0, loss=loss)
        full = result_shared_chi2(result)
        assert full is not None
        # the GLS statistic re-minimises over the model's directions: at the robust
        # solution it is the linear fit's chi2 (the weighted one was 0.59x that)
        assert full.chi2 == pytest.approx(linear.chi2, rel=2e-3), loss


def test_covariance_factor_keeps_small_variances_in_other_units() -> None:
    """A 1 px^2 and a 1e-13 m^2 variance: both directions kept (a raw eigenvalue cut at
    1e-12 of the largest dropped the metres)."""
    S = np.diag([1.0, 1e-13])
    L = covariance_factor(S)
    assert L.shape == (2, 2)
    assert L @ L.T == pytest.approx(S, rel=1e-9, abs=1e-25)
    correlated = np.array([[1.0, 1e-6], [1e-6, 1e-12]])  # correlation 1: one direction
    assert covariance_factor(correlated).shape[1] == 1


def test_weighted_chi2_tail_edges() -> None:
    """At the mean: the saddlepoint's limit (1/2 - skewness / (6 sqrt(2 pi))), continuous
    with its neighbours and near the draws (was the normal's 1/2);
    a statistic beyond the floats' resolution: 0, not an exception; far below the mean: 1."""
    weights = np.array([10.0])
    mean = 100.0 + 10.0
    skew = (8 * (100 + 1000)) / (2 * (100 + 100)) ** 1.5
    assert weighted_chi2_tail(mean, 100, weights) == pytest.approx(
        0.5 - skew / (6 * np.sqrt(2 * np.pi)), rel=1e-12)
    draws = np.random.default_rng(0).chisquare(100, 200_000) + 10 * np.random.default_rng(
        1).chisquare(1, 200_000)
    assert weighted_chi2_tail(mean, 100, weights) == pytest.approx(
        float(np.mean(draws > mean)), abs=0.025)
    sd = np.sqrt(400.0)
    for step in (-0.002, 0.002):
        assert weighted_chi2_tail(mean + step * sd, 100, weights) == pytest.approx(
            weighted_chi2_tail(mean, 100, weights), abs=2e-3)
    assert weighted_chi2_tail(2e13, 100, weights) == 0.0
    assert weighted_chi2_tail(1e-300, 100, weights) == 1.0
