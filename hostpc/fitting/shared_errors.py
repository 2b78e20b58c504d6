"""Errors shared by every sample: the stereo rig's calibration error, in the fit's covariance.

Each sample's `cov` holds the noise of that sample only. The rig used to triangulate every
point was itself estimated (from chessboard views) and errs by some delta with covariance
S (24 x 24, `hostpc.vision.rig_uncertainty`). That delta moves every measured point by
D_i @ delta (D_i = dp_i/drig, (3, 24)), the SAME delta for all samples: the measurement
errors are correlated across samples and do not average out.

The fit's estimator is unchanged (weighted by the per-sample covariances); its covariance is
the sandwich for the full, correlated measurement covariance. To first order the estimate
moves by dx = A @ delta, A = (J^T W J)^-1 J^T W D (whitened: A = Cov @ Jw^T @ Dw), so

    Cov(x) = Cov_noise + A @ S @ A^T.

Which documents carry it: a dataset with a top-level `rig_uncertainty` block
({"rig": <rig file document>, "parameters": [...], "covariance": 24 x 24}) and per-sample
`uv` (the raw pixel centres the points were triangulated from). Written by the stereo_target
method when its rig has a calibration covariance (docs/vision.md section 3).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Any

import numpy as np

from hostpc.model.problem import Problem

BLOCK = "rig_uncertainty"
SIGNIFICANCE = 2.0
"""The residual excess must exceed what the stated covariance explains by this many of its
standard deviations before the shared covariance is scaled up (`residual_scale`)."""
_CACHE: OrderedDict[str, np.ndarray] = OrderedDict()
_CACHE_SIZE = 16


def _sensitivity(block: Any, uv: np.ndarray) -> np.ndarray | None:
    """(N, 3, 24) dp/drig for the samples' uv (cached: candidate fits reuse it)."""
    from hostpc.errors import InputError
    from hostpc.vision.rig import rig_from_dict
    from hostpc.vision.rig_uncertainty import point_sensitivity

    digest = hashlib.sha1(np.ascontiguousarray(uv).tobytes())
    digest.update(repr(block.get("rig")).encode())
    key = digest.hexdigest()
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    try:
        rig = rig_from_dict(block.get("rig"), f"dataset {BLOCK}.rig")
    except InputError:
        return None
    value = point_sensitivity(rig, uv)
    _CACHE[key] = value
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return value


def shared_covariance(problem: Problem) -> tuple[np.ndarray, np.ndarray] | None:
    """(D (N, m, K) raw sensitivity of the measurements, S (K, K)) of the problem's shared
    error, or None if its dataset declares none (or cannot: no uv, wrong shapes)."""
    block = problem.dataset.extra_fields.get(BLOCK)
    if not isinstance(block, dict):
        return None
    uv = getattr(problem.dataset.samples, "uv", None)
    if uv is None or problem.measured.shape[1] != 3:
        return None
    try:
        S = np.asarray(block.get("covariance"), dtype=float)
    except (TypeError, ValueError):
        return None
    D = _sensitivity(block, np.asarray(uv, float))
    if D is None or S.ndim != 2 or S.shape != (D.shape[2], D.shape[2]):
        return None
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(D))):
        return None
    return D, S


def residual_scale(jacobian_free: np.ndarray, D_whitened: np.ndarray, S: np.ndarray,
                   residuals: np.ndarray, expected_noise: float | None = None,
                   noise_variance: float | None = None) -> float:
    """How much larger the shared error is than S says, from the fit's own residuals (>= 1).

    The whitened residuals r = P (e + Dw delta) (P: projector off the Jacobian's columns)
    have E[r^T r] = dof + k trace(P Dw S Dw^T P) when Cov(delta) = k S. The method-of-moments
    estimate k = (chi2 - dof) / trace(...) is taken only when the excess is significant:
    chi2 above its expectation under k = 1 by more than SIGNIFICANCE standard deviations
    (Var = 2 dof + 2 trace((P Dw S Dw^T P)^2) for Gaussian errors); else k = 1, the rig's
    own covariance, never less. (Without the gate, a chance excess of the noise in a world
    whose S is right inflated the sigma: dual_loop's elbow offsets came out at MSE / sigma^2
    0.6-0.7.) expected_noise, noise_variance replace dof, 2 dof when the whitening includes
    more than the noise (a pixel floor: see below)."""
    rows, free = jacobian_free.shape
    dof = rows - free
    if dof <= 0 or not np.all(np.isfinite(residuals)):
        return 1.0
    Q, _ = np.linalg.qr(jacobian_free)
    PD = D_whitened - Q @ (Q.T @ D_whitened)
    G = PD.T @ PD
    GS = G @ S
    trace = float(np.trace(GS))
    if not trace > 0:
        return 1.0
    chi2 = float(residuals @ residuals)
    noise = float(dof) if expected_noise is None else expected_noise
    variance = (2.0 * dof if noise_variance is None else noise_variance) \
        + 2.0 * float(np.sum(GS * GS.T))
    if chi2 - noise - trace <= SIGNIFICANCE * np.sqrt(max(variance, 0.0)):
        return 1.0
    return max(1.0, (chi2 - noise) / trace)


def noise_moments(M: np.ndarray, Q3: np.ndarray) -> tuple[float, float]:
    """Mean and variance of r^T r for r = P e, e ~ N(0, M) (M: (N, m, m) block diagonal),
    P = I - Q Q^T the projector off the orthonormal columns Q3 ((N, m, F) per block):
    trace(P M P) = tr M - tr Q^T M Q and 2 trace(M P M P) =
    2 (tr M^2 - 2 tr Q^T M^2 Q + tr (Q^T M Q)^2), without forming an (Nm, Nm) matrix."""
    M2 = np.einsum("nij,njk->nik", M, M)
    QMQ = np.einsum("nif,nij,njg->fg", Q3, M, Q3)
    mean = float(np.trace(M, axis1=1, axis2=2).sum() - np.trace(QMQ))
    variance = 2.0 * float(np.einsum("nij,nji->", M, M)
                           - 2.0 * np.einsum("nif,nij,njf->", Q3, M2, Q3)
                           + np.sum(QMQ * QMQ.T))
    return mean, variance


def floor_covariance(problem: Problem, block: Any) -> np.ndarray | None:
    """(N, 3, 3) the per-sample `pixel_floor_px` part of the samples' covariance (the
    diagonal lateral z s/f, depth z^2 sqrt(2) s/(f b) model of stereo_target), or None if the
    block declares no floor."""
    try:
        floor = float(block.get("pixel_floor_px") or 0.0)
        rig = block.get("rig") or {}
        fx = float(rig["K_left"][0][0])
        baseline = float(np.linalg.norm(np.asarray(rig["T"], float)))
    except (TypeError, ValueError, KeyError, IndexError):
        return None
    if not (floor > 0 and fx > 0 and baseline > 0):
        return None
    z = np.maximum(np.abs(np.asarray(problem.measured, float)[:, 2]), 1e-3)
    cov = np.zeros((z.size, 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = (z * floor / fx) ** 2
    cov[:, 2, 2] = (z**2 * np.sqrt(2.0) * floor / (fx * baseline)) ** 2
    return cov


def added_parameter_covariance(problem: Problem, jacobian_free: np.ndarray,
                               covariance_free: np.ndarray, row_weight: np.ndarray,
                               residuals: np.ndarray | None = None) -> np.ndarray | None:
    """(F, F) what the shared error changes in the free parameters' covariance, or None.

    jacobian_free: (N*m, F) whitened (and robust-weighted) Jacobian of the free parameters;
    covariance_free: (F, F) their noise covariance; row_weight: (N*m,) robust weights'
    square roots applied to the rows; residuals: (N*m,) the fit's whitened residuals (robust
    weights applied): when given, S is scaled by `residual_scale` (the excess of the
    residuals over their noise-only expectation, attributed to the shared error).

    When the block declares a `pixel_floor_px` (a floor the method added to each sample's
    covariance to stand for the shared error in the weights and in chi2), the floor is a
    weighting only: the covariance is the sandwich for the samples' noise without the floor
    plus the (scaled) shared error, and the returned change can be negative."""
    shared = shared_covariance(problem)
    if shared is None:
        return None
    D, S = shared
    W = problem.sqrt_information  # (N, m, m)
    D_whitened = np.einsum("nij,njk->nik", W, D).reshape(-1, D.shape[2]) * row_weight[:, None]
    floor = floor_covariance(problem, problem.dataset.extra_fields.get(BLOCK))
    change = np.zeros_like(covariance_free)
    expected_noise = noise_variance = None
    if floor is not None:
        # whitened noise without the floor: M_i = I - W_i F_i W_i^T (weights on the rows)
        M = np.eye(W.shape[1])[None] - np.einsum("nij,njk,nlk->nil", W, floor, W)
        weight = row_weight.reshape(W.shape[0], W.shape[1])
        M = weight[:, :, None] * M * weight[:, None, :]
        J3 = jacobian_free.reshape(W.shape[0], W.shape[1], -1)
        meat = np.einsum("nif,nij,njg->fg", J3, M, J3)
        change += covariance_free @ meat @ covariance_free - covariance_free
        Q, _ = np.linalg.qr(jacobian_free)
        expected_noise, noise_variance = noise_moments(
            M, Q.reshape(W.shape[0], W.shape[1], -1))
    if residuals is not None:
        S = S * residual_scale(jacobian_free, D_whitened, S, np.ravel(residuals),
                               expected_noise, noise_variance)
    A = covariance_free @ (jacobian_free.T @ D_whitened)
    change += A @ S @ A.T
    return 0.5 * (change + change.T)
