"""Stereo camera renderer: circular dot target and chessboard, 8-bit grey images.

Camera model: pinhole plus OpenCV distortion (k1, k2, p1, p2, k3); pixel (0, 0) is the CENTRE
of the top-left pixel (OpenCV convention). Camera frame: x right, y down, z forward.

Every pattern lies on a plane given by `T_cam_plane` (plane coordinates u = x, v = y of the
plane frame, plane z = 0). For each pixel the exact ray through its centre (from a
precomputed undistortion map, solved to 1e-12) is intersected with the plane. A disk's edges
cover each pixel by the exact area a straight edge through it covers (signed distance and
direction from the local gradient, in pixels): a pixel that integrates its area, as a
sensor's does, so a disk's intensity centroid is its image's area centroid to 2e-4 px
(bench/bench_centre_error.py; a one-pixel ramp in the distance, exact only for edges along
the pixel grid, left 0.002-0.004 px that varied with the sub-pixel phase). The chessboard's
edges use that ramp (its signed distance divided by the local pixel footprint). Then a
Gaussian blur and pixel noise. The pattern is only computed inside
its projected bounding box (plus the blur support); the background is flat plus noise.

Noise comes from a bank of Gaussian samples drawn once from the seeded RNG; each frame
uses a window at a random offset with a random flip (also seeded), so a 1280x1024 pair costs
a copy, not 2.6 M fresh Gaussians.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

_NOISE_MARGIN = 128  # the noise bank is this many pixels larger than the image

Drawn = tuple[np.ndarray, tuple[int, int, int, int]] | None
"""A pattern drawn before the noise: its blurred float32 patch and the box (y0, y1, x0, x1)
it covers, or None if nothing of it is visible."""


@dataclass(frozen=True)
class CameraModel:
    """Pinhole + OpenCV distortion. Intrinsics in pixels; distortion (5,) k1, k2, p1, p2, k3."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float]

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def distort_normalized(camera: CameraModel, xy: np.ndarray) -> np.ndarray:
    """(N, 2) ideal normalised coordinates -> (N, 2) distorted normalised coordinates."""
    k1, k2, p1, p2, k3 = camera.distortion
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=1)


def project_points(camera: CameraModel, points_cam: np.ndarray) -> np.ndarray:
    """(N, 3) points in the camera frame (m, z > 0) -> (N, 2) pixel coordinates."""
    p = np.atleast_2d(np.asarray(points_cam, dtype=float))
    xy = p[:, :2] / p[:, 2:3]
    d = distort_normalized(camera, xy)
    return np.stack([camera.fx * d[:, 0] + camera.cx, camera.fy * d[:, 1] + camera.cy], axis=1)


def project_point(camera: CameraModel, T_cam_frame: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(3,) point in `frame` -> (2,) pixel coordinates in the camera (T_cam_frame (4, 4))."""
    p = T_cam_frame[:3, :3] @ np.asarray(point, dtype=float) + T_cam_frame[:3, 3]
    return project_points(camera, p[None, :])[0]


def undistort_pixels(camera: CameraModel, uv: np.ndarray, tol: float = 1e-14) -> np.ndarray:
    """(N, 2) pixels -> (N, 2) ideal normalised coordinates (inverse of the distortion).

    Newton's method with the analytic Jacobian of the distortion, from the distorted
    coordinates as the first guess; converges to `tol` (normalised units) in a few steps.
    """
    k1, k2, p1, p2, k3 = camera.distortion
    uv = np.asarray(uv, dtype=float)
    xd = (uv[:, 0] - camera.cx) / camera.fx
    yd = (uv[:, 1] - camera.cy) / camera.fy
    x, y = xd.copy(), yd.copy()
    for _ in range(20):
        x2, y2, xy = x * x, y * y, x * y
        r2 = x2 + y2
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
        ex = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2) - xd
        ey = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy - yd
        jxx = radial + 2.0 * x2 * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
        jyy = radial + 2.0 * y2 * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
        jxy = 2.0 * xy * d_radial + 2.0 * p1 * x + 2.0 * p2 * y  # d ex/dy = d ey/dx
        det = jxx * jyy - jxy * jxy
        x -= (jyy * ex - jxy * ey) / det
        y -= (jxx * ey - jxy * ex) / det
        if (
            float(np.max(np.abs(ex), initial=0.0)) < tol
            and float(np.max(np.abs(ey), initial=0.0)) < tol
        ):
            break
    return np.stack([x, y], axis=1)


RAY_MAP_VERSION = 1
"""Part of the ray map cache's key: raise it when `undistort_pixels` or `ray_map` changes."""


def ray_map_cache_file(camera: CameraModel) -> Path:
    """Where `ray_map` keeps a camera's map between processes: $ZEROCAL_CACHE_DIR, else
    $XDG_CACHE_HOME/zerocal, else ~/.cache/zerocal; the name is a hash of every intrinsic
    (floats by their exact repr) and RAY_MAP_VERSION."""
    root = os.environ.get("ZEROCAL_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "zerocal")
    key = repr((RAY_MAP_VERSION, camera.width, camera.height, camera.fx, camera.fy,
                camera.cx, camera.cy, tuple(camera.distortion)))
    return Path(root) / f"ray_map-{hashlib.sha256(key.encode()).hexdigest()[:32]}.npy"


@lru_cache(maxsize=8)
def ray_map(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Normalised ray coordinates (x, y) of every pixel centre: two (H, W) float32 arrays.

    Solving the undistortion for every pixel is about a third of a second, the same in every
    stub process for the same camera, so the map is kept on disk (`ray_map_cache_file`) and
    read back (a few milliseconds); a missing, unreadable or wrongly shaped file is solved
    anew and rewritten (atomically: parallel stubs may race), a cache that cannot be written
    (read-only home) is skipped."""
    shape = (camera.height, camera.width)
    path = ray_map_cache_file(camera)
    xy_map: np.ndarray | None = None
    with contextlib.suppress(OSError, ValueError):
        loaded = np.load(path, allow_pickle=False)
        if loaded.shape == (2, *shape) and loaded.dtype == np.float32 and np.all(
                np.isfinite(loaded)):
            xy_map = loaded
    if xy_map is None:
        v, u = np.mgrid[0 : camera.height, 0 : camera.width]
        xy = undistort_pixels(camera, np.stack([u.ravel(), v.ravel()], axis=1).astype(float))
        xy_map = np.stack([xy[:, 0].reshape(shape), xy[:, 1].reshape(shape)]).astype(np.float32)
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npy",
                                             delete=False) as handle:
                np.save(handle, xy_map, allow_pickle=False)
            os.replace(handle.name, path)
    x, y = np.ascontiguousarray(xy_map[0]), np.ascontiguousarray(xy_map[1])
    x.setflags(write=False)
    y.setflags(write=False)
    return x, y


@dataclass(frozen=True)
class DiskPattern:
    """Dark disk (radius) on a bright round plate (plate_radius), grey levels 0..255."""

    radius: float
    plate_radius: float
    dot_level: float
    plate_level: float


@dataclass(frozen=True)
class ChessboardPattern:
    """cols x rows INNER corners at (i*square, j*square) in the board plane; a light margin of
    one square surrounds the (cols+1) x (rows+1) squares. The square whose lower corner is
    (0, 0) is dark."""

    cols: int
    rows: int
    square: float
    dark_level: float
    light_level: float

    def corners(self) -> np.ndarray:
        """(rows*cols, 3) inner corners in the board frame, row-major (x fastest)."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.stack(
            [i.ravel() * self.square, j.ravel() * self.square, np.zeros(i.size)], axis=1
        )

    def outline(self) -> tuple[float, float, float, float]:
        """(u_min, u_max, v_min, v_max) of the board incl. its light margin (m)."""
        s = self.square
        return -2 * s, (self.cols + 1) * s, -2 * s, (self.rows + 1) * s

    def outline_points(self, per_side: int) -> np.ndarray:
        """(4 per_side, 2) points along the outline's four sides (board frame, m): bottom,
        top, left, right, each from its start to its end corner."""
        u_min, u_max, v_min, v_max = self.outline()
        k = np.linspace(0.0, 1.0, per_side)
        return np.concatenate(
            [
                np.column_stack([u_min + (u_max - u_min) * k, np.full(per_side, v_min)]),
                np.column_stack([u_min + (u_max - u_min) * k, np.full(per_side, v_max)]),
                np.column_stack([np.full(per_side, u_min), v_min + (v_max - v_min) * k]),
                np.column_stack([np.full(per_side, u_max), v_min + (v_max - v_min) * k]),
            ]
        )


def _smooth_step(signed_distance: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """Box-filtered coverage of the half-plane signed_distance > 0 (in place, float32)."""
    out = np.divide(signed_distance, footprint, out=signed_distance)
    out += 0.5
    return np.clip(out, 0.0, 1.0, out=out)


def _pixel_area_cover(signed_distance: np.ndarray, grad_x: np.ndarray, grad_y: np.ndarray
                      ) -> np.ndarray:
    """Exact area of a unit pixel covered by the half-plane signed_distance > 0, for an edge
    whose signed distance (plane units) has the gradient (grad_x, grad_y) per pixel: with
    d the distance from the pixel centre in pixels and (a, b) = the sorted |components| of
    the edge's unit normal, the covered fraction is P(a U1 + b U2 < d) for U1, U2 uniform
    on (-1/2, 1/2), a trapezoid's CDF (float32 (h, w)). A one-pixel ramp in d (the same
    area only for axis-aligned edges) aliases: it moved a disk's centroid by 0.002-0.004 px
    with the sub-pixel phase (bench/bench_centre_error.py). Exact for a STRAIGHT edge only:
    a disk's curvature adds ~0.27 px^2 of area in all, which matters for disks of a few
    pixels (1.1 px radius: 0.03 px of centroid error) and not for the target's (>= 16 px)."""
    g = np.hypot(grad_x, grad_y)
    np.maximum(g, np.float32(1e-12), out=g)
    d = signed_distance / g
    ax = np.abs(grad_x) / g
    ay = np.abs(grad_y) / g
    a = np.maximum(ax, ay)
    b = np.minimum(ax, ay)
    t = np.clip(d + np.float32(0.5) * (a + b), 0.0, a + b)  # 0 .. a + b across the edge
    b_safe = np.maximum(b, np.float32(1e-6))
    inv_2ab = np.float32(0.5) / (a * b_safe)
    low = t * t * inv_2ab
    middle = (t - np.float32(0.5) * b) / a
    high = np.float32(1.0) - (a + b - t) ** 2 * inv_2ab
    cover = np.where(t < b, low, np.where(t <= a, middle, high))
    cover = np.where(b < 1e-6, d + np.float32(0.5), cover)  # an axis-aligned edge: a ramp
    return np.clip(cover, 0.0, 1.0).astype(np.float32)


def _gradient(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d f / d x, d f / d y) in pixel units by central differences (one-sided at the
    border), each (h, w)."""
    gx = np.empty_like(f)
    gy = np.empty_like(f)
    gx[:, 1:-1] = (f[:, 2:] - f[:, :-2]) * 0.5
    gx[:, 0] = f[:, 1] - f[:, 0]
    gx[:, -1] = f[:, -1] - f[:, -2]
    gy[1:-1] = (f[2:] - f[:-2]) * 0.5
    gy[0] = f[1] - f[0]
    gy[-1] = f[-1] - f[-2]
    return gx, gy


def _gradient_norm(f: np.ndarray) -> np.ndarray:
    """|grad f| in pixel units by central differences (one-sided at the border), (h, w)."""
    gx, gy = _gradient(f)
    g = np.hypot(gx, gy, out=gx)
    np.maximum(g, 1e-12, out=g)
    return g


class Renderer:
    """Renders one camera of the rig. Deterministic given the RNG it is built with.

    camera: truth intrinsics; noise_sigma: grey levels; blur_sigma: pixels;
    background_level: grey level of everything that is not the pattern.
    """

    def __init__(
        self,
        camera: CameraModel,
        noise_sigma: float,
        blur_sigma: float,
        background_level: float,
        rng: np.random.Generator,
    ) -> None:
        self.camera = camera
        self.noise_sigma = float(noise_sigma)
        self.blur_sigma = float(blur_sigma)
        self.background_level = float(background_level)
        self._rng = rng
        self._ray_x, self._ray_y = ray_map(camera)
        shape = (camera.height + _NOISE_MARGIN, camera.width + _NOISE_MARGIN)
        if self.noise_sigma > 0:
            self._noise = (rng.standard_normal(shape, dtype=np.float32) * self.noise_sigma).astype(
                np.float32
            )
        else:
            self._noise = np.zeros(shape, np.float32)
        self._background_bank = np.clip(
            np.rint(self._noise + np.float32(self.background_level)), 0, 255
        ).astype(np.uint8)
        self._pad = int(math.ceil(4 * self.blur_sigma)) + 3

    # -------------------------------------------------------------- frame assembly

    def _noise_window(self) -> tuple[int, int, bool, bool]:
        oy, ox = (int(v) for v in self._rng.integers(0, _NOISE_MARGIN + 1, size=2))
        fy, fx = (bool(v) for v in self._rng.integers(0, 2, size=2))
        return oy, ox, fy, fx

    def _window(self, bank: np.ndarray, win: tuple[int, int, bool, bool]) -> np.ndarray:
        oy, ox, fy, fx = win
        h, w = self.camera.height, self.camera.width
        view = bank[oy : oy + h, ox : ox + w]
        if fy:
            view = view[::-1]
        if fx:
            view = view[:, ::-1]
        return view

    def _blurred(self, patch: np.ndarray) -> np.ndarray:
        """The float patch after the lens blur (no randomness: any thread may call it)."""
        if self.blur_sigma > 0:
            patch = cv2.GaussianBlur(
                patch, (0, 0), self.blur_sigma, borderType=cv2.BORDER_REPLICATE
            )
        return patch

    def compose(self, drawn: Drawn) -> np.ndarray:
        """(H, W) uint8 frame: background plus noise with the blurred float patch of `drawn`
        (from `disk_patch` / `chessboard_patch`, None: nothing visible) pasted at its box
        (y0, y1, x0, x1). Draws the frame's noise window from the renderer's RNG: frames
        must be composed in capture order."""
        win = self._noise_window()
        image = np.ascontiguousarray(self._window(self._background_bank, win))
        if drawn is None:
            return image
        patch, (y0, y1, x0, x1) = drawn
        patch += self._window(self._noise, win)[y0:y1, x0:x1]
        np.rint(patch, out=patch)
        np.clip(patch, 0, 255, out=patch)
        image[y0:y1, x0:x1] = patch.astype(np.uint8)
        return image

    def background(self) -> np.ndarray:
        """(H, W) uint8: flat background plus noise."""
        return self.compose(None)

    # -------------------------------------------------------------- geometry helpers

    def _bbox(
        self, T_cam_plane: np.ndarray, outline_pts: np.ndarray
    ) -> tuple[int, int, int, int] | None:
        """Pixel box (y0, y1, x0, x1) covering the projected outline (K, 2) plane points, plus
        the blur pad; None if nothing is visible. Points behind the camera -> whole image."""
        pts = np.column_stack([outline_pts, np.zeros(len(outline_pts))])
        cam_pts = pts @ T_cam_plane[:3, :3].T + T_cam_plane[:3, 3]
        h, w = self.camera.height, self.camera.width
        if np.all(cam_pts[:, 2] <= 1e-6):
            return None
        if np.any(cam_pts[:, 2] <= 1e-3):
            return 0, h, 0, w
        uv = project_points(self.camera, cam_pts)
        x0 = max(0, int(math.floor(uv[:, 0].min())) - self._pad)
        x1 = min(w, int(math.ceil(uv[:, 0].max())) + self._pad + 1)
        y0 = max(0, int(math.floor(uv[:, 1].min())) - self._pad)
        y1 = min(h, int(math.ceil(uv[:, 1].max())) + self._pad + 1)
        if x1 - x0 < 3 or y1 - y0 < 3:
            return None
        return y0, y1, x0, x1

    def _plane_coords(
        self, T_cam_plane: np.ndarray, box: tuple[int, int, int, int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Plane coordinates (u, v) (m, float32 (h, w)) hit by each pixel ray in box, and the
        mask of rays that hit the plane in front of the camera."""
        y0, y1, x0, x1 = box
        rx = self._ray_x[y0:y1, x0:x1]
        ry = self._ray_y[y0:y1, x0:x1]
        R = T_cam_plane[:3, :3]
        p0 = T_cam_plane[:3, 3]
        n = R[:, 2]
        e1, e2 = R[:, 0], R[:, 1]
        f32 = np.float32
        denom = f32(n[0]) * rx + f32(n[1]) * ry + f32(n[2])
        t = np.divide(f32(n @ p0), denom, out=np.zeros_like(denom), where=np.abs(denom) > 1e-9)
        valid = t > 0
        u = t * (f32(e1[0]) * rx + f32(e1[1]) * ry + f32(e1[2])) - f32(e1 @ p0)
        v = t * (f32(e2[0]) * rx + f32(e2[1]) * ry + f32(e2[2])) - f32(e2 @ p0)
        return u, v, valid

    # -------------------------------------------------------------- patterns

    def render_disk(self, T_cam_target: np.ndarray, pattern: DiskPattern) -> np.ndarray:
        """(H, W) uint8 image of the disk target; T_cam_target (4, 4): the target frame has
        the disk centre at its origin and the plate normal as its z axis."""
        return self.compose(self.disk_patch(T_cam_target, pattern))

    def disk_patch(self, T_cam_target: np.ndarray, pattern: DiskPattern) -> Drawn:
        """The blurred float patch and box of `render_disk` before the noise (None: nothing
        visible). Deterministic and free of the RNG: it may be drawn in another thread."""
        angles = np.linspace(0.0, 2 * math.pi, 73)
        ring = pattern.plate_radius * np.column_stack([np.cos(angles), np.sin(angles)])
        box = self._bbox(T_cam_target, ring)
        if box is None:
            return None
        u, v, valid = self._plane_coords(T_cam_target, box)
        rho = np.hypot(u, v)
        grad_x, grad_y = _gradient(rho)
        plate = _pixel_area_cover(np.float32(pattern.plate_radius) - rho, grad_x, grad_y)
        dot = _pixel_area_cover(np.float32(pattern.radius) - rho, grad_x, grad_y)
        bg = np.float32(self.background_level)
        patch = bg + np.float32(pattern.plate_level - self.background_level) * plate
        patch += np.float32(pattern.dot_level - pattern.plate_level) * dot
        patch[~valid] = bg
        return self._blurred(patch), box

    def render_chessboard(self, T_cam_board: np.ndarray, pattern: ChessboardPattern) -> np.ndarray:
        """(H, W) uint8 image of the chessboard; T_cam_board (4, 4): board frame with the first
        inner corner at its origin, x along a row of corners, z the board normal."""
        return self.compose(self.chessboard_patch(T_cam_board, pattern))

    def chessboard_patch(self, T_cam_board: np.ndarray, pattern: ChessboardPattern) -> Drawn:
        """The blurred float patch and box of `render_chessboard` before the noise (None:
        nothing visible). Deterministic and free of the RNG: it may be drawn in another
        thread."""
        u_min, u_max, v_min, v_max = pattern.outline()
        outline = pattern.outline_points(17)
        box = self._bbox(T_cam_board, outline)
        if box is None:
            return None
        u, v, valid = self._plane_coords(T_cam_board, box)
        wu = _gradient_norm(u)
        wv = _gradient_norm(v)
        s = pattern.square
        f32 = np.float32

        def half_width_cover(coord: np.ndarray, lo: float, hi: float, w: np.ndarray) -> np.ndarray:
            centre, half = f32(0.5 * (lo + hi)), f32(0.5 * (hi - lo))
            return _smooth_step(half - np.abs(coord - centre), w)

        plate = half_width_cover(u, u_min, u_max, wu) * half_width_cover(v, v_min, v_max, wv)
        squares = half_width_cover(u, -s, pattern.cols * s, wu) * half_width_cover(
            v, -s, pattern.rows * s, wv
        )

        def even_square(coord: np.ndarray, w: np.ndarray) -> np.ndarray:
            t = coord / f32(s)
            k_floor = np.floor(t)
            frac = t - k_floor
            dist = np.minimum(frac, 1 - frac) * f32(s)
            odd = (k_floor.astype(np.int64) & 1).astype(bool)
            dist[odd] *= -1
            return _smooth_step(dist, w)

        # clamp to the centres of the border squares so the checker value is constant across
        # the outer edge of the squares area (that edge is drawn by `squares` alone)
        half = 0.5 * s
        eu = even_square(np.clip(u, f32(-half), f32(pattern.cols * s - half)), wu)
        ev = even_square(np.clip(v, f32(-half), f32(pattern.rows * s - half)), wv)
        dark = eu * ev + (1 - eu) * (1 - ev)
        bg = f32(self.background_level)
        patch = bg + f32(pattern.light_level - self.background_level) * plate
        patch += f32(pattern.dark_level - pattern.light_level) * dark * squares
        patch[~valid] = bg
        return self._blurred(patch.astype(np.float32)), box
