"""Camera sources: the SOURCE text of `--camera-left` / `--left` -> an open cv2.VideoCapture.

    0, 1, ...                 a device index (V4L2 on Linux)
    /dev/video0               a V4L2 device path
    "v4l2src ! ... ! appsink" a GStreamer pipeline (any text containing " ! "; needs an
                              OpenCV built with GStreamer)
    left_%04d.png             an image sequence (printf pattern, numbered from 0..4 on)
    session.mkv               a video file

A source that does not open raises `CameraError` (exit code 3) naming the camera and the
source. Exposure and gain are set where the backend allows; `apply_controls` returns the
controls the backend refused (a warning, not an error: many webcams ignore them).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hostpc.errors import ConnectionFailed


class CameraError(ConnectionFailed):
    """A camera does not open, delivers no frame, or delivers a stale (frozen) frame."""

    exit_code = 3


@dataclass(frozen=True)
class CameraSource:
    """A parsed SOURCE. kind: "device" | "v4l2" | "gstreamer" | "sequence" | "file";
    target: the device index (int) or the text handed to VideoCapture."""

    text: str
    kind: str
    target: int | str

    @property
    def live(self) -> bool:
        """True for a camera (its backend timestamps are capture times), False for files."""
        return self.kind in ("device", "v4l2", "gstreamer")


def parse_source(text: str) -> CameraSource:
    """SOURCE text -> CameraSource (see the module docstring)."""
    stripped = text.strip()
    if stripped.isdigit():
        return CameraSource(text, "device", int(stripped))
    if " ! " in stripped or stripped.endswith("appsink") or "appsink " in stripped:
        return CameraSource(text, "gstreamer", stripped)
    if stripped.startswith("/dev/"):
        return CameraSource(text, "v4l2", stripped)
    if "%" in stripped:
        return CameraSource(text, "sequence", stripped)
    return CameraSource(text, "file", stripped)


def open_source(text: str, camera: str) -> tuple[Any, CameraSource]:
    """Open SOURCE for `camera` ("left" / "right") -> (cv2.VideoCapture, CameraSource).

    Raises CameraError with one line naming the camera and the source if it does not open.
    """
    import cv2

    source = parse_source(text)
    if source.kind == "file" and not Path(source.target).is_file():  # type: ignore[arg-type]
        raise CameraError(f"{camera} camera: {text!r} does not open (no such file)")
    if source.kind == "sequence" and not _sequence_start(str(source.target)):
        raise CameraError(f"{camera} camera: {text!r} does not open (no image of the "
                          "sequence numbered 0..4)")
    if source.kind == "gstreamer" and "GStreamer:                   YES" not in \
            cv2.getBuildInformation():
        raise CameraError(f"{camera} camera: {text!r} is a GStreamer pipeline but this "
                          "OpenCV was built without GStreamer")
    api = {"v4l2": cv2.CAP_V4L2, "gstreamer": cv2.CAP_GSTREAMER}.get(source.kind, cv2.CAP_ANY)
    if source.kind == "device":
        api = cv2.CAP_V4L2 if Path("/dev").is_dir() else cv2.CAP_ANY
    previous_level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # the one line below
    try:
        capture = cv2.VideoCapture(source.target, api)
    finally:
        cv2.utils.logging.setLogLevel(previous_level)
    if not capture.isOpened():
        capture.release()
        raise CameraError(f"{camera} camera: {text!r} does not open ({source.kind})")
    if source.live:
        capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not a queued one
    return capture, source


def _sequence_start(pattern: str) -> bool:
    """True if the printf pattern names an existing file for an index in 0..4 (what
    OpenCV's image-sequence readers look for)."""
    for index in range(5):
        try:
            name = pattern % index
        except (TypeError, ValueError):
            return False
        if Path(name).is_file():
            return True
    return False


def apply_controls(capture: Any, exposure: float | None, gain: float | None) -> list[str]:
    """Set exposure (backend units: V4L2 exposure_absolute is 100 us steps) and gain on an
    open capture; returns the names of the controls the backend refused."""
    import cv2

    refused = []
    if exposure is not None:
        capture.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # V4L2: manual exposure
        if not capture.set(cv2.CAP_PROP_EXPOSURE, float(exposure)):
            refused.append("exposure")
    if gain is not None and not capture.set(cv2.CAP_PROP_GAIN, float(gain)):
        refused.append("gain")
    return refused
