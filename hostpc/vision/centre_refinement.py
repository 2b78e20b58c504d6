"""Re-correcting the perspective bias of the disk centres with a better plate normal.

The image of a tilted disk is not centred on the projection of the disk's centre: the
measurement subtracts this perspective bias, computed for the plate normal it is given
(`TargetMeasurer.measure(normal_hint=...)`). During acquisition the only normal on hand is
the NOMINAL one (nominal joint zeros and camera mount), off by the very errors being
calibrated (~0.5 deg). The bias changes by about f r^2 / z^2 per radian of tilt (~1 px/rad
for a 10 mm disk at 0.4 m), so the nominal normal leaves an error of ~0.005-0.01 px that is
a smooth function of the pose: it does not average out over poses, and it made the fitted
joint offsets err by about twice their reported sigma against the simulator (docs/vision.md
section 3).

`recorrect_centres` moves each centre from the bias of one normal to that of another and
re-triangulates: `uv_new = uv + bias(p, n_used) - bias(p, n_better)`. The stereo_target method
calls it after a preliminary fit, with the normals of the fitted model (a second pass makes
no further difference: the bias's sensitivity times the fitted normal's error is ~1e-4 px).
"""

from __future__ import annotations

import numpy as np

from hostpc.vision.rectification import rectification_for
from hostpc.vision.rig import StereoRig
from hostpc.vision.triangulation import CameraModel, disk_image_moments, triangulate


def recorrect_centres(rig: StereoRig, target_radius: float, uv: np.ndarray, p: np.ndarray,
                      normals_used: np.ndarray, normals_better: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(uv (N, 2, 2) px, p (N, 3) m) with the bias of `normals_used` replaced by that of
    `normals_better` ((N, 3) unit normals in the left camera frame, towards the cameras).

    uv: raw-image disk centres [[u_l, v_l], [u_r, v_r]] as measured; p: their triangulated
    points (left camera frame, m). Rows with non-finite input are returned unchanged."""
    uv = np.asarray(uv, float).reshape(-1, 2, 2)
    p = np.asarray(p, float).reshape(-1, 3)
    n_used = _unit(normals_used)
    n_better = _unit(normals_better)
    ok = np.all(np.isfinite(uv.reshape(len(uv), -1)), axis=1) & np.all(np.isfinite(p), axis=1)
    ok &= np.all(np.isfinite(n_used), axis=1) & np.all(np.isfinite(n_better), axis=1)
    uv_new, p_new = uv.copy(), p.copy()
    if not np.any(ok):
        return uv_new, p_new
    cameras = (CameraModel(rig.K_left, rig.dist_left, np.eye(3), np.zeros(3)),
               CameraModel(rig.K_right, rig.dist_right, rig.R, rig.T))
    index = np.flatnonzero(ok)
    centres = np.concatenate([p[index], p[index]])
    normals = np.concatenate([n_used[index], n_better[index]])
    images = disk_image_moments(cameras, centres, normals, float(target_radius))
    k = index.size
    rect = rectification_for(rig)
    for cam in range(2):
        bias = np.asarray(images[cam].bias, float)  # (2k, 2)
        uv_new[index, cam] += bias[:k] - bias[k:]
    for i in index:
        p_new[i] = triangulate(rect, uv_new[i, 0], uv_new[i, 1]).p
    return uv_new, p_new


def _unit(vectors: np.ndarray) -> np.ndarray:
    v = np.asarray(vectors, float).reshape(-1, 3)
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / norm
