"""The stereo rig's shared error, as the stereo kinds' models answer it (stereo_target, and
dual_loop's head camera, whose datasets carry the same ``rig_uncertainty`` block).

The generic side (``hostpc.fitting.shared_errors``) asks a measurement model for its shared
error (``SharedError``) and knows nothing of rigs: how it moves each measured point (D =
dp/drig, from the samples' raw pixel centres ``uv`` and the block's rig,
``hostpc.vision.rig_uncertainty``), its covariance (the block's), and the per-sample pixel
floor the method added to each covariance. All read here from the dataset's block (the
functions taking ``block`` read its JSON), with the rig.
"""

from __future__ import annotations

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.kinds.stereo_target.rig_block import BLOCK
from hostpc.model.layout import Problem, SharedError


def rig_shared_error(problem: Problem) -> SharedError | None:
    """The rig's shared error of the problem's dataset (its ``rig_uncertainty`` block), or
    None: no block, a covariance that does not read or does not match the sensitivity, no
    uv, or values that are not finite."""
    block = problem.dataset.extra_fields.get(BLOCK)
    if not isinstance(block, dict):
        return None
    try:
        S = np.asarray(block.get("covariance"), dtype=float)
    except (TypeError, ValueError):
        return None
    D = rig_point_sensitivity(problem, block)
    if D is None or S.ndim != 2 or S.shape != (D.shape[2], D.shape[2]):
        return None
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(D))):
        return None
    return SharedError(D, S, rig_floor_covariance(problem, block))


def rig_point_sensitivity(problem: Problem, block: JsonObject) -> np.ndarray | None:
    """(N, 3, 24) dp/drig for the samples' uv, or None (no uv, not 3-D points, a rig that
    does not read); kept in the problem's shared values by the content of uv and the rig
    (candidate fits and folds of one dataset reuse it)."""
    uv = problem.dataset.samples.uv
    if uv is None or problem.measured.shape[1] != 3:
        return None
    import hashlib  # here: the most datasets hold no uv (its import is ~5 ms of start-up)

    uv = np.asarray(uv, float)
    digest = hashlib.sha1(np.ascontiguousarray(uv).tobytes())
    digest.update(repr(block.get("rig")).encode())
    sensitivity: np.ndarray | None = problem.shared.value(
        None, ("rig point sensitivity", digest.hexdigest()),
        lambda: _compute_sensitivity(block, uv))
    return sensitivity


def _compute_sensitivity(block: JsonObject, uv: np.ndarray) -> np.ndarray | None:
    from hostpc.vision.rig import rig_from_dict
    from hostpc.vision.rig_uncertainty import point_sensitivity

    try:
        rig = rig_from_dict(block.get("rig"), f"dataset {BLOCK}.rig")
    except InputError:
        return None
    return point_sensitivity(rig, uv)


def rig_floor_covariance(problem: Problem, block: JsonObject) -> np.ndarray | None:
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
