"""Errors shared by every sample: the stereo rig's calibration error, in the fit's covariance.

Each sample's `cov` holds the noise of that sample only. The rig used to triangulate every
point was itself estimated (from chessboard views) and errs by some delta with covariance
S (24 x 24, `hostpc.vision.rig_uncertainty`). That delta moves every measured point by
D_i @ delta (D_i = dp_i/drig, (3, 24)), the SAME delta for all samples: the measurement
errors are correlated across samples and do not average out. The measurement model supplies
D, S and the per-sample floor (`shared_error`, a `hostpc.model.layout.SharedError`): the rig
is its knowledge (hostpc.kinds.stereo_target.shared_error), not this module's.

The fit's estimator is unchanged (weighted by the per-sample covariances); its covariance is
the sandwich for the full, correlated measurement covariance. To first order the estimate
moves by dx = A @ delta, A = (J^T W J)^-1 J^T W D with J = d(predicted)/dx (whitened, with
the solver's Jw = d(W (measured - predicted))/dx = -W J: A = -Cov @ Jw^T @ Dw), so

    Cov(x) = Cov_noise + A @ S @ A^T.

Which documents carry it: a dataset with a top-level `rig_uncertainty` block
({"rig": <rig file document>, "parameters": [...], "covariance": 24 x 24}) and per-sample
`uv` (the raw pixel centres the points were triangulated from). Written by the stereo_target
method when its rig has a calibration covariance (docs/vision.md section 3).

The same block gives the fit's chi2 with the shared error inside (`shared_error_chi2`,
`result_shared_chi2`; the algebra in hostpc.fitting.shared_chi2): the push guard's adequacy
test (docs/vision.md 3.3).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from hostpc.fitting.shared_chi2 import (
    chi2_with_shared_error,
    covariance_factor,
    shared_excess,
)
from hostpc.model.layout import Problem

SCALE_ALPHA = 0.02
"""S is scaled up (`residual_scale`) only when the fit's residual chi-square exceeds the upper
SCALE_ALPHA quantile of its exact law under the stated S (`shared_chi2.shared_excess`): with
S right, S is scaled up in SCALE_ALPHA of the worlds, whatever the geometry (about the
one-sided level of the earlier "2 standard deviations" gate, which assumed a Gaussian)."""


def shared_covariance(problem: Problem) -> tuple[np.ndarray, np.ndarray] | None:
    """(D (N, m, K) raw sensitivity of the measurements, S (K, K)) of the problem's shared
    error, or None if its measurement model states none for its dataset (no block, no uv,
    wrong shapes)."""
    shared = problem.measurement.shared_error(problem)
    return None if shared is None else (shared.sensitivity, shared.covariance)


def residual_scale(jacobian_free: np.ndarray, D_whitened: np.ndarray, S: np.ndarray,
                   residuals: np.ndarray, noise_blocks: np.ndarray | None = None) -> float:
    """How much larger the shared error is than S says, from the fit's own residuals (>= 1).

    Whitened by the noise (M) and projected off the Jacobian's columns, the residuals have
    E[r^T r] = dof + k trace(G) when Cov(delta) = k S (G = (P Dw L)^T (P Dw L), S = L L^T):
    the method-of-moments estimate k = 1 + (chi2 - dof - trace G) / trace G = (chi2 - dof) /
    trace G is taken only when the excess is significant: chi2 above the upper SCALE_ALPHA
    quantile of its exact law under k = 1 (`shared_chi2.shared_excess`: chi-square plus one
    weighted chi-square(1) per shared direction); else k = 1, the stated S, never less.

    Why the exact law: the earlier gate (chi2 above its mean by 2 of its standard
    deviations, a Gaussian approximation) assumed many comparable shared directions, but one
    or two dominate (the humanoid head camera: one carries 93 % of trace G), so the shared
    part is a heavy-tailed chi-square(1): it scaled a right S up by k = 6-10 in 4 % of the
    worlds (not 2.3 %), and those inflated sigmas pulled the elbows' MSE / sigma^2 to
    0.87-0.89 on average (docs/vision.md 3.1, tests/hostpc/test_shared_error_scale.py).

    jacobian_free: (n, F); D_whitened: (n, K); S: (K, K); residuals: (n,) whitened;
    noise_blocks: (B, b, b) with B b = n, the whitened noise covariance M (block diagonal;
    None: M = I), e.g. the noise without a pixel floor the whitening includes."""
    r = np.ravel(residuals)
    if jacobian_free.shape[0] <= jacobian_free.shape[1] or not np.all(np.isfinite(r)):
        return 1.0
    try:
        chi2, dof, trace, tail = shared_excess(r, jacobian_free,
                                               D_whitened @ covariance_factor(S), noise_blocks)
    except np.linalg.LinAlgError:  # a noise block not positive definite: nothing to test
        return 1.0
    if not trace > 0 or tail >= SCALE_ALPHA:
        return 1.0
    return max(1.0, (chi2 - dof) / trace)


def added_parameter_covariance(problem: Problem, jacobian_free: np.ndarray,
                               covariance_free: np.ndarray, row_weight: np.ndarray,
                               residuals: np.ndarray | None = None,
                               prior_free: np.ndarray | None = None) -> np.ndarray | None:
    """(F, F) what the shared error changes in the free parameters' covariance, or None.

    jacobian_free: (N*m, F) whitened (and robust-weighted) Jacobian of the free parameters;
    covariance_free: (F, F) their noise covariance; row_weight: (N*m,) robust weights'
    square roots applied to the rows; residuals: (N*m,) the fit's whitened residuals (robust
    weights applied): when given, S is scaled by `residual_scale` (the excess of the
    residuals over their noise-only expectation, attributed to the shared error).

    When the block declares a `pixel_floor_px` (a floor the method added to each sample's
    covariance to stand for the shared error in the weights and in chi2), the floor is a
    weighting only: the covariance is the sandwich for the samples' noise without the floor
    plus the (scaled) shared error, and the returned change can be negative.

    prior_free: (K, F) the whitened prior rows (by the free parameters). A prior block that
    states its `shared_sensitivity` B (+d value / d delta: a cell reference's frame recorded
    with the same rig) errs by the SAME shared error as the samples: its part B S B^T of the
    block's covariance is taken out of the noise (A_p S A_p^T, A_p = Cov Jp^T Bw) and the
    shared error enters once, through samples and prior together: (A + A_p) S (A + A_p)^T,
    both +d x / d delta (A = -Cov Jw^T Dw: the samples' rows are measured - predicted, the
    prior's x - value).
    Counted as independent noise instead, the cross terms (of either sign) are lost: the
    reference's rig error and the new samples' are one error."""
    shared = problem.measurement.shared_error(problem)
    if shared is None:
        return None
    D, S, floor = shared.sensitivity, shared.covariance, shared.floor
    W = problem.sqrt_information  # (N, m, m)
    D_whitened = np.einsum("nij,njk->nik", W, D).reshape(-1, D.shape[2]) * row_weight[:, None]
    change = np.zeros_like(covariance_free)
    noise_blocks = None
    if floor is not None:
        # whitened noise without the floor: M_i = I - W_i F_i W_i^T (weights on the rows)
        M = np.eye(W.shape[1])[None] - np.einsum("nij,njk,nlk->nil", W, floor, W)
        weight = row_weight.reshape(W.shape[0], W.shape[1])
        M = weight[:, :, None] * M * weight[:, None, :]
        J3 = jacobian_free.reshape(W.shape[0], W.shape[1], -1)
        meat = np.einsum("nif,nij,njg->fg", J3, M, J3)
        if prior_free is not None:  # the prior rows' noise is theirs in full (no floor)
            meat += prior_free.T @ prior_free
        change += covariance_free @ meat @ covariance_free - covariance_free
        noise_blocks = M
    if residuals is not None:
        S = S * residual_scale(jacobian_free, D_whitened, S, np.ravel(residuals), noise_blocks)
    A = -covariance_free @ (jacobian_free.T @ D_whitened)  # + d x / d delta
    prior_shared = _prior_shared(problem, S.shape[0])
    if prior_shared is not None and prior_free is not None:
        A_prior = covariance_free @ (prior_free.T @ prior_shared)
        change -= A_prior @ shared.covariance @ A_prior.T  # was in the prior's noise
        A = A + A_prior
    change += A @ S @ A.T
    return 0.5 * (change + change.T)


def _prior_shared(problem: Problem, width: int) -> np.ndarray | None:
    """(K, Ks) the whitened `shared_sensitivity` of the problem's prior rows, or None (no
    block states one, or not of the shared error's width)."""
    from hostpc.fitting.priors import problem_constraints

    constraints = problem_constraints(problem)
    shared = None if constraints is None else constraints.whitened_shared()
    return shared if shared is not None and shared.shape[1] == width else None


def parameter_shared_sensitivity(problem: Problem, x: np.ndarray, free: np.ndarray
                                 ) -> np.ndarray | None:
    """(P, Ks) how a fit's estimate at x moves with the shared error, +d x / d delta (zero
    rows for fixed parameters; the linear loss's weights), or None without a shared error:
    measurements moved by D delta and prior blocks' values by their `shared_sensitivity`
    times delta move the refitted x by (this) @ delta. What a cell reference records of a
    frame measured with a stereo rig (hostpc.calibrate.reference), so that a later run with
    the same rig knows the frame's error is its own samples' error too.

    The rows are r = [W (measured - predicted); L^-1 (x - value)]: dr = [Dw; -Bw] delta
    and Gauss-Newton dx = -(Jall^T Jall)^+ Jall^T dr, hence the stack [-Dw; Bw]."""
    from hostpc.fitting.priors import problem_constraints
    from hostpc.fitting.solver import evaluate

    shared = problem.measurement.shared_error(problem)
    if shared is None:
        return None
    x = np.asarray(x, dtype=float)
    free = np.asarray(free, dtype=bool)
    evaluation = evaluate(problem, x)
    assert evaluation.jacobian is not None
    J = evaluation.jacobian[:, free]
    D = np.einsum("nij,njk->nik", problem.sqrt_information, shared.sensitivity)
    Dw = -D.reshape(J.shape[0], -1)
    Jall = J
    constraints = problem_constraints(problem)
    prior_shared = _prior_shared(problem, Dw.shape[1])
    if constraints is not None and constraints.index.size:
        Jall = np.vstack([J, constraints.jacobian(x.size)[:, free]])
        Dw = np.vstack([Dw, np.zeros((constraints.index.size, Dw.shape[1]))
                        if prior_shared is None else prior_shared])
    out = np.zeros((x.size, Dw.shape[1]))
    out[free] = np.linalg.pinv(Jall.T @ Jall) @ (Jall.T @ Dw)
    return out


@dataclass(frozen=True)
class SharedChi2:
    """chi2: the statistic T (see the module docstring); dof: rows - rank of the Jacobian;
    plain_chi2: r^T r over the same rows (without the shared error)."""

    chi2: float
    dof: int
    plain_chi2: float

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")


def shared_error_chi2(problem: Problem, x: np.ndarray, free: np.ndarray
                      ) -> SharedChi2 | None:
    """The chi2 with the shared error inside of a fit at x (P,) with free parameters
    free (P,) bool, or None when the problem's dataset declares no shared error (no
    `rig_uncertainty` block, or no uv).

    Rows: the samples' whitened residuals, unweighted (as the fit's own chi2 and its band:
    under a robust loss the weights would shrink exactly the residuals the guard must see),
    and the prior rows of `--prior`; their Jacobian at x by the free parameters."""
    from hostpc.fitting.priors import problem_constraints
    from hostpc.fitting.solver import evaluate

    shared = shared_covariance(problem)
    if shared is None:
        return None
    D, S = shared
    x = np.asarray(x, dtype=float)
    free = np.asarray(free, dtype=bool)
    evaluation = evaluate(problem, x)
    assert evaluation.jacobian is not None
    n, m = evaluation.whitened.shape
    r = evaluation.whitened.ravel()
    J = evaluation.jacobian[:, free]
    Dw = np.einsum("nij,njk->nik", problem.sqrt_information, D).reshape(n * m, -1)
    U = Dw @ covariance_factor(S)
    constraints = problem_constraints(problem)
    if constraints is not None and constraints.index.size:
        r = np.concatenate([r, constraints.residuals(x)])
        J = np.vstack([J, constraints.jacobian(x.size)[:, free]])
        U = np.vstack([U, np.zeros((constraints.index.size, U.shape[1]))])
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J)) and np.all(np.isfinite(U))):
        return None
    chi2, dof = chi2_with_shared_error(r, J, U)
    return SharedChi2(chi2=chi2, dof=dof, plain_chi2=float(r @ r))


class _Fitted(Protocol):
    """What `result_shared_chi2` reads of a FitResult (named structurally: fitting.result
    imports this module)."""

    @property
    def problem(self) -> Problem: ...
    @property
    def x(self) -> np.ndarray: ...
    @property
    def fixed(self) -> np.ndarray: ...


def result_shared_chi2(result: _Fitted) -> SharedChi2 | None:
    """`shared_error_chi2` of a fit (None for a dataset without a shared error)."""
    return shared_error_chi2(result.problem, result.x, ~result.fixed)
