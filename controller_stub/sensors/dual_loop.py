"""The humanoid head's stereo camera as the dual_loop kind's sensor: it returns each visible
target already triangulated, with its covariance, instead of images.

The camera is a rectified pinhole pair (focal ``f`` px, principal point at the image centre,
right camera at ``+baseline`` along the left camera's x). A true point (left camera frame) is
projected into both images, each centroid coordinate gets Gaussian noise ``pixel_sigma``,
and the point is triangulated with the controller's own (erring) calibration of the pair;
its covariance is the first-order propagation of the pixel noise. Never imports hostpc.
Lengths metres, pixels px.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["CALIBRATION_PARAMETERS", "RIG_VECTOR", "StereoTriangulator"]

CALIBRATION_PARAMETERS = ("left.fx", "left.fy", "left.cx", "left.cy",
                          "right.fx", "right.fy", "right.cx", "right.cy", "baseline")
# the rig-file parameter vector (24: per camera fx fy cx cy k1 k2 p1 p2 k3, then the stereo
# rotation vector and translation T; the right camera at +baseline means T = (-b, 0, 0))
RIG_VECTOR = tuple(f"{c}.{n}" for c in ("left", "right")
                   for n in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")) + (
    "stereo.rx", "stereo.ry", "stereo.rz", "stereo.tx", "stereo.ty", "stereo.tz")


class StereoTriangulator:
    """Rectified stereo pair: projection, pixel noise, triangulation and its covariance.

    focal: px; baseline: m; width, height: px; pixel_sigma: px per image coordinate.
    calibration_error: (9,) what the controller's own calibration of the pair errs by, in
    CALIBRATION_PARAMETERS order (px, m); calibration_sigma: (9,) the standard deviations its
    calibration reports. Projection uses the true pair, triangulation the calibrated one
    (per camera ``n = ((u - cx) / fx, (v - cy) / fy)``, ``z = b / (n_Lx - n_Rx)``,
    ``x = n_Lx z``, ``y = (n_Ly + n_Ry) / 2 z``); the stereo rotation is exact."""

    def __init__(self, focal: float, baseline: float, width: int, height: int,
                 pixel_sigma: float, calibration_error: np.ndarray | None = None,
                 calibration_sigma: np.ndarray | None = None) -> None:
        self.f = float(focal)
        self.b = float(baseline)
        self.width = int(width)
        self.height = int(height)
        self.cx = (width - 1) / 2.0
        self.cy = (height - 1) / 2.0
        self.sigma = float(pixel_sigma)
        true = np.array([self.f, self.f, self.cx, self.cy] * 2 + [self.b])
        self.calibration_error = (np.zeros(9) if calibration_error is None
                                  else np.asarray(calibration_error, dtype=float))
        self.calibrated = true + self.calibration_error
        self.calibration_sigma = (np.zeros(9) if calibration_sigma is None
                                  else np.asarray(calibration_sigma, dtype=float))

    def project(self, p: np.ndarray) -> np.ndarray:
        """(4,) pixels [uL, vL, uR, vR] of a point p (3,) in the left camera frame."""
        x, y, z = p
        return np.array([self.f * x / z + self.cx, self.f * y / z + self.cy,
                         self.f * (x - self.b) / z + self.cx, self.f * y / z + self.cy])

    def visible(self, p: np.ndarray) -> bool:
        if p[2] <= 0.05:
            return False
        uv = self.project(p)
        inside_u = (0.0 <= uv[[0, 2]]) & (uv[[0, 2]] <= self.width - 1)
        inside_v = (0.0 <= uv[[1, 3]]) & (uv[[1, 3]] <= self.height - 1)
        return bool(np.all(inside_u) and np.all(inside_v))

    def triangulate(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point (3,) m from pixels (4,) with the calibrated pair, and the Jacobian
        d point / d pixels (3, 4)."""
        uL, vL, uR, vR = uv
        fxl, fyl, cxl, cyl, fxr, fyr, cxr, cyr, b = self.calibrated
        nxl, nyl = (uL - cxl) / fxl, (vL - cyl) / fyl
        nxr, nyr = (uR - cxr) / fxr, (vR - cyr) / fyr
        disparity = nxl - nxr
        z = b / disparity
        ny = 0.5 * (nyl + nyr)
        dn_dx = np.array([1.0 / fxl, 0.0, -1.0 / fxr, 0.0])  # d disparity / d pixels
        dz = -z / disparity * dn_dx
        dx = nxl * dz + np.array([z / fxl, 0.0, 0.0, 0.0])
        dy = ny * dz + np.array([0.0, 0.5 / fyl, 0.0, 0.5 / fyr]) * z
        return np.array([nxl * z, ny * z, z]), np.vstack([dx, dy, dz])

    def measure(self, p_true: np.ndarray, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noisy triangulated point (3,), its covariance (3, 3) (m, m^2) and the noisy
        pixels [[uL, vL], [uR, vR]] (2, 2) it was triangulated from."""
        uv = self.project(p_true) + rng.normal(0.0, self.sigma, 4)
        p, J = self.triangulate(uv)
        cov = (self.sigma**2) * J @ J.T
        return p, cov, uv.reshape(2, 2)

    def calibration(self) -> dict[str, Any]:
        """The controller's calibration of the pair as a rig document (the host's rig-file
        format: zerocal-stereo-rig, version 1) with its (24, 24) covariance in RIG_VECTOR
        order (zero for distortion and the stereo rotation, which this model has exact)."""
        fxl, fyl, cxl, cyl, fxr, fyr, cxr, cyr, b = (float(v) for v in self.calibrated)
        rig = {"format": "zerocal-stereo-rig", "version": 1,
               "image_size": [self.width, self.height],
               "K_left": [[fxl, 0.0, cxl], [0.0, fyl, cyl], [0.0, 0.0, 1.0]],
               "dist_left": [0.0] * 5,
               "K_right": [[fxr, 0.0, cxr], [0.0, fyr, cyr], [0.0, 0.0, 1.0]],
               "dist_right": [0.0] * 5,
               "R": np.eye(3).tolist(), "T": [-b, 0.0, 0.0], "rms": 0.0, "n_views": 0}
        index = [RIG_VECTOR.index(n) for n in CALIBRATION_PARAMETERS[:8]]
        index.append(RIG_VECTOR.index("stereo.tx"))  # T_x = -b: same variance
        covariance = np.zeros((len(RIG_VECTOR), len(RIG_VECTOR)))
        covariance[index, index] = self.calibration_sigma**2
        return {"rig": rig, "parameters": list(RIG_VECTOR), "covariance": covariance.tolist()}
