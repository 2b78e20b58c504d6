"""Sub-pixel detection of the dark disk of the target on its bright plate (S203).

Coarse stage (4x area-downsampled image): the plate is the bright region (above 60 % of the
way from the darkest to the brightest level), the disk a dark hole inside it
(cv2.findContours, two-level hierarchy). Exactly one hole of plausible size and elliptical
shape must exist; otherwise the image is rejected with a reason (not found, cut by the
image border, several candidates, implausible shape).

Fine stage (full resolution, a window around the hole): the plate level is the median of an
annulus around the disk, the pixel noise its scaled MAD. The centre is the intensity
centroid with weights `plate - I` inside a soft-edged circular window, recentred three
times. The intensity centroid equals the area centroid of the projected disk (the blur is
symmetric; no threshold, so no threshold bias); it is NOT the projection of the disk centre
(perspective bias, corrected in `measure.py`). Its covariance is the exact linear
propagation of white pixel noise:

    cov(c) = sigma_n^2 * sum(window^2 * (x - c)(x - c)^T) / M^2,   M = sum(weights).

Pixel coordinates: (0, 0) is the centre of the top-left pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

SCALE = 4
"""Downsampling factor of the coarse stage."""
MIN_CONTRAST = 40.0
"""Grey levels between the darkest and brightest coarse pixel below which nothing is there."""
MIN_RADIUS_PX = 4.0
"""Smallest disk radius (full-resolution px) that is accepted."""
MIN_AXIS_RATIO = 0.3
"""Minor / major axis of the disk image below which it is implausible (tilt > 72 deg)."""
FILL_TOLERANCE = 0.12
"""|area / (pi a b) - 1| above this: not an ellipse."""
QUANTISATION_SIGMA = 1.0 / math.sqrt(12.0)
"""Floor of the pixel noise estimate (grey levels): 8-bit rounding."""


@dataclass(frozen=True, eq=False)
class DiskBlob:
    """The dark disk found in one image.

    centroid: (2,) intensity centroid (px, raw image).
    centroid_cov: (2, 2) its covariance from pixel noise (px^2).
    moments: (2, 2) central second moments of the intensity weights (px^2; the blur adds
        an isotropic part).
    area: disk image area (px^2) = sum of weights / contrast.
    contrast: plate level minus disk level (grey levels).
    noise_sigma: pixel noise estimated on the plate (grey levels).
    plate_offset: (2,) area centroid of the whole plate minus `centroid` (px), or None if
        the plate touches the image border; plate_area: plate area incl. the disk (px^2).
    """

    centroid: np.ndarray
    centroid_cov: np.ndarray
    moments: np.ndarray
    area: float
    contrast: float
    noise_sigma: float
    plate_offset: np.ndarray | None
    plate_area: float | None


@dataclass(frozen=True)
class DetectionFailure:
    """Why no disk was returned (one line, without the image name)."""

    reason: str


def _ellipse_axes(moments: np.ndarray) -> tuple[float, float]:
    """Semi-axes (a >= b) of the uniform ellipse with central second moments (2, 2)."""
    lam = np.linalg.eigvalsh(moments)
    return 2.0 * math.sqrt(max(lam[1], 0.0)), 2.0 * math.sqrt(max(lam[0], 0.0))


def _contour_moments(contour: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(area, centroid (2,), central second moments (2, 2)) of a filled contour polygon in
    the coordinates of its points."""
    m = cv2.moments(contour)
    area = m["m00"]
    if area <= 0:
        return 0.0, np.zeros(2), np.zeros((2, 2))
    c = np.array([m["m10"] / area, m["m01"] / area])
    mu = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / area
    return area, c, mu


def _to_full(xy: np.ndarray) -> np.ndarray:
    """Coarse pixel coordinates -> full-resolution pixel coordinates."""
    return xy * SCALE + 0.5 * (SCALE - 1)


def _cut_by_border(small: np.ndarray, bright: np.ndarray, lo: float, hi: float) -> bool:
    """True if a compact dark blob next to the plate touches the image border (the disk
    partly outside the image)."""
    dark = (small < lo + 0.3 * (hi - lo)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=8)
    h, w = small.shape
    near_plate = cv2.dilate(bright, np.ones((5, 5), np.uint8)) > 0
    for k in range(1, n):
        x, y, bw, bh, area = stats[k]
        touches = x == 0 or y == 0 or x + bw == w or y + bh == h
        if not touches or area > 0.02 * h * w or area < 2:
            continue
        mask = labels == k
        pts = cv2.findNonZero(mask.astype(np.uint8))
        hull_area = cv2.contourArea(cv2.convexHull(pts)) + 1.0
        if area / hull_area < 0.8:
            continue
        ring = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~mask
        if ring.any() and np.mean(near_plate[ring]) > 0.5:
            return True
    return False


def detect_disk(image: np.ndarray, pixel_sigma: float | None = None) -> DiskBlob | DetectionFailure:
    """Find the target's dark disk in one raw grey image (H, W) uint8.

    pixel_sigma: if given, the centroid covariance is pixel_sigma^2 * I (px^2) instead of
    the noise propagation.
    """
    h, w = image.shape
    small = cv2.resize(image, (w // SCALE, h // SCALE), interpolation=cv2.INTER_AREA)
    lo, hi, _, _ = cv2.minMaxLoc(small)
    if hi - lo < MIN_CONTRAST:
        return DetectionFailure(
            f"no target (no contrast, {hi - lo:.0f} grey levels: blank or out of view)"
        )
    bright = (small > lo + 0.6 * (hi - lo)).astype(np.uint8)
    contours, hierarchy = cv2.findContours(bright, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    min_area = math.pi * (MIN_RADIUS_PX / SCALE) ** 2
    candidates = []
    if hierarchy is not None:
        for k, contour in enumerate(contours):
            parent = hierarchy[0][k][3]
            if parent < 0:
                continue  # an outer boundary, not a hole
            area, c, mu = _contour_moments(contour.astype(np.float32))
            if area < min_area:
                continue
            x, y, bw, bh = cv2.boundingRect(contour)
            if float(small[y : y + bh, x : x + bw].min()) > lo + 0.3 * (hi - lo):
                continue  # a hole in the plate that is not dark
            candidates.append((contour, parent, area, c, mu))
    if not candidates:
        if _cut_by_border(small, bright, lo, hi):
            return DetectionFailure("target cut by the image border (partly out of view)")
        return DetectionFailure("target not found (out of view or no dark disk on the plate)")
    if len(candidates) > 1:
        return DetectionFailure(
            f"ambiguous target: {len(candidates)} dark blobs on the plate"
        )
    contour, parent, area, c_small, mu_small = candidates[0]
    a_s, b_s = _ellipse_axes(mu_small)
    if b_s < MIN_AXIS_RATIO * a_s:
        return DetectionFailure(f"implausible target shape (axis ratio {b_s / a_s:.2f})")
    # the polygon through boundary pixel centres is ~half a pixel inside the region
    fill = area / (math.pi * (a_s + 0.5) * (b_s + 0.5))
    if a_s > 3 and abs(fill - 1.0) > FILL_TOLERANCE and abs(area / (math.pi * a_s * b_s) - 1.0
                                                          ) > FILL_TOLERANCE:
        return DetectionFailure(f"implausible target shape (not an ellipse, fill {fill:.2f})")
    blob = _refine(image, _to_full(c_small), SCALE * (a_s + 0.5), pixel_sigma)
    if isinstance(blob, DetectionFailure):
        return blob
    # the whole plate (outer contour of the hole's parent), if it is inside the image
    plate = contours[parent]
    x, y, bw, bh = cv2.boundingRect(plate)
    plate_offset = None
    plate_area = None
    if x > 0 and y > 0 and x + bw < small.shape[1] and y + bh < small.shape[0]:
        p_area, p_c, _ = _contour_moments(plate.astype(np.float32))
        if p_area > area:
            plate_offset = _to_full(p_c) - blob.centroid
            plate_area = p_area * SCALE * SCALE
    return DiskBlob(
        centroid=blob.centroid,
        centroid_cov=blob.centroid_cov,
        moments=blob.moments,
        area=blob.area,
        contrast=blob.contrast,
        noise_sigma=blob.noise_sigma,
        plate_offset=plate_offset,
        plate_area=plate_area,
    )


def _refine(
    image: np.ndarray, centre: np.ndarray, radius: float, pixel_sigma: float | None
) -> DiskBlob | DetectionFailure:
    """Intensity centroid of the dark disk near `centre` (px) of major semi-axis ~`radius`."""
    h, w = image.shape
    r_win = 1.35 * radius + 4.0  # window radius: the disk plus the blurred edge
    r_out = r_win + 4.0  # the plate annulus r_win..r_out gives the plate level and noise
    half = int(math.ceil(r_out)) + 2
    cx, cy = int(round(centre[0])), int(round(centre[1]))
    x0, x1, y0, y1 = cx - half, cx + half + 1, cy - half, cy + half + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return DetectionFailure("target cut by the image border (too close to the edge)")
    patch = image[y0:y1, x0:x1].astype(np.float64)
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    xs -= centre[0]  # coordinates relative to the coarse centre (better conditioned)
    ys -= centre[1]
    rho0 = np.hypot(xs, ys)
    annulus = patch[(rho0 >= r_win + 1.0) & (rho0 <= r_out)]
    # robust level and noise of the (integer-valued) plate: median, then a clipped mean/std
    median = float(np.median(annulus))
    spread = max(1.4826 * float(np.median(np.abs(annulus - median))), 1.0)
    inliers = annulus[np.abs(annulus - median) < 4.0 * spread]
    # the MAD of integer grey levels is coarse (1.48 for noise 2.0, so the first clip is at
    # 2.5 sigma and its std 5 % low): clip again at 5 of that std, which keeps the outliers
    # out and the noise's tails in (bench/bench_centre_error.py)
    inliers = annulus[np.abs(annulus - float(inliers.mean())) < 5.0 * max(
        float(inliers.std()), QUANTISATION_SIGMA)]
    plate = float(inliers.mean())
    noise = max(float(inliers.std()), QUANTISATION_SIGMA)
    weights_raw = plate - patch
    c = np.zeros(2)
    for _ in range(2):  # the coarse centre is within ~0.5 px: two recentrings converge
        rho = np.hypot(xs - c[0], ys - c[1])
        window = np.clip(r_win - rho + 0.5, 0.0, 1.0)
        weights = weights_raw * window
        mass = float(weights.sum())
        if mass <= 0:
            return DetectionFailure("target not found (no dark disk inside the plate)")
        c = np.array([float((weights * xs).sum()), float((weights * ys).sum())]) / mass
    dx, dy = xs - c[0], ys - c[1]
    moments = np.array(
        [
            [float((weights * dx * dx).sum()), float((weights * dx * dy).sum())],
            [float((weights * dx * dy).sum()), float((weights * dy * dy).sum())],
        ]
    ) / mass
    a, b = _ellipse_axes(moments)
    inner = patch[np.hypot(dx, dy) <= max(1.0, 0.4 * b)]
    contrast = plate - float(np.median(inner))
    if contrast < MIN_CONTRAST:
        return DetectionFailure(f"implausible target (contrast {contrast:.0f} grey levels)")
    if pixel_sigma is None:
        w2 = window * window
        cov = noise**2 * np.array(
            [
                [float((w2 * dx * dx).sum()), float((w2 * dx * dy).sum())],
                [float((w2 * dx * dy).sum()), float((w2 * dy * dy).sum())],
            ]
        ) / mass**2
    else:
        cov = float(pixel_sigma) ** 2 * np.eye(2)
    return DiskBlob(
        centroid=c + centre,
        centroid_cov=cov,
        moments=moments,
        area=mass / contrast,
        contrast=contrast,
        noise_sigma=noise,
        plate_offset=None,
        plate_area=None,
    )
