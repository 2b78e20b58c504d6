"""stereo_target: the second pass that re-corrects the disk centres with fitted normals.

At acquisition the perspective bias of each disk centre is removed with the NOMINAL plate
normal (`StereoTargetMethod.normal_in_camera`), which the zero errors and the camera mount
error tilt by ~0.5 deg; that leaves a pose-dependent error that does not average out
(`hostpc.vision.centre_refinement`). When the fit dataset is built, a preliminary fit (the
dataset's default model) gives better normals; the centres are re-corrected with them and
re-triangulated, and the dataset keeps the refined `p` and `uv` (the covariances are those of
the measurement: the correction moves a centre by ~0.01 px, it does not change its noise).
A set too small for its own fit (the 3 verification poses) is re-corrected with the frames
of the last fit (`frames_only`): after a motor swap into an estimated camera mount the
nominal normal is 10 deg off, not 0.5.

The fitted model's normal at pose i is read off the model itself: the prediction of the
target shifted by eps along its base-frame normal, minus that of the target
(R_camera_base @ n_base * eps), so no frame algebra is repeated here.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from hostpc.dataset import Dataset
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

MIN_SAMPLES = 6
"""Fewer samples than this (the 4 poses of a short plan's verify set) are left as measured:
their own fit has too few measurements for the default model (3 per sample against its
12-15 parameters). A short fit plan (7-8 poses) IS refined: it was not while this was 20,
and that alone made its sigmas dishonest (MSE / sigma^2 about 2.1 for q3 and q5 over 40
simulated worlds; refined 1.04 and 1.30, docs/vision.md section 3.2)."""
_EPS = 1e-3
MAX_PRELIMINARY_CHI2_DOF = 100.0
"""A preliminary fit whose whitened residuals are more than 10x the stated noise (RMS) is
not trusted for the normals (`preliminary_model`)."""


def model_normals(problem: Problem, x: np.ndarray, target_normal: np.ndarray) -> np.ndarray:
    """(N, 3) the target plate normal in the camera frame at every sample, by the model of
    `problem` at parameters x (P,); target_normal: (3,) unit normal in the base frame."""
    dataset = problem.dataset
    target = np.asarray(dataset.frames["target"], float)
    shifted = dataclasses.replace(
        dataset, frames={**dict(dataset.frames), "target": target + _EPS * target_normal})
    moved = build_problem(shifted, list(problem.effect_names), plugins=problem.plugins)
    p0, _ = predict(problem, x, jacobian=False)
    p1, _ = predict(moved, x, jacobian=False)
    n = np.asarray(p1 - p0, float) / _EPS
    return np.asarray(n / np.linalg.norm(n, axis=1, keepdims=True), float)


def preliminary_model(dataset: Dataset) -> tuple[tuple[str, ...], np.ndarray] | None:
    """(effects, x) of the dataset's default model fitted to its samples, or None (the
    centres then stay as measured): fewer than MIN_SAMPLES samples, a fit that does not
    converge, or one whose residuals are grossly beyond the stated noise (chi2/dof above
    MAX_PRELIMINARY_CHI2_DOF: a gross outlier, e.g. 3 mm among 6 samples, bends every fitted
    normal by ~1 deg, worse than the nominal's 0.5 deg; a model missing a small effect,
    chi2/dof of a few, still gives normals far better than the nominal ones)."""
    from hostpc.fitting import solve

    if len(dataset.samples.q) < MIN_SAMPLES:
        return None
    problem = build_problem(dataset)
    result = solve(problem, cv_folds=0)
    if not result.converged or not result.chi2_dof <= MAX_PRELIMINARY_CHI2_DOF:
        return None
    return problem.effect_names, np.asarray(result.x, float)


def frames_only(dataset: Dataset, fitted: tuple[tuple[str, ...], np.ndarray]
                ) -> tuple[tuple[str, ...], np.ndarray]:
    """(effects, x) of `fitted` with every parameter but the frames' (tool, target, base)
    zeroed: what holds for any later set of this cell (a push moves the joint offsets into
    the controller's readings, never the camera mount or the target); `dataset` is one the
    model was fitted to (its layout)."""
    effects, x = fitted
    problem = build_problem(dataset, list(effects))
    kept = np.zeros_like(x)
    for name in problem.frame_names:
        span = problem.layout.effect_slices[name]
        kept[span] = x[span]
    return effects, kept


def refine_dataset(dataset: Dataset, rig: Any, target_radius: float,
                   target_normal: np.ndarray, fitted: tuple[tuple[str, ...], np.ndarray] | None
                   = None) -> tuple[Dataset, tuple[tuple[str, ...], np.ndarray] | None]:
    """(the dataset with re-corrected p and uv, the model used: (effects, x)).

    fitted: a model from an earlier refinement (effects, x) to use instead of fitting this
    dataset (which needs MIN_SAMPLES samples); returned unchanged when nothing can be done
    (no uv, too few samples and no model, a fit that does not converge)."""
    from hostpc.vision.centre_refinement import recorrect_centres

    samples = dataset.samples
    if samples.uv is None or len(samples.q) == 0 or "target" not in dataset.frames:
        return dataset, fitted
    target_normal = np.asarray(target_normal, float) / np.linalg.norm(target_normal)
    if fitted is None:
        fitted = preliminary_model(dataset)
        if fitted is None:
            return dataset, None
    effects, x = fitted
    problem = build_problem(dataset, list(effects))
    if problem.layout.size != x.size:
        return dataset, fitted
    nominal = model_normals(problem, np.zeros_like(x), target_normal)
    better = model_normals(problem, x, target_normal)
    uv_measured = np.asarray(samples.uv, float)
    uv, p = recorrect_centres(rig, target_radius, uv_measured, np.asarray(samples.p, float),
                              nominal, better)
    refined = dataclasses.replace(samples, uv=uv, p=p)
    return dataclasses.replace(dataset, samples=refined), fitted
