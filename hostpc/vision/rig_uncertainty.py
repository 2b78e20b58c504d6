"""The stereo rig's own uncertainty, and what it does to triangulated points.

A rig calibrated from ~20 chessboard views is not exact: its intrinsics and the left-right
transform err by a little, and that error is SHARED by every point measured with the rig (it
does not average out over poses). This module gives

- `rig_vector` / `rig_with_vector`: the 24 rig parameters as a vector, in this order
  (`RIG_PARAMETERS`): left fx fy cx cy (px), left k1 k2 p1 p2 k3, the same for the right
  camera, the left-to-right rotation as a rotation vector (rad, applied on the left:
  R' = Rodrigues(dr) @ R) and the translation T (m);
- `chessboard_rig_covariance`: the (24, 24) covariance of those parameters from the
  chessboard fit itself (Gauss-Newton at the solution, the per-view board poses
  marginalised, the corner noise estimated from the residuals);
- `point_sensitivity`: (N, 3, 24) derivative of each triangulated point (left camera frame,
  m) by the rig parameters, from the points' raw pixel centres (central differences of the
  same triangulation the measurement used).

A fit propagates `sensitivity @ covariance @ sensitivity^T` (correlated across samples) into
its parameter covariance: see `hostpc.fitting.shared_errors` and docs/vision.md section 3.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from hostpc.json_object import JsonObject
from hostpc.vision.rectification import Rectification, rectification_for
from hostpc.vision.rig import StereoRig
from hostpc.vision.triangulation import point_from_rectified

_INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
RIG_PARAMETERS: tuple[str, ...] = (
    tuple(f"left.{n}" for n in _INTRINSICS) + tuple(f"right.{n}" for n in _INTRINSICS)
    + ("stereo.rx", "stereo.ry", "stereo.rz", "stereo.tx", "stereo.ty", "stereo.tz")
)
N_RIG = len(RIG_PARAMETERS)
# central-difference steps per parameter (px, unitless distortion, rad, m)
_STEPS = np.array([0.05, 0.05, 0.05, 0.05, 1e-4, 1e-4, 1e-5, 1e-5, 1e-4] * 2
                  + [1e-5] * 3 + [1e-5] * 3)
_POSE_STEP = 1e-6


def _dist5(dist: np.ndarray) -> np.ndarray:
    out = np.zeros(5)
    d = np.ravel(dist)
    out[: min(5, d.size)] = d[:5]
    return out


def rig_vector(rig: StereoRig) -> np.ndarray:
    """(24,) the rig's parameters in `RIG_PARAMETERS` order (rotation part zero)."""
    parts: list[Any] = []
    for K, dist in ((rig.K_left, rig.dist_left), (rig.K_right, rig.dist_right)):
        parts.append([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
        parts.append(_dist5(dist))
    parts.append(np.zeros(3))
    parts.append(rig.T)
    return np.concatenate([np.asarray(p, float) for p in parts])


def rig_with_vector(rig: StereoRig, vector: np.ndarray) -> StereoRig:
    """`rig` with the parameters of `vector` (24,) (rotation part: a left-applied delta)."""
    v = np.asarray(vector, float)

    def camera(offset: int, K0: np.ndarray, dist0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K = np.array(K0, float)
        K[0, 0], K[1, 1], K[0, 2], K[1, 2] = v[offset: offset + 4]
        dist = np.array(np.ravel(dist0), float)
        dist[: min(5, dist.size)] = v[offset + 4: offset + 4 + min(5, dist.size)]
        return K, dist

    K1, d1 = camera(0, rig.K_left, rig.dist_left)
    K2, d2 = camera(9, rig.K_right, rig.dist_right)
    R = cv2.Rodrigues(v[18:21].reshape(3, 1))[0] @ rig.R
    return StereoRig(rig.image_size, K1, d1, K2, d2, R, v[21:24], rig.rms, rig.n_views)


def _view_residuals(theta: np.ndarray, R0: np.ndarray, pose: np.ndarray,
                    object_points: np.ndarray, left: np.ndarray, right: np.ndarray
                    ) -> np.ndarray:
    """Reprojection residuals (4M,) of one view: rig theta (24,) about the stereo rotation R0
    (3, 3), board pose (6,) in the left
    camera (rvec, tvec), corners (M, 3) m, observed left/right (M, 2) px."""
    K1 = np.array([[theta[0], 0, theta[2]], [0, theta[1], theta[3]], [0, 0, 1.0]])
    K2 = np.array([[theta[9], 0, theta[11]], [0, theta[10], theta[12]], [0, 0, 1.0]])
    R_view = cv2.Rodrigues(pose[:3].reshape(3, 1))[0]
    R_stereo = cv2.Rodrigues(theta[18:21].reshape(3, 1))[0] @ R0
    uv_left = cv2.projectPoints(object_points, pose[:3], pose[3:], K1, theta[4:9])[0]
    r_right = cv2.Rodrigues(R_stereo @ R_view)[0]
    t_right = R_stereo @ pose[3:] + theta[21:24]
    uv_right = cv2.projectPoints(object_points, r_right, t_right, K2, theta[13:18])[0]
    return np.concatenate([(uv_left.reshape(-1, 2) - left).ravel(),
                           (uv_right.reshape(-1, 2) - right).ravel()])



def chessboard_rig_covariance(
    rig: StereoRig,
    object_points: np.ndarray,
    left_corners: Sequence[np.ndarray],
    right_corners: Sequence[np.ndarray],
    rvecs: Sequence[np.ndarray],
    tvecs: Sequence[np.ndarray],
) -> tuple[np.ndarray, float]:
    """(24, 24) covariance of `rig_vector(rig)` from its chessboard fit, and the corner noise
    sigma (px) estimated from the residuals.

    object_points: (M, 3) board corners (m); left/right_corners: per view (M, 2) px;
    rvecs/tvecs: per view the board pose in the LEFT camera (the stereo fit's). The view
    poses are nuisance parameters, marginalised (Schur complement)."""
    R0 = np.asarray(rig.R, float)
    theta = rig_vector(rig)
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    poses = [np.concatenate([np.ravel(r), np.ravel(t)]).astype(float)
             for r, t in zip(rvecs, tvecs, strict=True)]
    left = [np.asarray(c, float).reshape(-1, 2) for c in left_corners]
    right = [np.asarray(c, float).reshape(-1, 2) for c in right_corners]
    A = np.zeros((N_RIG, N_RIG))
    schur = np.zeros((N_RIG, N_RIG))
    ssr, n_res = 0.0, 0
    for pose, lv, rv in zip(poses, left, right, strict=True):
        r0 = _view_residuals(theta, R0, pose, obj, lv, rv)
        ssr += float(r0 @ r0)
        n_res += r0.size
        J_rig = np.empty((r0.size, N_RIG))
        for k in range(N_RIG):
            step = np.zeros(N_RIG)
            step[k] = _STEPS[k]
            J_rig[:, k] = (_view_residuals(theta + step, R0, pose, obj, lv, rv)
                           - _view_residuals(theta - step, R0, pose, obj, lv, rv)) / (2 * _STEPS[k])
        J_pose = np.empty((r0.size, 6))
        for k in range(6):
            step = np.zeros(6)
            step[k] = _POSE_STEP
            J_pose[:, k] = (_view_residuals(theta, R0, pose + step, obj, lv, rv)
                            - _view_residuals(theta, R0, pose - step, obj, lv, rv)
                            ) / (2 * _POSE_STEP)
        A += J_rig.T @ J_rig
        B = J_rig.T @ J_pose
        schur += B @ np.linalg.solve(J_pose.T @ J_pose, B.T)
    n_params = N_RIG + 6 * len(poses)
    sigma2 = ssr / max(n_res - n_params, 1)
    information = A - schur
    covariance = sigma2 * np.linalg.pinv(0.5 * (information + information.T), rcond=1e-12)
    return 0.5 * (covariance + covariance.T), float(np.sqrt(sigma2))


def point_sensitivity(rig: StereoRig, uv: np.ndarray) -> np.ndarray:
    """(N, 3, 24) derivative of the triangulated points by the rig parameters.

    uv: (N, 2, 2) raw pixel centres [[u_l, v_l], [u_r, v_r]] the points were triangulated
    from (px). Rows with a non-finite uv get zeros."""
    uv = np.asarray(uv, float).reshape(-1, 2, 2)
    theta = rig_vector(rig)
    ok = np.all(np.isfinite(uv.reshape(len(uv), -1)), axis=1)
    out = np.zeros((len(uv), 3, N_RIG))
    rows = np.flatnonzero(ok)
    for k in range(N_RIG):
        step = np.zeros(N_RIG)
        step[k] = _STEPS[k]
        plus = _points(rectification_for(rig_with_vector(rig, theta + step)), uv[rows])
        minus = _points(rectification_for(rig_with_vector(rig, theta - step)), uv[rows])
        for n, i in enumerate(rows):
            out[i, :, k] = (plus[n] - minus[n]) / (2 * _STEPS[k])
    return out


def _points(rect: Rectification, uv: np.ndarray) -> list[np.ndarray]:
    """The points ``triangulate`` gives for the (N, 2, 2) raw centres ``uv``: every centre
    rectified in one call per camera (each point alone: the same values), without the
    derivative by uv (point_sensitivity needs only the points)."""
    left = rect.rectify_points(uv[:, 0], "left")
    right = rect.rectify_points(uv[:, 1], "right")
    return [point_from_rectified(rect, l, r)[0] for l, r in zip(left, right, strict=True)]


def uncertainty_document(rig: StereoRig, covariance: np.ndarray,
                         pixel_floor_px: float = 0.0) -> JsonObject:
    """The dataset's `rig_uncertainty` block: the rig, its parameter names and covariance,
    and the pixel floor the samples' covariances include (a weighting the fit's covariance
    takes back out: hostpc.fitting.shared_errors)."""
    document: JsonObject = {"rig": rig.to_dict(), "parameters": list(RIG_PARAMETERS),
                            "covariance": np.asarray(covariance, float).tolist()}
    if pixel_floor_px > 0:
        document["pixel_floor_px"] = float(pixel_floor_px)
    return document
