"""Choosing chessboard views for a rig calibration that covers the image.

A focal length, a principal point and above all the distortion are determined only where
the board has been: a calibration from views that all sit in the middle of the image
extrapolates to its corners. `calibrate_rig` therefore flags a board that covered less than
`MIN_COVERAGE` of an 8 x 8 grid of image cells in either camera. Instead of failing a fixed
set of views, the acquisition plans them (`CoveragePlanner`):

1. take the controller's planned views; a view whose board is not found in both images is
   rejected and REPLACED by the next view on offer;
2. while either image is covered less than `TARGET_COVERAGE` (the flag's own threshold),
   take further views on offer and keep those that cover a cell not covered yet (in either
   image), until the coverage is reached or the offer is exhausted.

The offer is what the controller can show: `chessboard.n_views` planned views and up to
`chessboard.max_views` in all (the simulator offers extra views aimed all over the image).
Pure numerics: the caller captures, this module decides.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

GRID_CELLS = 8
"""The coverage grid: GRID_CELLS x GRID_CELLS cells over the image."""
MIN_COVERAGE = 0.5
"""Fraction of grid cells the board must have covered in each camera (else flagged)."""
TARGET_COVERAGE = MIN_COVERAGE
"""The planner asks for views until each image is covered this much. No margin above
MIN_COVERAGE: `calibrate_rig` checks the same corners of the same kept views with the same
`coverage`, so a plan that reached it is never flagged. A margin cost robot time for little:
at 0.55 the default world took 44 captures (20 planned + 24 offered, 21 of which added no
cell), at 0.50 it takes 20; docs/performance.md, "Rig calibration views"."""


def covered_cells(corners: np.ndarray, size: tuple[int, int], cells: int = GRID_CELLS
                  ) -> np.ndarray:
    """(cells * cells,) bool: the grid cells the convex hull of `corners` (M, 2) px touches
    in an image of `size` (w, h) px."""
    w, h = size
    mask = np.zeros((h // 4 + 1, w // 4 + 1), np.uint8)
    hull = cv2.convexHull((np.asarray(corners, float).reshape(-1, 2) / 4.0).astype(np.int32))
    cv2.fillConvexPoly(mask, hull, 1)
    hit = np.zeros(cells * cells, dtype=bool)
    for gy in range(cells):
        for gx in range(cells):
            y0, y1 = gy * mask.shape[0] // cells, (gy + 1) * mask.shape[0] // cells
            x0, x1 = gx * mask.shape[1] // cells, (gx + 1) * mask.shape[1] // cells
            hit[gy * cells + gx] = bool(mask[y0:y1, x0:x1].any())
    return hit


def coverage(corner_sets: list[np.ndarray], size: tuple[int, int],
             cells: int = GRID_CELLS) -> float:
    """Fraction of the grid cells touched by any board's convex hull."""
    hit = np.zeros(cells * cells, dtype=bool)
    for corners in corner_sets:
        hit |= covered_cells(corners, size, cells)
    return float(hit.mean())


@dataclass
class CoveragePlanner:
    """Decides which captured views to keep (module docstring).

    n_planned: how many views the calibration wants at least; size: (w, h) px."""

    n_planned: int
    size: tuple[int, int]
    target: float = TARGET_COVERAGE
    kept: list[int] = field(default_factory=list)
    rejected: list[tuple[int, str]] = field(default_factory=list)
    _left: np.ndarray = field(default_factory=lambda: np.zeros(GRID_CELLS**2, bool))
    _right: np.ndarray = field(default_factory=lambda: np.zeros(GRID_CELLS**2, bool))

    @property
    def coverage(self) -> tuple[float, float]:
        """(left, right) fraction of the grid covered by the kept views."""
        return float(self._left.mean()), float(self._right.mean())

    def done(self) -> bool:
        """Enough views kept and both images covered to the target."""
        return len(self.kept) >= self.n_planned and min(self.coverage) >= self.target

    def offer(self, view: int, left: np.ndarray | None, right: np.ndarray | None) -> bool:
        """Consider view `view` with its detected corners (M, 2) px per image (None: not
        found). Returns True if the view is kept."""
        if left is None or right is None:
            side = "both images" if left is None and right is None else (
                "the left image" if left is None else "the right image")
            self.rejected.append((view, f"chessboard not found in {side}"))
            return False
        cells_left = covered_cells(left, self.size)
        cells_right = covered_cells(right, self.size)
        new = bool(np.any(cells_left & ~self._left) or np.any(cells_right & ~self._right))
        if len(self.kept) >= self.n_planned and not new:
            self.rejected.append((view, "adds no coverage"))
            return False
        self.kept.append(view)
        self._left |= cells_left
        self._right |= cells_right
        return True
