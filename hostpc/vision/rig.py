"""The calibrated stereo rig as a value, and its JSON file.

Frames (docs/conventions.md): the left camera's optical frame (x right, y down, z forward,
OpenCV) is the rig frame. `R`, `T` follow OpenCV's stereoCalibrate: a point `x_left` in the
left camera frame is `x_right = R @ x_left + T` in the right camera frame, so the right
camera's centre is at `-R.T @ T` in the left frame and the baseline is `|T|` (m).
Pixels: (0, 0) is the centre of the top-left pixel.

File format (JSON, SI units)::

    {"format": "zerocal-stereo-rig", "version": 1,
     "image_size": [w, h], "K_left": 3x3, "dist_left": [k1, k2, p1, p2, k3, ...],
     "K_right": 3x3, "dist_right": [...], "R": 3x3, "T": [tx, ty, tz],
     "rms": px, "n_views": int}
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.input_files import RIG, read_input_text
from hostpc.json_object import JsonObject

RIG_FORMAT = "zerocal-stereo-rig"
RIG_VERSION = 1


def _frozen(array: Any, shape: tuple[int, ...] | None, name: str) -> np.ndarray:
    """A read-only float64 copy of `array`, checked against `shape` (ValueError names it)."""
    out = np.array(array, dtype=float, copy=True)
    if shape is not None and out.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name}: non-finite value")
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class StereoRig:
    """Intrinsics and extrinsics of a calibrated stereo pair.

    image_size: (w, h) pixels of both cameras.
    K_left, K_right: (3, 3) camera matrices (px).
    dist_left, dist_right: (k,) OpenCV distortion coefficients (k1, k2, p1, p2, k3[, ...]).
    R: (3, 3), T: (3,) m, x_right = R @ x_left + T (OpenCV stereoCalibrate).
    rms: reprojection RMS of the calibration (px); n_views: chessboard views used.
    covariance: (24, 24) covariance of the rig parameters from its calibration, in the order
    of `hostpc.vision.rig_uncertainty.RIG_PARAMETERS`, or None (unknown: a rig file without
    it). It is not part of the fingerprint.

    Arrays are stored read-only; equality is identity (use `fingerprint()` to compare).
    """

    image_size: tuple[int, int]
    K_left: np.ndarray
    dist_left: np.ndarray
    K_right: np.ndarray
    dist_right: np.ndarray
    R: np.ndarray
    T: np.ndarray
    rms: float = 0.0
    n_views: int = 0
    covariance: np.ndarray | None = None
    #: its ``hostpc.vision.rectification.Rectification``, computed on the first
    #: ``rectification_for(rig)`` and kept with the rig (a rig is immutable)
    rectification: object | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size: expected positive (w, h), got {self.image_size}")
        object.__setattr__(self, "image_size", (w, h))
        for name, shape in (("K_left", (3, 3)), ("K_right", (3, 3)), ("R", (3, 3))):
            object.__setattr__(self, name, _frozen(getattr(self, name), shape, name))
        object.__setattr__(self, "T", _frozen(np.ravel(self.T), (3,), "T"))
        for name in ("dist_left", "dist_right"):
            dist = _frozen(np.ravel(getattr(self, name)), None, name)
            if dist.size not in (4, 5, 8, 12, 14):
                raise ValueError(f"{name}: expected 4, 5, 8, 12 or 14 coefficients")
            object.__setattr__(self, name, dist)
        if abs(np.linalg.det(self.R) - 1.0) > 1e-6:
            raise ValueError("R: not a rotation matrix (det != 1)")
        if np.linalg.norm(self.T) <= 0.0:
            raise ValueError("T: zero baseline")
        if self.covariance is not None:
            cov = _frozen(self.covariance, (24, 24), "covariance")
            if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0) or np.any(np.diag(cov) < 0):
                raise ValueError("covariance: not a symmetric positive semi-definite matrix")
            object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "rms", float(self.rms))
        object.__setattr__(self, "n_views", int(self.n_views))

    @property
    def baseline(self) -> float:
        """Distance between the two camera centres (m)."""
        return float(np.linalg.norm(self.T))

    @property
    def T_left_right(self) -> np.ndarray:
        """(4, 4) pose of the right camera in the left camera frame (conventions.md)."""
        T = np.eye(4)
        T[:3, :3] = self.R.T
        T[:3, 3] = -self.R.T @ self.T
        return T

    def fingerprint(self) -> str:
        """A short hash of every parameter (to compare two rigs)."""
        digest = hashlib.sha1(repr(self.image_size).encode())
        for a in (self.K_left, self.dist_left, self.K_right, self.dist_right, self.R, self.T):
            digest.update(np.ascontiguousarray(a).tobytes())
        return digest.hexdigest()[:16]

    def to_dict(self) -> JsonObject:
        """JSON-serialisable mapping in the file format of the module docstring."""
        return {
            "format": RIG_FORMAT,
            "version": RIG_VERSION,
            "image_size": list(self.image_size),
            "K_left": self.K_left.tolist(),
            "dist_left": self.dist_left.tolist(),
            "K_right": self.K_right.tolist(),
            "dist_right": self.dist_right.tolist(),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "rms": self.rms,
            "n_views": self.n_views,
            **({} if self.covariance is None else {"covariance": self.covariance.tolist()}),
        }


def rig_from_dict(data: Any, source: str = "<rig>") -> StereoRig:
    """Validate a mapping (file format above) into a StereoRig.

    Raises InputError with one line naming `source` and the offending field.
    """
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a JSON object, got {type(data).__name__}")
    if data.get("format") != RIG_FORMAT:
        raise InputError(f"{source}: format: expected {RIG_FORMAT!r}, got {data.get('format')!r}")
    if data.get("version") != RIG_VERSION:
        raise InputError(f"{source}: version: expected {RIG_VERSION}, got {data.get('version')!r}")
    fields: dict[str, Any] = {}
    for name in ("image_size", "K_left", "dist_left", "K_right", "dist_right", "R", "T"):
        if name not in data:
            raise InputError(f"{source}: {name}: missing")
        try:
            fields[name] = np.asarray(data[name], dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{source}: {name}: not a numeric array") from None
    size = fields["image_size"]
    if size.shape != (2,) or np.any(size != np.round(size)):
        raise InputError(f"{source}: image_size: expected two integers [w, h]")
    for name in ("rms", "n_views"):
        value = data.get(name, 0)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
            value
        ):
            raise InputError(f"{source}: {name}: expected a number, got {value!r}")
        fields[name] = value
    fields["image_size"] = (int(size[0]), int(size[1]))
    if data.get("covariance") is not None:
        try:
            fields["covariance"] = np.asarray(data["covariance"], dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{source}: covariance: not a numeric array") from None
    try:
        rig = StereoRig(**fields)
    except ValueError as exc:
        raise InputError(f"{source}: {exc}") from None
    for name in ("K_left", "K_right"):
        K = getattr(rig, name)
        if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
            raise InputError(f"{source}: {name}: focal lengths must be positive and finite, "
                             f"got fx {K[0, 0]}, fy {K[1, 1]}")
    if not (np.all(np.isfinite(rig.T)) and float(np.linalg.norm(rig.T)) > 0):
        raise InputError(f"{source}: T: the baseline must be non-zero and finite")
    return rig


def save_rig(rig: StereoRig, path: str | Path, extra: JsonObject | None = None) -> None:
    """Write `rig` as JSON to `path` atomically (a crash never leaves half a rig file;
    InputError if the file cannot be written), with the fields of `extra` beside it (a
    rig cache's check view: hostpc/kinds/stereo_target/rig_cache.py)."""
    from hostpc.files import write_text_atomic

    path = Path(path)
    try:
        write_text_atomic(path, json.dumps({**rig.to_dict(), **(extra or {})}, indent=2)
                          + "\n")
    except OSError as exc:
        raise InputError(f"{path}: cannot write rig file ({exc.strerror})") from None


def load_rig(path: str | Path) -> StereoRig:
    """Read a rig JSON file; InputError (one line naming the file and field) on any problem."""
    return rig_from_dict(rig_document(path), str(path))


def rig_document(path: str | Path) -> Any:
    """The parsed JSON of a rig file, not yet checked (`rig_from_dict` checks it); InputError
    naming the file if it cannot be read or is not JSON."""
    path = Path(path)
    text = read_input_text(path, RIG)  # a regular file within the rig size limit
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
