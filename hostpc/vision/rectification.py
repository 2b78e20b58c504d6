"""Stereo rectification of a rig: matrices, point rectification, cached image maps.

`rectification_for(rig)` runs cv2.stereoRectify once per rig (kept on the rig object,
``rig.rectification``: no module cache). Rectified frame: the left camera frame rotated
by `R1` (x_rect = R1 @ x_left), both rectified cameras share the focal length `f` and the
row `cy`; the right camera sits at +baseline along the rectified x axis, so a point at
depth Z has disparity `x_left - x_right = f * baseline / Z` (with CALIB_ZERO_DISPARITY, cx
is shared too).
The full-image remap tables (only the SGBM path needs them) are built on first use.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from hostpc.vision.rig import StereoRig

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)


@dataclass(eq=False)
class Rectification:
    """Rectification of one rig (OpenCV stereoRectify, alpha=0, zero disparity at infinity).

    R1, R2: (3, 3) rotations left/right camera -> rectified frames.
    P1, P2: (3, 4) projection matrices of the rectified cameras (px).
    Q: (4, 4) disparity-to-depth matrix.
    """

    rig: StereoRig
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    _maps: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = field(
        default=None, repr=False
    )

    @property
    def focal(self) -> float:
        """Focal length of the rectified cameras (px)."""
        return float(self.P1[0, 0])

    @property
    def baseline(self) -> float:
        """Baseline along the rectified x axis (m, positive)."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    @property
    def cx_left(self) -> float:
        return float(self.P1[0, 2])

    @property
    def cx_right(self) -> float:
        return float(self.P2[0, 2])

    @property
    def cy(self) -> float:
        return float(self.P1[1, 2])

    def rectify_points(self, uv: np.ndarray, side: str) -> np.ndarray:
        """(N, 2) raw (distorted) pixels of camera `side` ("left"|"right") -> (N, 2)
        rectified pixels (undistorted iteratively to 1e-12)."""
        rig = self.rig
        if side == "left":
            K, dist, R, P = rig.K_left, rig.dist_left, self.R1, self.P1
        else:
            K, dist, R, P = rig.K_right, rig.dist_right, self.R2, self.P2
        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        out = cv2.undistortPointsIter(pts, K, dist, R, P, _UNDISTORT_CRITERIA)
        return np.asarray(out, dtype=float).reshape(-1, 2)

    def maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(map1_left, map2_left, map1_right, map2_right) remap tables (fixed point, built
        once)."""
        if self._maps is None:
            rig = self.rig
            left = cv2.initUndistortRectifyMap(
                rig.K_left, rig.dist_left, self.R1, self.P1, rig.image_size, cv2.CV_16SC2
            )
            right = cv2.initUndistortRectifyMap(
                rig.K_right, rig.dist_right, self.R2, self.P2, rig.image_size, cv2.CV_16SC2
            )
            self._maps = (left[0], left[1], right[0], right[1])
        return self._maps

    def rectify_images(
        self, left: np.ndarray, right: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rectified (H, W) copies of a raw image pair (bilinear remap)."""
        m1l, m2l, m1r, m2r = self.maps()
        return (
            cv2.remap(left, m1l, m2l, cv2.INTER_LINEAR),
            cv2.remap(right, m1r, m2r, cv2.INTER_LINEAR),
        )


def rectification_for(rig: StereoRig) -> Rectification:
    """The Rectification of `rig`, computed once per rig object (``rig.rectification``)."""
    if isinstance(rig.rectification, Rectification):
        return rig.rectification
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
        rig.K_left, rig.dist_left, rig.K_right, rig.dist_right, rig.image_size,
        rig.R, rig.T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0,
    )
    rect = Rectification(rig, R1, R2, P1, P2, Q)
    object.__setattr__(rig, "rectification", rect)  # frozen: the one value it derives
    return rect
