"""A stereo pair of OpenCV cameras: near-simultaneous capture, timestamps, skew, stale frames.

`StereoCamera.capture()` grabs both cameras first and only then retrieves (decodes) the two
frames, as OpenCV recommends for multi-camera capture: the two exposures are as close as
the backend allows, and the slow part (decoding, colour conversion) comes after both.

Every pair carries, per camera, the host clock (`time.monotonic()`, s) at the middle of its
grab and the backend's own timestamp (`CAP_PROP_POS_MSEC` / 1000, s: the V4L2 buffer time
for a live camera, the media time for a file); `skew_s` is right minus left, from the
backend timestamps for live cameras that report them, else from the host grab times.

A camera that delivers no frame, the same image as last time, or a backend timestamp that
does not advance raises `CameraError` (one line, exit code 3): a frozen camera must never
pass an old image off as the pose the robot is at now.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.sensors.sources import CameraError, CameraSource, apply_controls, open_source

CAMERAS = ("left", "right")


@dataclass(frozen=True)
class StereoPair:
    """left, right: (H, W) uint8 grey images; t_left / t_right: host clock (s) at each grab;
    stamp_left / stamp_right: backend timestamps (s, 0 when the backend reports none);
    skew_s: right minus left exposure time (s); index: 0-based capture count."""

    left: np.ndarray
    right: np.ndarray
    t_left: float
    t_right: float
    stamp_left: float
    stamp_right: float
    skew_s: float
    index: int

    def timing(self) -> dict[str, float | int]:
        """The timing as a JSON-ready mapping (for logs and recordings)."""
        return {"index": self.index, "t_left": self.t_left, "t_right": self.t_right,
                "stamp_left": self.stamp_left, "stamp_right": self.stamp_right,
                "skew_s": self.skew_s}


class StereoCamera:
    """Two open VideoCaptures. sources: (left SOURCE, right SOURCE) texts; exposure / gain
    in backend units (None: leave as is); max_skew_s: refuse a pair of live cameras whose
    |skew| exceeds it (None: no limit; files are read one after the other, their skew is
    reported but not refused); discard: pairs grabbed and dropped before each capture, so
    that no frame exposed before the robot stopped is used (None: 1 for live cameras, whose
    driver may hold a frame in its buffer, 0 for files). Close with `close()` (or use as a
    context manager)."""

    def __init__(self, left: str, right: str, *, exposure: float | None = None,
                 gain: float | None = None, max_skew_s: float | None = None,
                 discard: int | None = None) -> None:
        self._captures: list[Any] = []
        self.sources: list[CameraSource] = []
        self.refused_controls: dict[str, list[str]] = {}
        try:
            for camera, text in zip(CAMERAS, (left, right), strict=True):
                capture, source = open_source(text, camera)
                self._captures.append(capture)
                self.sources.append(source)
                refused = apply_controls(capture, exposure, gain)
                if refused:
                    self.refused_controls[camera] = refused
        except BaseException:
            self.close()
            raise
        self.max_skew_s = max_skew_s
        live = all(source.live for source in self.sources)
        self.discard = (1 if live else 0) if discard is None else max(0, int(discard))
        self._count = 0
        self._previous: list[np.ndarray | None] = [None, None]
        self._previous_stamp: list[float | None] = [None, None]

    def __enter__(self) -> StereoCamera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release both cameras (safe to call twice)."""
        for capture in self._captures:
            capture.release()
        self._captures = []

    def capture(self) -> StereoPair:
        """Grab both, then retrieve both; checks (see the module docstring). Blocking."""
        import cv2

        if len(self._captures) != 2:
            raise CameraError("stereo camera is closed")
        for _ in range(self.discard):
            for camera, capture in zip(CAMERAS, self._captures, strict=True):
                if not capture.grab():
                    raise CameraError(f"{camera} camera: no frame (capture {self._count})")
        host_times: list[float] = []
        for camera, capture in zip(CAMERAS, self._captures, strict=True):
            before = time.monotonic()
            grabbed = capture.grab()
            after = time.monotonic()
            if not grabbed:
                raise CameraError(f"{camera} camera: no frame (capture {self._count}; "
                                  "unplugged, or the end of a file source)")
            host_times.append(0.5 * (before + after))
        images: list[np.ndarray] = []
        stamps: list[float] = []
        for camera, capture in zip(CAMERAS, self._captures, strict=True):
            ok, image = capture.retrieve()
            if not ok or image is None:
                raise CameraError(f"{camera} camera: frame {self._count} cannot be decoded")
            images.append(_grey(image, cv2))
            stamps.append(float(capture.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0)
        for k, camera in enumerate(CAMERAS):
            self._check_fresh(k, camera, images[k], stamps[k])
        live = all(s.live for s in self.sources)
        if live and stamps[0] > 0 and stamps[1] > 0:  # V4L2 buffer times, one kernel clock
            skew = stamps[1] - stamps[0]
        else:
            skew = host_times[1] - host_times[0]
        if live and self.max_skew_s is not None and abs(skew) > self.max_skew_s:
            raise CameraError(f"stereo skew {skew * 1e3:.2f} ms at capture {self._count} "
                              f"exceeds the budget {self.max_skew_s * 1e3:.2f} ms")
        pair = StereoPair(images[0], images[1], host_times[0], host_times[1], stamps[0],
                          stamps[1], float(skew), self._count)
        self._count += 1
        return pair

    def _check_fresh(self, k: int, camera: str, image: np.ndarray, stamp: float) -> None:
        previous, previous_stamp = self._previous[k], self._previous_stamp[k]
        if previous is not None and previous.shape == image.shape and \
                np.array_equal(previous, image):
            raise CameraError(f"{camera} camera: frozen frame (capture {self._count} is the "
                              "same image as the one before)")
        if previous_stamp is not None and stamp > 0 and stamp <= previous_stamp:
            raise CameraError(f"{camera} camera: stale frame (timestamp {stamp:.6f} s does "
                              f"not advance past {previous_stamp:.6f} s)")
        self._previous[k] = image
        self._previous_stamp[k] = stamp


def _grey(image: np.ndarray, cv2: Any) -> np.ndarray:
    """(H, W) uint8 from whatever the backend decoded (grey, BGR, BGRA; 16 bit scaled)."""
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    return np.ascontiguousarray(image, dtype=np.uint8)
