"""Parameter sigmas when the stated noise is not to be trusted: scaled and resampled.

A fit's sigmas (``FitResult.std``) take the samples' stated covariances as given. Real
files often misstate the noise (chi2/dof of 3-5 on laser-tracker and motion-capture data),
and then every sigma is too small by sqrt(chi2/dof). Two honest alternatives, reported
beside the stated-noise sigmas, never instead of them:

- ``scaled_std``: the sigmas times sqrt(chi2/dof): right when the noise is misstated by one
  factor for all samples and the model is right;
- ``jackknife_std``: the leave-one-pose-out jackknife, which assumes neither: each pose
  (all its samples, ``hostpc.fitting.folds.pose_groups``) is left out in turn, and the
  spread of the fits without it, times (g - 1) / sqrt(g) over g poses, is the sigma. Each
  leave-out fit is the linearised step from the full solution (the same update as the
  cross-validation's, exact for a linear model and off by the curvature times the step
  squared), refitted where the remaining poses do not determine the parameters or the loss
  is robust.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np

from hostpc.fitting.fitting import _leave_out_steps
from hostpc.fitting.folds import pose_groups
from hostpc.fitting.result import FitResult
from hostpc.fitting.solver import Loss, evaluate, levenberg_marquardt

MIN_JACKKNIFE_POSES = 3


def scaled_std(result: FitResult) -> np.ndarray:
    """(P,) the sigmas scaled by sqrt(chi2/dof) (NaN where fixed, or without dof)."""
    factor = math.sqrt(result.chi2_dof) if result.dof > 0 and math.isfinite(
        result.chi2_dof) else math.nan
    return np.asarray(result.std, float) * factor


def jackknife_std(result: FitResult) -> np.ndarray | None:
    """(P,) leave-one-pose-out jackknife sigma of every parameter (NaN where the fit held
    it); None with fewer than MIN_JACKKNIFE_POSES poses."""
    problem = result.problem
    groups = pose_groups(problem.dataset.samples)
    n_poses = int(groups.max()) + 1 if groups.size else 0
    if n_poses < MIN_JACKKNIFE_POSES:
        return None
    order = np.argsort(groups, kind="stable")
    pose_sets = np.split(order, np.flatnonzero(np.diff(groups[order])) + 1)
    free = ~result.fixed
    steps: list[np.ndarray | None] = [None] * n_poses
    if result.loss == "linear":
        steps = _leave_out_steps(problem, evaluate(problem, result.x), free, pose_sets)
    estimates = np.empty((n_poses, result.x.size))
    everything = np.arange(problem.measured.shape[0])
    for k, (left_out, step) in enumerate(zip(pose_sets, steps, strict=True)):
        if step is None:
            train = np.setdiff1d(everything, left_out)
            step = levenberg_marquardt(problem.subset(train), result.x, free,
                                       loss=cast(Loss, result.loss), max_iterations=30).x - result.x
        estimates[k] = result.x + step
    spread = estimates - estimates.mean(axis=0)
    std = np.sqrt((n_poses - 1) / n_poses * np.sum(spread**2, axis=0))
    std[~free] = np.nan
    return std
