"""The patent's depth path (S204 variant): a semi-global block-matching disparity map
(cv2.StereoSGBM) of the rectified pair, sampled at the target centre.

Both raw images are rectified with the rig's cached remap tables; SGBM runs on the whole
rectified pair with a 64-pixel disparity search centred on the disparity of the centre path
(so the search range never misses the target; a blind search over the working volume would
be several times slower still). The target has texture only at the disk's edge: inside the
disk the map is smoothness-driven (biased by up to ~1 px) and on the plate it is noise. So
the map is sampled as the median of the valid disparities in a band of 0.6-1.4 disk radii
around the rectified centre. Its standard deviation is the median's standard error (one
independent value per matching block) combined with `SGBM_SIGMA_FLOOR_PX`, the systematic
error SGBM shows there on the simulator's images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hostpc.vision.rectification import Rectification

SGBM_SIGMA_FLOOR_PX = 0.4
"""Floor of the disparity standard deviation of the SGBM path (px): the systematic error
of SGBM at the edge of a textureless disk measured on the simulator (docs/vision.md)."""
NUM_DISPARITIES = 64
BLOCK_SIZE = 9
BAND = (0.6, 1.4)
"""The disparities are sampled in this band of disk radii around the centre: the disk's
edge, the only texture of the target (inside the disk and on the plate the map is
smoothness-driven or noise)."""


@dataclass(frozen=True)
class SampledDisparity:
    """disparity at the centre (px, rectified), its standard deviation (px), and the number
    of map pixels that entered the fit."""

    disparity: float
    sigma: float
    n_pixels: int


def sgbm_disparity_at(
    rect: Rectification,
    left: np.ndarray,
    right: np.ndarray,
    centre_rectified: np.ndarray,
    disparity_guess: float,
    radius_px: float,
) -> SampledDisparity | str:
    """SGBM disparity at `centre_rectified` (2,) (rectified left pixel).

    left, right: raw (H, W) uint8 images; disparity_guess: px, sets the search range;
    radius_px: disk radius in the image (sets the sampling window).
    Returns the sampled disparity, or a one-line reason string if the map has too few
    valid pixels there.
    """
    left_rect, right_rect = rect.rectify_images(left, right)
    min_disparity = int(math.floor(disparity_guess)) - NUM_DISPARITIES // 2
    matcher = cv2.StereoSGBM_create(  # type: ignore[attr-defined]
        minDisparity=min_disparity,
        numDisparities=NUM_DISPARITIES,
        blockSize=BLOCK_SIZE,
        P1=8 * BLOCK_SIZE**2,
        P2=32 * BLOCK_SIZE**2,
        disp12MaxDiff=1,
        uniquenessRatio=5,
        speckleWindowSize=0,
        mode=cv2.STEREO_SGBM_MODE_SGBM,
    )
    disp = matcher.compute(left_rect, right_rect).astype(np.float64) / 16.0
    xc, yc = float(centre_rectified[0]), float(centre_rectified[1])
    half = int(math.ceil(BAND[1] * radius_px)) + 1
    h, w = disp.shape
    x0, x1 = max(0, int(xc) - half), min(w, int(xc) + half + 1)
    y0, y1 = max(0, int(yc) - half), min(h, int(yc) + half + 1)
    window = disp[y0:y1, x0:x1]
    ys, xs = np.mgrid[y0:y1, x0:x1]
    rho = np.hypot(xs - xc, ys - yc)
    band = (rho >= BAND[0] * radius_px) & (rho <= BAND[1] * radius_px)
    values = window[band & (window >= min_disparity)]
    if values.size < max(20, band.sum() // 4):
        return f"SGBM disparity map has too few valid pixels at the target ({values.size})"
    median = float(np.median(values))
    mad = float(np.median(np.abs(values - median)))
    # the median's standard error with the matching blocks' correlation (one independent
    # value per block area), plus the systematic floor
    n_independent = max(values.size / BLOCK_SIZE**2, 1.0)
    sigma_stat = 1.2533 * 1.4826 * mad / math.sqrt(n_independent)
    return SampledDisparity(
        disparity=median, sigma=math.hypot(sigma_stat, SGBM_SIGMA_FLOOR_PX), n_pixels=values.size
    )
