"""A station's rig cache: the stereo rig calibrated once per camera, reused robot after robot.

A rig (intrinsics, distortion, the right camera's pose in the left's) belongs to the
camera, not to the robot it is mounted on: a station that mounts one stereo camera on robot
after robot need not show it the chessboard 20 times per robot. With the option `rig_cache`
(a folder) a run keys the rig by the camera identity the controller reports
(`camera_serial` in its camera description, docs/protocol.md) as `<folder>/<serial>.json`:

- no cached rig for that camera: the run calibrates one (as without the option) and stores it;
- a cached rig: the run captures chessboard views 0..CHECK_VIEWS-1 and checks that the cached
  rig still fits view 0 and the most tilted of the others (`view_fit`): the board's pose
  found from the left corners with the cached left intrinsics (PnP) reprojects the left
  corners, and through the cached stereo pose the right ones, within `fit_bound` (FIT_FACTOR
  x the rig's own calibration RMS, within MIN_FIT_PX..MAX_FIT_PX, so not the file's word
  alone). The tilted view catches a focal length error both cameras share, which a
  fronto-parallel view hides (docs/vision.md: x1.01 caught in 12 of 12 simulated worlds,
  narrowly in some). It fits: the run uses it (CHECK_VIEWS captures of robot time instead
  of 20) and says so; it does not (another camera with the same serial, a knocked lens, a
  changed focus): the run calibrates anew and replaces it. A cached file that cannot be
  read or is not a rig is a miss too.

The run folder keeps the rig it used (`rig.json`), and the result says which
(`describe`: `cached`). The rig's calibration covariance goes into the fit's shared error as
for a rig calibrated in the run; every robot calibrated with one cached rig shares its error.
"""

from __future__ import annotations

import hashlib
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

FIT_FACTOR = 2.5
"""A cached rig fits a fresh chessboard view when both images' reprojection RMS is within
this many times the rig's own calibration RMS..."""
MAX_FIT_PX = 0.3
"""...but never above this (px), whatever RMS the file claims (an edited "rms": 5.0 does not
make any rig fit)..."""
MIN_FIT_PX = 0.07
"""...and never below this (px): a rig file without an RMS, or a very good one."""
CHECK_VIEWS = 4
"""Chessboard views 0..CHECK_VIEWS-1 are captured; view 0 and the most tilted of the others
must both fit (a focal length error shared by both cameras hides in a fronto-parallel view:
the board just seems farther away)."""


def fit_bound(rig: Any) -> float:
    """The largest view RMS (px) that fits `rig`: FIT_FACTOR x its RMS within
    [MIN_FIT_PX, MAX_FIT_PX]."""
    return max(min(FIT_FACTOR * float(getattr(rig, "rms", 0.0) or 0.0), MAX_FIT_PX),
               MIN_FIT_PX)


MAX_NAME = 64
"""A serial longer than this (characters) is cut and gets a hash suffix (no ENAMETOOLONG)."""


def cache_name(serial: str) -> str:
    """The serial made a file name: characters other than A-Z a-z 0-9 . _ - become `_`;
    a name so changed, or longer than MAX_NAME, gets a short hash of the raw serial (so
    "a/b" and "a_b" differ). Also how messages name the camera (never the raw serial)."""
    raw = serial.strip()
    name = re.sub(r"[^A-Za-z0-9._-]", "_", raw)
    if name == raw and 0 < len(name) <= MAX_NAME and not name.startswith("."):
        return name
    digest = hashlib.sha256(raw.encode("utf-8", "surrogatepass")).hexdigest()[:12]
    return f"{name.lstrip('.')[:MAX_NAME - 13] or 'camera'}-{digest}"


def cache_path(folder: str | Path, serial: str) -> Path:
    """The cached rig of the camera `serial` in `folder` (cache_name)."""
    return Path(folder) / f"{cache_name(serial)}.json"


def check_folder(folder: str | Path) -> str | None:
    """None if the cache folder exists or can be created, and a file can be written in it;
    else why not (one line)."""
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path, prefix=".zerocal-probe-"):
            pass
    except OSError as exc:
        return f"--rig-cache {path}: cannot write there ({exc.strerror or exc})"
    return None


def _board_pose(rig: Any, object_points: np.ndarray, left: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(R (3, 3), t (3,)) of the board in the left camera from its left corners (PnP with the
    rig's left intrinsics), None if that fails."""
    import cv2

    try:
        ok, rvec, tvec = cv2.solvePnP(object_points, np.asarray(left, np.float64).reshape(-1, 1, 2),
                                      rig.K_left, rig.dist_left)
    except cv2.error:  # a degenerate cached rig (a zero focal length): it does not fit
        return None
    return (cv2.Rodrigues(rvec)[0], tvec.reshape(3)) if ok else None


def board_tilt_deg(rig: Any, object_points: np.ndarray, left: np.ndarray) -> float:
    """The board's tilt (deg) from facing the left camera, -1 if its pose is not found."""
    pose = _board_pose(rig, np.asarray(object_points, np.float64).reshape(-1, 3), left)
    return -1.0 if pose is None else float(np.degrees(np.arccos(min(abs(pose[0][2, 2]), 1.0))))


def view_fit(rig: Any, object_points: np.ndarray, left: np.ndarray, right: np.ndarray
             ) -> tuple[float, float]:
    """(left, right) reprojection RMS (px) of one chessboard view's detected corners
    (M, 2) each with `rig`: the board pose from the left corners (PnP, the rig's left
    intrinsics), the right corners through the rig's stereo pose (R, T)."""
    import cv2

    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    pose = _board_pose(rig, obj, left)
    if pose is None:
        return float("inf"), float("inf")
    in_left = obj @ pose[0].T + pose[1].reshape(1, 3)
    in_right = in_left @ np.asarray(rig.R, float).T + np.asarray(rig.T, float).reshape(1, 3)
    out = []
    for points, K, dist, seen in ((in_left, rig.K_left, rig.dist_left, left),
                                  (in_right, rig.K_right, rig.dist_right, right)):
        projected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, dist)
        error = projected.reshape(-1, 2) - np.asarray(seen, float).reshape(-1, 2)
        out.append(float(np.sqrt(np.mean(np.sum(error**2, axis=1)))))
    return out[0], out[1]
