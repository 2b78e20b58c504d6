"""The simulated stereo camera: rendering captures and describing the camera.

The left camera rides on the flange (`T_flange_camera`, truth); the right one is
`T_left_right` from it. Pattern "target" renders the circular target seen from the robot's
physical pose; "chessboard" renders one of the rig-calibration views, fixed relative to the
left camera. Images are 8-bit grey (H, W); lengths metres, angles radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import Scenario
from controller_stub.sensors.board_views import chessboard_views
from controller_stub.sensors.render import (
    CameraModel,
    ChessboardPattern,
    DiskPattern,
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


class StereoCameraMixin:
    """The stereo camera of `Simulation`: renderers, chessboard views, captures.

    Part of `controller_stub.world.simulation.Simulation` (its module docstring has the contract);
    the state below is created by `Simulation.__init__`.
    """

    scenario: Scenario
    camera: CameraModel
    T_left_right: np.ndarray
    T_base_target: np.ndarray
    disk_pattern: DiskPattern
    board_pattern: ChessboardPattern
    _board_views: np.ndarray | None
    _extra_board_views: np.ndarray | None = None
    _renderers: tuple[Renderer, Renderer] | None
    _q: np.ndarray
    _time: float

    if TYPE_CHECKING:  # provided by Simulation

        def camera_pose(self) -> np.ndarray: ...

    def renderers(self) -> tuple[Renderer, Renderer]:
        """(left, right) renderers with the truth intrinsics (built on first use)."""
        if self._renderers is None:
            cam = self.scenario.camera
            level = self.scenario.target.background_level
            self._renderers = (
                Renderer(
                    self.camera,
                    cam.pixel_noise_sigma,
                    cam.blur_sigma,
                    level,
                    stream_rng(self.scenario.seed, STREAM_LEFT),
                ),
                Renderer(
                    self.camera,
                    cam.pixel_noise_sigma,
                    cam.blur_sigma,
                    level,
                    stream_rng(self.scenario.seed, STREAM_RIGHT),
                ),
            )
        return self._renderers

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
                stream_rng(self.scenario.seed, STREAM_VIEWS),
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
                stream_rng(self.scenario.seed, STREAM_EXTRA_VIEWS),
                centre_range=(0.05, 0.95),
            )
        return self._extra_board_views.copy()

    def chessboard_corners(self) -> np.ndarray:
        """(rows*cols, 3) inner corners in the board frame (m), row-major."""
        return self.board_pattern.corners()

    def capture_stereo(self, pattern: str = "target", view: int = 0) -> StereoFrame:
        """Render a stereo pair (left, right (H, W) uint8).

        pattern "target": the circular target seen from the robot's physical pose.
        pattern "chessboard": the `view`-th chessboard pose (relative to the left camera,
        independent of the robot). Raises SimulationRefused("invalid_argument") otherwise.
        The frame is stamped at the start of the exposure; the clock then advances by the
        scenario's `motion.capture_s` (robot time spent standing still for the capture).
        """
        T_right_left = np.linalg.inv(self.T_left_right)
        left_r, right_r = self.renderers()
        if pattern == "target":
            T_left_target = np.linalg.inv(self.camera_pose()) @ self.T_base_target
            left = left_r.render_disk(T_left_target, self.disk_pattern)
            right = right_r.render_disk(T_right_left @ T_left_target, self.disk_pattern)
        elif pattern == "chessboard":
            n_views = self.scenario.chessboard.n_views
            max_views = (1 + EXTRA_VIEW_FACTOR) * n_views
            if not (isinstance(view, int) and 0 <= view < max_views):
                raise SimulationRefused(
                    "invalid_argument", f"chessboard view {view!r} not in 0..{max_views - 1}"
                )
            T_left_board = (self.chessboard_poses()[view] if view < n_views
                            else self.extra_chessboard_poses()[view - n_views])
            left = left_r.render_chessboard(T_left_board, self.board_pattern)
            right = right_r.render_chessboard(T_right_left @ T_left_board, self.board_pattern)
        else:
            raise SimulationRefused("invalid_argument", f"unknown pattern {pattern!r}")
        frame = StereoFrame(left=left, right=right, q=self._q.copy(), time=self._time)
        self._time += float(self.scenario.motion.capture_s)  # exposure + readout
        return frame

    def camera_description(self) -> dict[str, Any]:
        """What the controller reports about its camera: never the hidden truth."""
        sc = self.scenario
        cam, tgt, board = sc.camera, sc.target, sc.chessboard
        return {
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
