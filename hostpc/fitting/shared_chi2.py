"""The fit's chi-square with the shared (rig / head camera calibration) error inside.

The plain chi2 of a fit, `r^T r` over the whitened residuals, tests the residuals against
the samples' own covariance (noise, plus a pixel floor where the method adds one). The
rig's calibration error is not in it: it moves every point by `D_i @ delta`, the same
`delta` (covariance S) for every sample (hostpc.fitting.shared_errors), so a world whose rig
errs within its stated covariance can still push chi2 above its band. This module tests
the residuals against the full covariance instead,

    V = C + D S D^T        (whitened: V_w = I + U U^T, U = Dw L, S = L L^T),

with the residual projector of the generalised least-squares fit under V:

    T = min_x (r - J x)^T V^-1 (r - J x)
      = r^T V^-1 r - (J^T V^-1 r)^T (J^T V^-1 J)^-1 (J^T V^-1 r).

The fit itself is the C-weighted one (its residuals r differ from the measurement errors e
by J dx), but the GLS projector annihilates J's columns, so T is the same for r as for e:
for Gaussian errors with covariance V and a linear model, T follows chi-square with exactly
`rows - rank(J)` degrees of freedom (the plain chi2 does not: its expectation grows with
`trace(P Dw S Dw^T P)`). V^-1 is never formed: V_w^(-1/2) = I - Q (I - (1 + s^2)^(-1/2)) Q^T
from the thin SVD U = Q diag(s) R^T (the Woodbury identity over the K <= 24 shared
parameters), then T is the squared residual of least squares on the rows whitened by it.
Cost O(rows (K^2 + F^2)). A singular S (parameters with zero variance) is fine: L keeps
only its positive eigen-directions.

Prior rows (`--prior`) enter as rows with no shared error; robust weights multiply the rows
as in the fit. S is used as stated (not scaled by `shared_errors.residual_scale`, which is
estimated from this same chi2 and would make the test unable to fail).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.model.problem import Problem

EIGEN_TOLERANCE = 1e-12
"""Eigenvalues of S below this fraction of the largest are taken as zero (no variance)."""


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


def covariance_factor(S: np.ndarray) -> np.ndarray:
    """(K, R) L with L @ L.T = S (symmetric positive semi-definite (K, K)); the R columns
    are the eigen-directions with positive variance (R = 0 for S = 0)."""
    S = 0.5 * (np.asarray(S, dtype=float) + np.asarray(S, dtype=float).T)
    values, vectors = np.linalg.eigh(S)
    largest = float(np.max(np.abs(values))) if values.size else 0.0
    keep = values > EIGEN_TOLERANCE * largest
    return vectors[:, keep] * np.sqrt(values[keep])


def chi2_with_shared_error(residuals: np.ndarray, jacobian: np.ndarray,
                           shared_whitened: np.ndarray) -> tuple[float, int]:
    """(T, dof) of whitened residuals r (n,) against V_w = I + U U^T.

    jacobian: (n, F) derivative of r by the free parameters (whitened like r);
    shared_whitened: (n, R) U = Dw L, the whitened shared-error directions (Dw = W D the
    whitened sensitivity of the measurements to the shared parameters, S = L L^T; zero rows
    for rows without shared error, e.g. priors). dof = n - rank(jacobian)."""
    r = np.asarray(residuals, dtype=float).ravel()
    J = np.asarray(jacobian, dtype=float).reshape(r.size, -1)
    U = np.asarray(shared_whitened, dtype=float).reshape(r.size, -1)
    if U.shape[1]:
        Q, s, _ = np.linalg.svd(U, full_matrices=False)
        shrink = 1.0 - 1.0 / np.sqrt(1.0 + s**2)  # V^(-1/2) = I - Q diag(shrink) Q^T
        r = r - Q @ (shrink * (Q.T @ r))
        J = J - Q @ (shrink[:, None] * (Q.T @ J))
    rank = 0
    if J.shape[1]:
        scale = np.linalg.norm(J, axis=0)
        scale[scale == 0] = 1.0
        Qj, Rj = np.linalg.qr(J / scale)
        diagonal = np.abs(np.diag(Rj))
        independent = diagonal > 1e-10 * max(float(np.max(diagonal, initial=0.0)), 1e-300)
        if not np.all(independent):  # rank-deficient: project with an SVD basis instead
            Uj, sj, _ = np.linalg.svd(J / scale, full_matrices=False)
            Qj = Uj[:, sj > 1e-10 * float(sj[0])]
        else:
            Qj = Qj[:, independent]
        rank = Qj.shape[1]
        r = r - Qj @ (Qj.T @ r)
    return float(r @ r), int(r.size - rank)


def shared_error_chi2(problem: Problem, x: np.ndarray, free: np.ndarray,
                      weights: np.ndarray | None = None) -> SharedChi2 | None:
    """The chi2 with the shared error inside of a fit at x (P,) with free parameters
    free (P,) bool and robust sample weights (N,) (None: all 1), or None when the
    problem's dataset declares no shared error (no `rig_uncertainty` block, or no uv).

    Rows: the samples' whitened residuals (the weights' square roots applied) and the prior
    rows of `--prior`; their Jacobian at x by the free parameters."""
    from hostpc.fitting.priors import problem_constraints
    from hostpc.fitting.shared_errors import shared_covariance
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
    row_weight = (np.ones(n * m) if weights is None
                  else np.repeat(np.sqrt(np.asarray(weights, dtype=float)), m))
    r = evaluation.whitened.ravel() * row_weight
    J = evaluation.jacobian[:, free] * row_weight[:, None]
    L = covariance_factor(S)
    Dw = np.einsum("nij,njk->nik", problem.sqrt_information, D).reshape(n * m, -1)
    U = (Dw @ L) * row_weight[:, None]
    constraints = problem_constraints(problem)
    if constraints is not None and constraints.index.size:
        r = np.concatenate([r, constraints.residuals(x)])
        J = np.vstack([J, constraints.jacobian(x.size)[:, free]])
        U = np.vstack([U, np.zeros((constraints.index.size, U.shape[1]))])
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J)) and np.all(np.isfinite(U))):
        return None
    chi2, dof = chi2_with_shared_error(r, J, U)
    return SharedChi2(chi2=chi2, dof=dof, plain_chi2=float(r @ r))


def result_shared_chi2(result: object) -> SharedChi2 | None:
    """`shared_error_chi2` of a FitResult (None for anything else, e.g. a saved fit that
    carries no problem, or a dataset without a shared error)."""
    problem = getattr(result, "problem", None)
    if not isinstance(problem, Problem):
        return None
    x, fixed, weights = (getattr(result, k, None) for k in ("x", "fixed", "weights"))
    if x is None or fixed is None:
        return None
    return shared_error_chi2(problem, np.asarray(x), ~np.asarray(fixed, dtype=bool),
                             None if weights is None else np.asarray(weights))
