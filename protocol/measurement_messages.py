"""Measurement messages: camera capture, controller-triangulated targets, laser tracker.

Images do not travel in JSON: a `capture_done` header describes them (`ImageInfo`) and the
pixels follow as binary attachments of the same frame, in order. Units: m, m^2, rad, s.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from protocol.message_base import (
    FiniteFloat,
    ImageEncoding,
    JointVector,
    Pattern,
    Reply,
    Request,
    ShortText,
)

# --- camera --------------------------------------------------------------------------------


class Capture(Request):
    """Expose the stereo pair: pattern "target" or "chessboard" (view index for the latter).

    Needs an authenticated session: rendering and sending megabytes of pixels is the most
    expensive thing a controller does, so it is not offered to anonymous peers.
    """

    kind: Literal["capture"] = "capture"
    pattern: Pattern = "target"
    view: Annotated[int, Field(ge=0)] = 0
    encoding: ImageEncoding = "raw"


class ImageInfo(BaseModel):
    """How to read one image attachment: raw is row-major uint8 (height, width); png is PNG."""

    model_config = ConfigDict(extra="forbid")
    camera: Literal["left", "right"]
    width: Annotated[int, Field(ge=1, le=65535)]
    height: Annotated[int, Field(ge=1, le=65535)]
    dtype: Literal["uint8"] = "uint8"
    encoding: ImageEncoding = "raw"
    nbytes: Annotated[int, Field(ge=0)]


class CaptureDone(Reply):
    """A stereo pair: `images` describes the attachments (left, right), in order.

    q: (n,) reported joint angles at the exposure (rad); time: sim time of the exposure (s).
    """

    kind: Literal["capture_done"] = "capture_done"
    pattern: Pattern
    view: int
    q: JointVector
    time: FiniteFloat
    images: Annotated[list[ImageInfo], Field(min_length=2, max_length=2)]

    def expected_attachments(self) -> int:
        """One attachment per image."""
        return len(self.images)


# --- measured targets (a controller with its own stereo front end) --------------------------


Vector3 = Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]
Matrix3 = Annotated[list[Vector3], Field(min_length=3, max_length=3)]
Vector2 = Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)]
Matrix2 = Annotated[list[Vector2], Field(min_length=2, max_length=2)]


class MeasureTargets(Request):
    """Measure every target the controller's camera sees now, already triangulated.

    For a controller whose vision front end delivers points instead of images (the
    humanoid's head camera, dual_loop). Needs an authenticated session, like `capture`.
    """

    kind: Literal["measure_targets"] = "measure_targets"


class TargetObservation(BaseModel):
    """One triangulated target: `chain` names the kinematic chain that carries it (e.g.
    "left", "right"); p: (3,) m in the camera (left optical) frame; cov: (3, 3) m^2;
    uv (optional): the pixel centres [[u_l, v_l], [u_r, v_r]] (px) it was triangulated from,
    so the host can propagate the camera calibration's covariance (docs/vision.md)."""

    model_config = ConfigDict(extra="forbid")
    chain: ShortText
    p: Vector3
    cov: Matrix3
    uv: Matrix2 | None = None


class TargetsMeasured(Reply):
    """The visible targets (none if nothing is in view), with the joint angles at the
    measurement: q (n,) rad, all joints of the controller; time: controller time (s)."""

    kind: Literal["targets_measured"] = "targets_measured"
    q: JointVector
    time: FiniteFloat
    targets: Annotated[list[TargetObservation], Field(max_length=64)]


# --- laser tracker (world_point) ----------------------------------------------------------


class MeasureTracker(Request):
    """Measure every reflector on the flange with the cell's laser tracker, now.

    Needs an authenticated session, like `capture`. A controller without a tracker refuses
    with reason `unsupported`.
    """

    kind: Literal["measure_tracker"] = "measure_tracker"


class ReflectorObservation(BaseModel):
    """One reflector measured by the tracker: name; p: (3,) m in the tracker (world)
    frame; cov: (3, 3) m^2."""

    model_config = ConfigDict(extra="forbid")
    name: ShortText
    p: Vector3
    cov: Matrix3


class TrackerMeasured(Reply):
    """The reflectors in the tracker's view, the names of those whose beam is lost (line of
    sight outside their acceptance cone), the joint angles q (n,) rad at the measurement,
    controller time (s), and the tracker's nominal description (`world_base` {xyz, rpy}
    registration of the robot base, `reflectors` name -> (3,) nominal flange position,
    `axes`, `acceptance_deg`, `sigma_distance` m, `sigma_angle` rad)."""

    kind: Literal["tracker_measured"] = "tracker_measured"
    q: JointVector
    time: FiniteFloat
    reflectors: Annotated[list[ReflectorObservation], Field(max_length=64)]
    lost: Annotated[list[ShortText], Field(max_length=64)] = []
    description: dict[str, Any] = {}


# --- zero offsets --------------------------------------------------------------------------
