"""Stereo rig calibration from chessboard image pairs (S201).

Corners are found on a half-resolution copy (fast) and refined to sub-pixel on the full image
(cv2.cornerSubPix). Each camera is calibrated alone (cv2.calibrateCamera), then both jointly
with the extrinsics (cv2.stereoCalibrateExtended, intrinsics refined from that guess).
A calibration that should not be trusted is flagged in `RigCalibration.warnings`, never
silently accepted: RMS above 0.5 px, fewer than 8 usable views, a board that covered too
little of the image, views that are all nearly fronto-parallel, or an outlier view.

Image pairs on disk (`load_image_pairs`): a folder of `left_<id>.<ext>` and
`right_<id>.<ext>` files (ext png, bmp, tif, tiff, jpg, jpeg), paired by `<id>` (e.g.
`left_00.png` + `right_00.png`), in the natural order of `<id>`.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hostpc.errors import InputError
from hostpc.vision.rig import StereoRig
from hostpc.vision.rig_planning import MIN_COVERAGE
from hostpc.vision.rig_planning import coverage as coverage_of
from hostpc.vision.rig_uncertainty import chessboard_rig_covariance

MAX_RMS_PX = 0.5
"""A calibration with a larger reprojection RMS (px) is flagged as poor."""
MIN_VIEWS = 8
"""Fewer usable views than this is flagged as poor."""
MIN_TILT_SPREAD_DEG = 10.0
"""Largest board tilt among the views below this: focal length poorly determined."""
OUTLIER_VIEW_RMS_PX = 1.0
"""A single view with a larger RMS is flagged."""
ABSOLUTE_MIN_VIEWS = 3
"""Below this no calibration is attempted (InputError)."""

_IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg")


@dataclass(frozen=True)
class ChessboardSpec:
    """Chessboard geometry: `cols` x `rows` INNER corners, `square` side (m).

    Object points are (i * square, j * square, 0), i along a row (cols), row-major.
    """

    cols: int
    rows: int
    square: float

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise ValueError(f"board: need at least 3x3 inner corners, got {self.cols}x{self.rows}")
        if not (math.isfinite(self.square) and self.square > 0.0):
            raise ValueError(f"board square: expected a positive size in m, got {self.square}")

    def object_points(self) -> np.ndarray:
        """(rows*cols, 3) float32 corner positions in the board frame (m)."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        pts = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) * self.square
        return pts.astype(np.float32)


@dataclass(frozen=True)
class RigCalibration:
    """Result of `calibrate_rig`.

    rig: the calibrated StereoRig; rms: stereo reprojection RMS (px);
    per_view_rms: RMS (px) of each used view (mean of left and right);
    used_views: indices into the input pairs that entered the fit;
    skipped_views: (index, reason) of the pairs that did not;
    corner_sigma_px: the corner noise the fit's residuals show (px); the rig's parameter
    covariance from this fit is `rig.covariance` (hostpc.vision.rig_uncertainty);
    warnings: why the calibration should not be trusted (empty if fine).
    """

    rig: StereoRig
    rms: float
    per_view_rms: list[float]
    used_views: list[int]
    warnings: tuple[str, ...]
    skipped_views: tuple[tuple[int, str], ...] = ()
    corner_sigma_px: float | None = None

    @property
    def ok(self) -> bool:
        """True if no warning was raised."""
        return not self.warnings


def as_gray(image: np.ndarray, what: str) -> np.ndarray:
    """A 2-D uint8 view of `image` (colour converted); InputError for anything else."""
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        image = cv2.cvtColor(image, code)
    if image.ndim != 2:
        raise InputError(f"{what}: expected a 2-D grey image, got shape {image.shape}")
    if image.dtype != np.uint8:
        if image.dtype == np.uint16:
            image = np.right_shift(image, 8).astype(np.uint8)
        else:
            raise InputError(f"{what}: expected uint8 pixels, got {image.dtype}")
    return np.ascontiguousarray(image)


def find_chessboard(image: np.ndarray, board: ChessboardSpec) -> np.ndarray | None:
    """Inner corners of `board` in a grey image: (rows*cols, 2) float32 px, or None.

    Detected on a half-resolution copy (images wider than 1000 px), refined with
    cornerSubPix on the full image; row-major in OpenCV's order.
    """
    pattern = (board.cols, board.rows)
    flags = (
        cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    )
    h, w = image.shape
    scale = 2 if w > 1000 else 1
    small = (
        cv2.resize(image, (w // scale, h // scale), interpolation=cv2.INTER_AREA)
        if scale > 1
        else image
    )
    found, corners = cv2.findChessboardCorners(small, pattern, flags=flags)
    if not found or corners is None:
        return None
    # small pixel j covers full pixels scale*j .. scale*j + scale - 1
    corners = (corners.astype(np.float64) * scale + 0.5 * (scale - 1)).astype(np.float32)
    # refinement window: a third of the smallest corner spacing, 3..11 px half size
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(
        float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
        float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))),
    )
    half = int(np.clip(spacing / 3.0, 3, 11))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(image, corners, (half, half), (-1, -1), criteria)
    return refined.reshape(-1, 2)


@contextmanager
def _opencv_single_thread() -> Iterator[None]:
    """OpenCV on one thread while inside: its calibration sums are split across threads in a
    varying order, which changed the rig by up to 3e-9 relative between runs of the same
    views (a rig file, its fingerprint and every fit downstream then differed)."""
    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


def calibrate_rig(
    pairs: list[tuple[np.ndarray, np.ndarray]], board: ChessboardSpec,
    corners: list[tuple[np.ndarray | None, np.ndarray | None]] | None = None,
) -> RigCalibration:
    """Calibrate a stereo rig from chessboard image pairs.

    pairs: (left, right) grey images (H, W) uint8 of the same board pose, all the same size.
    board: the chessboard (inner corners, square in m). corners: per pair, the corners
    `find_chessboard` found in (left, right) (the caller detected them already, e.g. to
    plan the views), so they are not detected twice; None: detected here.
    Returns a RigCalibration whose `warnings` say whether it can be trusted. Raises
    InputError for unusable input: no pairs, mismatched image sizes, or fewer than 3 pairs
    in which the board is found in both images.
    """
    if not pairs:
        raise InputError("stereo calibration: no image pairs given")
    size: tuple[int, int] | None = None
    left_pts: list[np.ndarray] = []
    right_pts: list[np.ndarray] = []
    used: list[int] = []
    skipped: list[tuple[int, str]] = []
    for k, pair in enumerate(pairs):
        if len(pair) != 2:
            raise InputError(f"pair {k}: expected (left, right) images")
        left = as_gray(pair[0], f"pair {k} left image")
        right = as_gray(pair[1], f"pair {k} right image")
        if left.shape != right.shape:
            raise InputError(f"pair {k}: left {left.shape} and right {right.shape} differ in size")
        this_size = (left.shape[1], left.shape[0])
        if size is None:
            size = this_size
        elif this_size != size:
            raise InputError(f"pair {k}: image size {this_size} differs from {size} of pair 0")
        if corners is not None and k < len(corners):
            corners_left, corners_right = corners[k]
        else:
            corners_left = find_chessboard(left, board)
            corners_right = find_chessboard(right, board)
        if corners_left is None or corners_right is None:
            side = "both images" if corners_left is None and corners_right is None else (
                "the left image" if corners_left is None else "the right image"
            )
            skipped.append((k, f"chessboard not found in {side}"))
            continue
        # the same corner order in both images (the cameras are nearly parallel)
        if np.dot(corners_left[-1] - corners_left[0], corners_right[-1] - corners_right[0]) < 0:
            corners_right = corners_right[::-1].copy()
        left_pts.append(corners_left.reshape(-1, 1, 2))
        right_pts.append(corners_right.reshape(-1, 1, 2))
        used.append(k)
    assert size is not None
    if len(used) < ABSOLUTE_MIN_VIEWS:
        raise InputError(
            f"stereo calibration: the chessboard {board.cols}x{board.rows} was found in both "
            f"images of only {len(used)} of {len(pairs)} pairs (need at least "
            f"{ABSOLUTE_MIN_VIEWS}, better {MIN_VIEWS}+)"
        )
    obj = [board.object_points().reshape(-1, 1, 3)] * len(used)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-7)
    with _opencv_single_thread():  # the same views give the same rig, run after run
        _, K1, d1, rvecs, _ = cv2.calibrateCamera(obj, left_pts, size, None, None)
        _, K2, d2, _, _ = cv2.calibrateCamera(obj, right_pts, size, None, None)
        out = cv2.stereoCalibrateExtended(
            obj, left_pts, right_pts, K1, d1, K2, d2, size, np.eye(3), np.zeros((3, 1)),
            flags=cv2.CALIB_USE_INTRINSIC_GUESS, criteria=criteria,
        )
    rms, K1, d1, K2, d2, R, T = out[:7]
    per_view = out[-1]  # (n_views, 2) RMS of the left and right image of each view
    per_view_rms = [float(v) for v in np.mean(np.asarray(per_view).reshape(-1, 2), axis=1)]
    rig = StereoRig(size, K1, d1.ravel(), K2, d2.ravel(), R, T.ravel(), float(rms), len(used))
    covariance, corner_sigma = chessboard_rig_covariance(
        rig, board.object_points(), left_pts, right_pts, out[9], out[10])
    rig = dataclasses.replace(rig, covariance=covariance)

    warnings: list[str] = []
    if rms > MAX_RMS_PX:
        warnings.append(f"reprojection RMS {rms:.3f} px exceeds {MAX_RMS_PX} px")
    if len(used) < MIN_VIEWS:
        warnings.append(f"only {len(used)} usable views (need at least {MIN_VIEWS})")
    for name, pts in (("left", left_pts), ("right", right_pts)):
        coverage = coverage_of([p.reshape(-1, 2) for p in pts], size)
        if coverage < MIN_COVERAGE:
            warnings.append(
                f"poor coverage: the board covered {100 * coverage:.0f}% of the {name} image "
                f"(need {100 * MIN_COVERAGE:.0f}%)"
            )
    tilts = [
        math.degrees(math.acos(min(1.0, abs(cv2.Rodrigues(r)[0][2, 2])))) for r in rvecs
    ]
    if max(tilts) < MIN_TILT_SPREAD_DEG:
        warnings.append(
            f"all views nearly fronto-parallel (max board tilt {max(tilts):.1f} deg < "
            f"{MIN_TILT_SPREAD_DEG:.0f} deg): focal length poorly determined"
        )
    for k, view_rms in zip(used, per_view_rms, strict=True):
        if view_rms > OUTLIER_VIEW_RMS_PX:
            warnings.append(f"view {k}: RMS {view_rms:.2f} px (outlier, > {OUTLIER_VIEW_RMS_PX})")
    return RigCalibration(
        rig=rig,
        rms=float(rms),
        per_view_rms=per_view_rms,
        used_views=used,
        warnings=tuple(warnings),
        skipped_views=tuple(skipped),
        corner_sigma_px=corner_sigma,
    )


def _natural_key(text: str) -> tuple[object, ...]:
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text))


def load_image_pairs(directory: str | Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Read `left_<id>.<ext>` / `right_<id>.<ext>` pairs from a folder.

    Returns [(id, left (H, W) uint8, right (H, W) uint8)] sorted naturally by id.
    InputError (naming the file) for a missing folder, an unpaired or unreadable file, or no
    pairs at all.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory}: not a folder")
    sides: dict[str, dict[str, Path]] = {"left": {}, "right": {}}
    for path in directory.iterdir():
        if path.suffix.lower() not in _IMAGE_SUFFIXES:
            continue
        match = re.fullmatch(r"(left|right)_(.+)", path.stem)
        if match:
            sides[match.group(1)][match.group(2)] = path
    for side, other in (("left", "right"), ("right", "left")):
        for key, path in sorted(sides[side].items()):
            if key not in sides[other]:
                raise InputError(f"{path}: no matching {other}_{key} image")
    if not sides["left"]:
        raise InputError(f"{directory}: no left_<id>/right_<id> image pairs found")
    pairs = []
    for key in sorted(sides["left"], key=_natural_key):
        images = []
        for side in ("left", "right"):
            path = sides[side][key]
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise InputError(f"{path}: cannot read image")
            images.append(image)
        pairs.append((key, images[0], images[1]))
    return pairs
