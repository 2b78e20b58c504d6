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
as in the fit (`shared_errors.shared_error_chi2` builds the rows of a fit). S is used as
stated (not scaled by `shared_errors.residual_scale`, which is estimated from the same
residuals and would make the test unable to fail).

`shared_excess` is the other statistic here: the plain residual chi2 in noise-whitened
coordinates, whose exact law with S right is chi2(dof - R) + sum_j (1 + mu_j) chi2_j(1)
(`weighted_chi2_tail`, a saddlepoint approximation): the gate of the shared error's scale.
Pure numerics: arrays in, numbers out.
"""

from __future__ import annotations

import math

import numpy as np

EIGEN_TOLERANCE = 1e-12
"""Eigenvalues of S below this fraction of the largest are taken as zero (no variance)."""


def covariance_factor(S: np.ndarray) -> np.ndarray:
    """(K, R) L with L @ L.T = S (symmetric positive semi-definite (K, K)); the R columns
    are the eigen-directions with positive variance (R = 0 for S = 0). The eigenvalues are
    taken of the correlation matrix (S scaled by its standard deviations), so parameters in
    different units (px, m) are not cut by the other's scale."""
    S = 0.5 * (np.asarray(S, dtype=float) + np.asarray(S, dtype=float).T)
    sd = np.sqrt(np.clip(np.diag(S), 0.0, None)) if S.size else np.zeros(0)
    varying = sd > 0
    L = np.zeros((S.shape[0], 0))
    if not np.any(varying):
        return L
    d = sd[varying]
    values, vectors = np.linalg.eigh(S[np.ix_(varying, varying)] / np.outer(d, d))
    keep = values > EIGEN_TOLERANCE * float(np.max(np.abs(values)))
    L = np.zeros((S.shape[0], int(np.sum(keep))))
    L[varying] = d[:, None] * vectors[:, keep] * np.sqrt(values[keep])
    return L


def _noise_whitened(residuals: np.ndarray, jacobian: np.ndarray, shared_whitened: np.ndarray,
                    noise_blocks: np.ndarray | None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r (n,), J (n, F), U (n, R)) as arrays, whitened by M^(-1/2) block by block
    (M_i = F_i F_i^T, Cholesky) when noise_blocks M (B, b, b) is given."""
    r = np.asarray(residuals, dtype=float).ravel()
    J = np.asarray(jacobian, dtype=float).reshape(r.size, -1)
    U = np.asarray(shared_whitened, dtype=float).reshape(r.size, -1)
    if noise_blocks is None:
        return r, J, U
    blocks = np.asarray(noise_blocks, dtype=float)
    factor = np.linalg.cholesky(blocks)

    def whiten(a: np.ndarray) -> np.ndarray:
        shaped = a.reshape(blocks.shape[0], blocks.shape[1], -1)
        return np.linalg.solve(factor, shaped).reshape(r.size, -1)

    return whiten(r[:, None]).ravel(), whiten(J), whiten(U)


def chi2_with_shared_error(residuals: np.ndarray, jacobian: np.ndarray,
                           shared_whitened: np.ndarray,
                           noise_blocks: np.ndarray | None = None) -> tuple[float, int]:
    """(T, dof) of whitened residuals r (n,) against V_w = M + U U^T.

    jacobian: (n, F) derivative of r by the free parameters (whitened like r);
    shared_whitened: (n, R) U = Dw L, the whitened shared-error directions (Dw = W D the
    whitened sensitivity of the measurements to the shared parameters, S = L L^T; zero rows
    for rows without shared error, e.g. priors); noise_blocks: (B, b, b) with B b = n, the
    whitened noise covariance M, block diagonal (e.g. the noise without a pixel floor the
    whitening includes), positive definite; None: M = I. dof = n - rank(jacobian)."""
    r, J, U = _noise_whitened(residuals, jacobian, shared_whitened, noise_blocks)
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


def _normal_sf(z: float) -> float:
    return 0.5 * math.erfc(z / math.sqrt(2.0))


def weighted_chi2_tail(x: float, ones: int, weights: np.ndarray) -> float:
    """P(Q > x) for Q = chi2(ones) + sum_j weights_j chi2_j(1) (independent; weights > 0):
    the Lugannani-Rice saddlepoint approximation, accurate to a few % of the tail
    probability in the UPPER tail (the scale gate's use; tested against draws) and at the
    mean (its limit there, 1/2 - skewness / (6 sqrt(2 pi))); in the far lower tail
    (x below ~1e-6 of the mean) it returns 1. Pure Python and numpy (no scipy import: the
    gate runs in every fit of a dataset with a shared error)."""
    lam = np.concatenate([np.ones(1), np.asarray(weights, dtype=float)])
    lam = lam[lam > 0]
    count = np.concatenate([[float(ones)], np.ones(lam.size - 1)])
    if ones <= 0:
        lam, count = lam[1:], count[1:]
    if lam.size == 0:
        return 1.0 if x < 0 else 0.0
    if not x > 0:
        return 1.0
    mean = float(np.sum(count * lam))
    k2 = float(np.sum(2.0 * count * lam**2))
    sd = math.sqrt(k2)
    if abs(x - mean) < 1e-3 * sd:  # the saddlepoint formula's removable singularity
        skewness = float(np.sum(8.0 * count * lam**3)) / k2**1.5
        return 0.5 - skewness / (6.0 * math.sqrt(2.0 * math.pi))
    if x < 1e-6 * mean:
        return 1.0

    def slope(t: float) -> float:  # K'(t) - x, increasing in t
        return float(np.sum(count * lam / (1.0 - 2.0 * lam * t))) - x

    upper = 0.5 / float(np.max(lam)) * (1.0 - 1e-12)
    if slope(upper) < 0:  # beyond what the floats resolve: the tail is 0
        return 0.0
    lower = -1.0
    while slope(lower) > 0:
        lower *= 4.0
    for _ in range(200):  # bisection to the float resolution (the slope is monotone)
        middle = 0.5 * (lower + upper)
        if middle in (lower, upper):
            break
        if slope(middle) > 0:
            upper = middle
        else:
            lower = middle
    t = 0.5 * (lower + upper)
    cgf = -0.5 * float(np.sum(count * np.log1p(-2.0 * lam * t)))
    curvature = float(np.sum(2.0 * count * lam**2 / (1.0 - 2.0 * lam * t) ** 2))
    w = math.copysign(math.sqrt(max(2.0 * (t * x - cgf), 0.0)), t)
    u = t * math.sqrt(curvature)
    if abs(w) < 1e-6 or abs(u) < 1e-9:
        return _normal_sf((x - mean) / sd)
    density = math.exp(-0.5 * w * w) / math.sqrt(2.0 * math.pi)
    tail = _normal_sf(w) + density * (1.0 / u - 1.0 / w)
    return min(1.0, max(0.0, tail))


def shared_excess(residuals: np.ndarray, jacobian: np.ndarray, shared_whitened: np.ndarray,
                  noise_blocks: np.ndarray | None = None) -> tuple[float, int, float, float]:
    """The residuals' plain chi-square in noise-whitened coordinates and its null law.

    Whitened by M^(-1/2) (noise_blocks M, None: I) and projected off the Jacobian's
    columns (P'), the residuals are r' = P' (e' + U' z): with the stated shared covariance
    right, Q = r'^T r' is exactly chi2(dof - R) + sum_j (1 + mu_j) chi2(1), mu_j (R of them)
    the eigenvalues of G = (P'U')^T (P'U'). Returns (Q, dof, trace G, P(Q' >= Q) under that
    law): Q - dof = k' trace G estimates the shared covariance's scale minus 1
    (`shared_errors.residual_scale`). Arguments as for `chi2_with_shared_error`."""
    r, J, U = _noise_whitened(residuals, jacobian, shared_whitened, noise_blocks)
    Q, _ = np.linalg.qr(J) if J.shape[1] else (np.zeros((r.size, 0)), None)
    r = r - Q @ (Q.T @ r)
    PU = U - Q @ (Q.T @ U)
    mu = np.linalg.eigvalsh(PU.T @ PU) if U.shape[1] else np.zeros(0)
    mu = mu[mu > 1e-12 * max(float(np.max(mu, initial=0.0)), 1e-300)]
    dof = int(r.size - Q.shape[1])
    statistic = float(r @ r)
    tail = weighted_chi2_tail(statistic, dof - mu.size, 1.0 + mu) if dof > 0 else 1.0
    return statistic, dof, float(np.sum(mu)), tail
