"""The stereo_target kind's simulated sensor: the stereo camera on the flange, the target it
looks at, and the chessboard views of the rig calibration (`StereoCamera`), and what the
controller reports of them (`camera_description`).

The left camera rides on the flange (`T_flange_camera`, truth); the right one is
`T_left_right` from it. Pattern "target" renders the circular target seen from the robot's
physical pose; "chessboard" renders one of the rig-calibration views, fixed relative to the
left camera. Images are 8-bit grey (H, W); lengths metres, angles radians. The images come
from `render.py`, the board poses from `board_views.py`; the camera's true pose is passed in
by the simulation (`Simulation.camera_pose`).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.geometry import make_transform, matrix_to_rpy
from controller_stub.scenario.spec import Scenario
from controller_stub.sensors.board_views import chessboard_views
from controller_stub.sensors.render import (
    CameraModel,
    ChessboardPattern,
    DiskPattern,
    Drawn,
    Renderer,
)
from controller_stub.streams import STREAM_LEFT, STREAM_RIGHT, STREAM_VIEWS, stream_rng

STREAM_EXTRA_VIEWS = 16
"""Random stream of the extra chessboard views (apart from streams.py's, so that adding them
changed no other draw)."""
EXTRA_VIEW_FACTOR = 3
"""Extra chessboard views offered beyond `n_views`, as a multiple of it."""


@dataclass(frozen=True)
class StereoFrame:
    """One stereo exposure: 8-bit grey images (H, W) and the reported joints at exposure."""

    left: np.ndarray
    right: np.ndarray
    q: np.ndarray
    time: float


def _plane_frame(origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(4, 4) frame at `origin` whose z axis is `normal` (x chosen orthogonal, deterministic)."""
    z = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - (helper @ z) * z
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = origin
    return T


def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    return {"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist()}


class StereoCamera:
    """The stereo camera on the flange and what it looks at: the target and the chessboard.

    Built from the scenario (nominal values plus the hidden errors: the mount, the target
    centre). camera: the true intrinsics of both cameras; T_flange_camera (+ _nominal): the
    left camera in the flange frame (4, 4); T_left_right: the right camera in the left one;
    T_base_target: the target plate's frame in base (its z axis the plate normal).
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        cam = scenario.camera
        self.camera = CameraModel(
            width=cam.image_width,
            height=cam.image_height,
            fx=cam.fx,
            fy=cam.fy,
            cx=cam.cx,
            cy=cam.cy,
            distortion=tuple(float(v) for v in cam.distortion),  # type: ignore[arg-type]
        )
        self.T_flange_camera_nominal = make_transform(cam.mount.xyz, cam.mount.rpy)
        self.T_flange_camera = self.T_flange_camera_nominal @ make_transform(
            cam.mount_error.xyz, cam.mount_error.rpy
        )
        self.T_left_right = make_transform([cam.baseline, 0.0, 0.0], cam.right_rpy)
        tgt = scenario.target
        self.target_centre = np.asarray(tgt.centre, float) + np.asarray(tgt.centre_error, float)
        self.T_base_target = _plane_frame(self.target_centre, np.asarray(tgt.normal, float))
        self.disk_pattern = DiskPattern(
            tgt.radius, tgt.plate_radius, tgt.dot_level, tgt.plate_level
        )
        board = scenario.chessboard
        self.board_pattern = ChessboardPattern(
            board.cols, board.rows, board.square_size, board.dark_level, board.light_level
        )
        self._board_views: np.ndarray | None = None  # drawn lazily (rejection sampling)
        self._extra_board_views: np.ndarray | None = None
        self._renderers: tuple[Renderer, Renderer] | None = None  # built on first capture
        self._pool: ThreadPoolExecutor | None = None  # draws the patches (`_draw`)
        self._board_ahead: dict[int, tuple[Future[Drawn], Future[Drawn]]] = {}

    def renderers(self) -> tuple[Renderer, Renderer]:
        """(left, right) renderers with the truth intrinsics (built on first use)."""
        if self._renderers is None:
            cam = self.scenario.camera
            level = self.scenario.target.background_level

            def build(stream: int) -> Renderer:
                return Renderer(self.camera, cam.pixel_noise_sigma, cam.blur_sigma, level,
                                stream_rng(self.scenario.seed, stream))

            # each from its own random stream: built side by side (their noise banks)
            left, right = (self._threads().submit(build, s) for s in (STREAM_LEFT, STREAM_RIGHT))
            self._renderers = (left.result(), right.result())
        return self._renderers

    @property
    def _views_seed(self) -> int:
        """The seed of the board poses: the chessboard's views_seed, else the scenario's."""
        views_seed = self.scenario.chessboard.views_seed
        return self.scenario.seed if views_seed is None else views_seed

    def chessboard_poses(self) -> np.ndarray:
        """(n_views, 4, 4) T_leftcamera_board of the rig-calibration views (truth)."""
        if self._board_views is None:
            board = self.scenario.chessboard
            self._board_views = chessboard_views(
                self.camera,
                self.T_left_right,
                self.board_pattern,
                board.n_views,
                (board.distance_min, board.distance_max),
                math.radians(board.max_tilt_deg),
                stream_rng(self._views_seed, STREAM_VIEWS),
            )
        return self._board_views.copy()

    def extra_chessboard_poses(self) -> np.ndarray:
        """(EXTRA_VIEW_FACTOR * n_views, 4, 4) further board poses, aimed anywhere in the
        image (centre 5-95 %), from their own random stream: views `n_views` and up, which a
        host asks for to complete its coverage or replace a rejected view."""
        if self._extra_board_views is None:
            board = self.scenario.chessboard
            self._extra_board_views = chessboard_views(
                self.camera,
                self.T_left_right,
                self.board_pattern,
                EXTRA_VIEW_FACTOR * board.n_views,
                (board.distance_min, board.distance_max),
                math.radians(board.max_tilt_deg),
                stream_rng(self._views_seed, STREAM_EXTRA_VIEWS),
                centre_range=(0.05, 0.95),
            )
        return self._extra_board_views.copy()

    def chessboard_corners(self) -> np.ndarray:
        """(rows*cols, 3) inner corners in the board frame (m), row-major."""
        return self.board_pattern.corners()

    def render(self, pattern: str, view: int, T_base_camera: Callable[[], np.ndarray]
               ) -> tuple[np.ndarray, np.ndarray]:
        """Render a stereo pair (left, right (H, W) uint8).

        The left and right patterns are drawn in two threads, and a chessboard view's
        successor is drawn ahead while the host looks at this one (a rig calibration asks
        for views 0, 1, ... in turn); the noise is added here, in capture order, so the
        images are the same bits as drawn one after the other.

        pattern "target": the circular target seen from the left camera's true pose
        `T_base_camera()` (4, 4), asked only for this pattern. pattern "chessboard": the
        `view`-th chessboard pose (relative to the left camera, independent of the robot).
        Raises SimulationRefused("invalid_argument") otherwise.
        """
        left_r, right_r = self.renderers()
        if pattern == "target":
            T_left_target = np.linalg.inv(T_base_camera()) @ self.T_base_target
            drawn = self._draw(Renderer.disk_patch, T_left_target, self.disk_pattern)
        elif pattern == "chessboard":
            n_views = self.scenario.chessboard.n_views
            max_views = (1 + EXTRA_VIEW_FACTOR) * n_views
            if not (isinstance(view, int) and 0 <= view < max_views):
                raise SimulationRefused(
                    "invalid_argument", f"chessboard view {view!r} not in 0..{max_views - 1}"
                )
            ahead, self._board_ahead = self._board_ahead, {}
            drawn = ahead[view] if view in ahead else self._board_patches(view)
            if view + 1 < n_views:  # a rig calibration asks for the views in turn
                self._board_ahead[view + 1] = self._board_patches(view + 1)
        else:
            raise SimulationRefused("invalid_argument", f"unknown pattern {pattern!r}")
        # the noise in capture order, left then right: the renderers' RNGs as ever
        return left_r.compose(drawn[0].result()), right_r.compose(drawn[1].result())

    def _draw(self, draw: Callable[[Renderer, np.ndarray, Any], Drawn], T_left: np.ndarray,
              pattern: Any) -> tuple[Future[Drawn], Future[Drawn]]:
        """The left and right patches of `pattern` at `T_left` (4, 4, in the left camera),
        drawn by `draw` in two threads (numpy and OpenCV release the GIL: both cores)."""
        left_r, right_r = self.renderers()
        T_right_left = np.linalg.inv(self.T_left_right)
        return (self._threads().submit(draw, left_r, T_left, pattern),
                self._threads().submit(draw, right_r, T_right_left @ T_left, pattern))

    def _threads(self) -> ThreadPoolExecutor:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="render")
        return self._pool

    def _board_patches(self, view: int) -> tuple[Future[Drawn], Future[Drawn]]:
        """The patches of chessboard view `view` (being) drawn."""
        n_views = self.scenario.chessboard.n_views
        T_left_board = (self.chessboard_poses()[view] if view < n_views
                        else self.extra_chessboard_poses()[view - n_views])
        return self._draw(Renderer.chessboard_patch, T_left_board, self.board_pattern)

    def truth(self) -> dict[str, Any]:
        """The camera's and the target's hidden truth (for `Simulation.truth()`)."""
        cam, tgt = self.scenario.camera, self.scenario.target
        return {
            "camera": {
                "image_width": cam.image_width,
                "image_height": cam.image_height,
                "fx": cam.fx,
                "fy": cam.fy,
                "cx": cam.cx,
                "cy": cam.cy,
                "distortion": list(cam.distortion),
                "baseline": cam.baseline,
                "T_left_right": _pose_dict(self.T_left_right),
                "T_flange_camera": _pose_dict(self.T_flange_camera),
                "T_flange_camera_nominal": _pose_dict(self.T_flange_camera_nominal),
            },
            "target": {
                "centre": self.target_centre.tolist(),
                "radius": tgt.radius,
                "normal": list(tgt.normal),
            },
        }


def camera_description(sc: Scenario) -> dict[str, Any]:
    """What the controller reports about its camera (and probe): never the hidden truth."""
    cam, tgt, board = sc.camera, sc.target, sc.chessboard
    return {
        "camera_serial": camera_serial(sc),
        "image_width": cam.image_width,
        "image_height": cam.image_height,
        "baseline_nominal": cam.baseline,
        "T_flange_camera_nominal": {"xyz": list(cam.mount.xyz), "rpy": list(cam.mount.rpy)},
        "target": {
            "radius": tgt.radius,
            "centre_nominal": list(tgt.centre),
            "normal": list(tgt.normal),
            "plate_radius": tgt.plate_radius,
        },
        "chessboard": {
            "cols": board.cols,
            "rows": board.rows,
            "square_size": board.square_size,
            "n_views": board.n_views,
            "max_views": (1 + EXTRA_VIEW_FACTOR) * board.n_views,
        },
        "probe": {
            "tip_nominal": list(sc.probe.tip),
            "stylus_radius": sc.probe.stylus_radius,
            "sphere_centre_nominal": list(sc.probe.sphere_centre),
            "sphere_radius": sc.probe.sphere_radius,
            "io_line": sc.probe.io_line,
            "repeatability": sc.probe.repeatability_sigma,
            # the simulated latch comes a fixed latency after the contact: no jitter
            "latency_jitter": 0.0,
        },
    }


def camera_serial(sc: Scenario) -> str:
    """The simulated camera's identity, as a real one reports its serial number: the same
    for the same camera (its intrinsics, distortion and stereo pose; not its mount, which
    is the robot's), whichever robot and world it is mounted in."""
    cam = sc.camera
    unit = [cam.image_width, cam.image_height, cam.fx, cam.fy, cam.cx, cam.cy,
            *cam.distortion, cam.baseline, *cam.right_rpy]
    digest = hashlib.sha256(repr([float(v) for v in unit]).encode()).hexdigest()
    return f"sim-{digest[:12]}"
