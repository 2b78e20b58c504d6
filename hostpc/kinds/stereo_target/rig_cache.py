"""A station's rig cache: the stereo rig calibrated once per camera, reused robot after robot.

A rig (intrinsics, distortion, the right camera's pose in the left's) belongs to the
camera, not to the robot it is mounted on: a station that mounts one stereo camera on robot
after robot need not show it the chessboard 20 times per robot. With the option `rig_cache`
(a folder) a run keys the rig by the camera identity the controller reports
(`camera_serial` in its camera description, docs/protocol.md) as `<folder>/<serial>.json`:

- no cached rig for that camera: the run calibrates one (as without the option) and stores it;
- a cached rig: the run captures chessboard view 0 and checks that the cached rig still fits
  it (`view_fit`): the board's pose found from the left corners with the cached left
  intrinsics (PnP) reprojects the left corners, and through the cached stereo pose the right
  ones, within FIT_FACTOR x the rig's own calibration RMS (at least MIN_FIT_PX). It fits:
  the run uses it (one capture of robot time instead of 20) and says so; it does not (another
  camera with the same serial, a knocked lens, a changed focus): the run calibrates anew and
  replaces it.

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

FIT_FACTOR = 3.0
"""A cached rig fits a fresh chessboard view when both images' reprojection RMS is within
this many times the rig's own calibration RMS."""
MIN_FIT_PX = 0.1
"""...and never asked below this (px): a rig file without an RMS, or a very good one."""


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


def view_fit(rig: Any, object_points: np.ndarray, left: np.ndarray, right: np.ndarray
             ) -> tuple[float, float]:
    """(left, right) reprojection RMS (px) of one chessboard view's detected corners
    (M, 2) each with `rig`: the board pose from the left corners (PnP, the rig's left
    intrinsics), the right corners through the rig's stereo pose (R, T)."""
    import cv2

    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, np.asarray(left, np.float64).reshape(-1, 1, 2),
                                      rig.K_left, rig.dist_left)
    except cv2.error:  # a degenerate cached rig (a zero focal length): it does not fit
        ok = False
    if not ok:
        return float("inf"), float("inf")
    R_board, _ = cv2.Rodrigues(rvec)
    in_left = obj @ R_board.T + tvec.reshape(1, 3)
    in_right = in_left @ np.asarray(rig.R, float).T + np.asarray(rig.T, float).reshape(1, 3)
    out = []
    for points, K, dist, seen in ((in_left, rig.K_left, rig.dist_left, left),
                                  (in_right, rig.K_right, rig.dist_right, right)):
        projected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, dist)
        error = projected.reshape(-1, 2) - np.asarray(seen, float).reshape(-1, 2)
        out.append(float(np.sqrt(np.mean(np.sum(error**2, axis=1)))))
    return out[0], out[1]


def fits(rig: Any, rms: tuple[float, float]) -> bool:
    """Does a view's (left, right) RMS (px) fit `rig` (FIT_FACTOR, MIN_FIT_PX)?"""
    bound = max(FIT_FACTOR * float(getattr(rig, "rms", 0.0) or 0.0), MIN_FIT_PX)
    return bool(max(rms) <= bound)
