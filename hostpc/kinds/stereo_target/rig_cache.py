"""A station's rig cache: the stereo rig calibrated once per camera, reused robot after robot.

A rig (intrinsics, distortion, the right camera's pose in the left's) belongs to the
camera, not to the robot it is mounted on: a station that mounts one stereo camera on robot
after robot need not show it the chessboard 20 times per robot. With the option `rig_cache`
(a folder) a run keys the rig by the camera identity the controller reports
(`camera_serial` in its camera description, docs/protocol.md) as `<folder>/<serial>.json`:

- no cached rig for that camera: the run calibrates one (as without the option) and stores it;
- a cached rig: the run checks that it still fits fresh chessboard views (`view_fit`): the
  board's pose found from the left corners with the cached left intrinsics (PnP)
  reprojects the left corners, and through the cached stereo pose the right ones, within
  `fit_bound` (FIT_FACTOR x the rig's own calibration RMS, within MIN_FIT_PX..MAX_FIT_PX,
  so not the file's word alone). Which views:
  - a cache file that names its check view (CHECK_VIEW_KEY, written with the rig: the
    calibration's own view, other than 0, that a focal length error shared by both cameras
    shows most, `choose_check_view`): views 0 and that one, 2 captures. A focal error both
    cameras share hides in a fronto-parallel view (the board just seems farther away);
    the check view must show FOCAL_ERROR above the bound (`focal_signal`, from the view
    captured now: the station may show other board poses than when the rig was stored),
    else views 1..CHECK_VIEWS-1 are added until one does;
  - a cache file written before check views were recorded (no CHECK_VIEW_KEY): views
    0..CHECK_VIEWS-1 are captured and view 0 and the most tilted of the others must fit
    (docs/vision.md: x1.01 caught in 12 of 12 simulated worlds, narrowly in some).
  It fits: the run uses it (2 captures of robot time, or CHECK_VIEWS, instead of 20) and
  says which check it made; it does not (another camera with the same serial, a knocked
  lens, a changed focus): the run calibrates anew and replaces it. A cached file that
  cannot be read or is not a rig (or names a check view the controller does not have) is a
  miss too.

The run folder keeps the rig it used (`rig.json`), and the result says which
(`describe`: `cached`). The rig's calibration covariance goes into the fit's shared error as
for a rig calibrated in the run; every robot calibrated with one cached rig shares its error.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
import tempfile
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.errors import InputError

FIT_FACTOR = 2.5
"""A cached rig fits a fresh chessboard view when both images' reprojection RMS is within
this many times the rig's own calibration RMS..."""
MAX_FIT_PX = 0.3
"""...but never above this (px), whatever RMS the file claims (an edited "rms": 5.0 does not
make any rig fit)..."""
MIN_FIT_PX = 0.07
"""...and never below this (px): a rig file without an RMS, or a very good one."""
CHECK_VIEWS = 4
"""A cache file without a check view: chessboard views 0..CHECK_VIEWS-1 are captured; view 0
and the most tilted of the others must both fit (a focal length error shared by both cameras
hides in a fronto-parallel view: the board just seems farther away). With a check view:
views 1..CHECK_VIEWS-1 are what is added when the check view no longer shows FOCAL_ERROR."""
CHECK_VIEW_KEY = "check_view"
"""The cache file's field naming its check view: {"view": int >= 1, "focal_signal_px": the
view's `focal_signal` when the rig was calibrated}."""
FOCAL_ERROR = 1.01
"""The focal length error shared by both cameras (both axes) the check must show: a check
view's `focal_signal` must reach the fit bound."""


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


def focal_signal(rig: Any, object_points: np.ndarray, left: np.ndarray) -> float:
    """The reprojection RMS (px, the larger image's) that both cameras' focal lengths x
    FOCAL_ERROR would give this chessboard view without noise: the corners `rig` itself
    predicts at the board's pose (PnP from the `left` corners) fitted with the scaled rig
    (`view_fit`); 0.0 if the pose is not found. A view whose signal reaches `fit_bound`
    shows such an error whatever the noise (the noise only adds to the RMS)."""
    import cv2

    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    pose = _board_pose(rig, obj, left)
    if pose is None:
        return 0.0
    in_left = obj @ pose[0].T + pose[1].reshape(1, 3)
    in_right = in_left @ np.asarray(rig.R, float).T + np.asarray(rig.T, float).reshape(1, 3)
    ideal = [cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 2)
             for points, K, dist in ((in_left, rig.K_left, rig.dist_left),
                                     (in_right, rig.K_right, rig.dist_right))]
    return max(view_fit(focal_scaled(rig, FOCAL_ERROR), obj, ideal[0], ideal[1]))


def focal_scaled(rig: Any, factor: float) -> Any:
    """`rig` with both cameras' focal lengths (fx, fy) times `factor`, the principal points
    where they were (a changed focus)."""
    def scaled(K: np.ndarray) -> np.ndarray:
        out = np.array(K, float)
        out[0, 0] *= factor
        out[1, 1] *= factor
        return out

    return dataclasses.replace(rig, K_left=scaled(rig.K_left), K_right=scaled(rig.K_right))


def choose_check_view(rig: Any, object_points: np.ndarray,
                      views: Iterable[tuple[int, np.ndarray]]) -> dict[str, Any] | None:
    """The cache file's CHECK_VIEW_KEY: of the calibration's (view, left corners) other
    than view 0 (which every check captures), the one with the largest `focal_signal`;
    None if there is none."""
    signals = [(focal_signal(rig, object_points, left), view) for view, left in views
               if view != 0]
    if not signals:
        return None
    signal, view = max(signals)
    return {"view": int(view), "focal_signal_px": round(float(signal), 4)}


def load_cached(path: Path, max_views: int) -> tuple[Any, int | None]:
    """(the cached rig, its check view or None for a cache file written before check views
    were recorded); InputError (one line) if the file is not a rig or names a check view
    outside 1..max_views-1."""
    from hostpc.vision.rig import rig_document, rig_from_dict

    data = rig_document(path)
    rig = rig_from_dict(data, str(path))
    entry = data.get(CHECK_VIEW_KEY)
    if entry is None:
        return rig, None
    view = entry.get("view") if isinstance(entry, dict) else None
    if isinstance(view, bool) or not isinstance(view, int) or not 1 <= view < max_views:
        raise InputError(f"{path}: {CHECK_VIEW_KEY}: expected a chessboard view 1.."
                         f"{max_views - 1}, got {entry!r}")
    return rig, view


Corners = tuple[Any, Any]
"""A chessboard view's (left, right) corners (M, 2) each, None where the board was not found."""


@dataclass(frozen=True)
class RigCheck:
    """A cached rig checked against fresh chessboard views (`check_rig`).

    views: the views that must fit; captures: how many were captured; rms: (left, right)
    view_fit RMS (px) of each of `views`; bound: fit_bound; signal: the largest
    focal_signal of `views` (px); check: which check, in words."""

    views: list[int]
    captures: int
    rms: list[tuple[float, float]]
    bound: float
    signal: float
    check: str

    @property
    def worst(self) -> float:
        """The largest RMS (px) of any checked view and image."""
        return max(max(pair) for pair in self.rms)

    @property
    def fits(self) -> bool:
        return self.worst <= self.bound

    def said(self) -> str:
        """The check in one clause: views, worst RMS, bound, signal, which check."""
        return (f"chessboard views {', '.join(map(str, self.views))}: RMS {self.worst:.3f} px, "
                f"bound {self.bound:.3f} px; a x{FOCAL_ERROR} focal error would show "
                f"{self.signal:.3f} px; {self.check}")

    def report(self) -> dict[str, Any]:
        """rig_calibration.json's fields of the check (besides `cached`)."""
        return {"check_views": self.views, "bound_px": self.bound, "captures": self.captures,
                "check": self.check, "focal_signal_px": round(self.signal, 4),
                "check_rms_px": [[r if np.isfinite(r) else None for r in pair]
                                 for pair in self.rms],
                "fits": self.fits}


async def check_rig(rig: Any, object_points: np.ndarray, check_view: int | None,
                    capture: Callable[[int], Awaitable[Corners]]) -> RigCheck:
    """Check the cached `rig` against chessboard views captured by `capture(view)` (the
    module docstring): with a `check_view` views 0 and it, more of 1..CHECK_VIEWS-1 while
    none shows FOCAL_ERROR above the bound; without (an older cache file) views
    0..CHECK_VIEWS-1, of which view 0 and the most tilted must fit."""
    obj, bound = np.asarray(object_points, np.float64).reshape(-1, 3), fit_bound(rig)
    corners: dict[int, Corners] = {}

    async def signal_of(view: int) -> float:
        corners[view] = await capture(view)
        left = corners[view][0]
        return 0.0 if left is None else focal_signal(rig, obj, left)

    if check_view is None:
        signals = [await signal_of(view) for view in range(CHECK_VIEWS)]
        tilts = [-1.0 if left is None else board_tilt_deg(rig, obj, left)
                 for left, _ in corners.values()]
        views = [0, max(range(1, CHECK_VIEWS), key=lambda v: tilts[v])]
        signal = max(signals[v] for v in views)
        check = (f"{CHECK_VIEWS}-capture check (the cache file names no check view; view "
                 f"{views[1]} the most tilted, {tilts[views[1]]:.0f} deg)")
    else:
        views = [0, check_view]
        signal = max([await signal_of(view) for view in views])
        added = [v for v in range(1, CHECK_VIEWS) if v != check_view]
        while signal < bound and added:  # the station shows other board poses now
            views.append(added.pop(0))
            signal = max(signal, await signal_of(views[-1]))
        check = (f"{len(corners)}-capture check (view {check_view}, the cache's check view"
                 + ("" if len(views) == 2 else
                    f", shows too little: views {', '.join(map(str, views[2:]))} added")
                 + ")")
    rms = [(float("inf"), float("inf")) if left is None or right is None
           else view_fit(rig, obj, left, right) for left, right in (corners[v] for v in views)]
    return RigCheck(views, len(corners), rms, bound, signal, check)
