"""Measurement messages: camera capture, controller-triangulated targets, laser tracker, and
the generic `sensor_read` of any other instrument.

Images do not travel in JSON: a `capture_done` header describes them (`ImageInfo`) and the
pixels follow as binary attachments of the same frame, in order. Units: m, m^2, rad, s.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

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


# --- any other instrument (a measurement kind's own simulated sensor) ---------------------

MAX_SENSOR_NODES = 4096
"""Most values (numbers, strings, booleans, nulls, arrays and objects, each counted) a
`sensor_read` request or reading may hold: an instrument's reading is a few numbers, never
a bulk transfer (images travel as `capture` attachments)."""
MAX_SENSOR_STRING = 1000
"""Longest string (characters) in a sensor request or reading, keys included."""

SensorName = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,63}$")]
"""A simulated or real instrument's name (the measurement kind's, e.g. `string_pot`)."""


def _bounded_json(document: dict[str, Any]) -> dict[str, Any]:
    """`document` if it is a small JSON object: at most MAX_SENSOR_NODES values, strings and
    keys of at most MAX_SENSOR_STRING characters, finite numbers; ValueError otherwise.
    (Its depth is already bounded by the header's MAX_JSON_DEPTH.)"""
    stack: list[Any] = [document]
    nodes = 0
    while stack:
        value = stack.pop()
        nodes += 1
        if nodes > MAX_SENSOR_NODES:
            raise ValueError(f"more than {MAX_SENSOR_NODES} values")
        if isinstance(value, dict):
            for key, item in value.items():
                if len(key) > MAX_SENSOR_STRING:
                    raise ValueError(f"a key longer than {MAX_SENSOR_STRING} characters")
                stack.append(item)
        elif isinstance(value, list):
            stack.extend(value)
        elif isinstance(value, str):
            if len(value) > MAX_SENSOR_STRING:
                raise ValueError(f"a string longer than {MAX_SENSOR_STRING} characters")
        elif isinstance(value, float):
            if not math.isfinite(value):
                raise ValueError("a number that is not finite")
        elif not (value is None or isinstance(value, bool | int)):
            raise ValueError(f"a {type(value).__name__}, not a JSON value")
    return document


SensorDocument = Annotated[dict[str, Any], AfterValidator(_bounded_json)]
"""A sensor's request or reading: a small JSON object whose shape is the instrument's own
contract (the kind's method and its simulated sensor agree on it; the protocol only bounds
it)."""


class SensorRead(Request):
    """Ask the instrument `sensor` for a reading; `request` says what to read, in the
    instrument's own terms (e.g. `{"what": "length", "average": 4}`).

    Needs an authenticated session, like `capture`. A controller without that instrument
    refuses with reason `unsupported`; a request the instrument cannot read is answered
    with `bad_message` and the instrument's reason.
    """

    kind: Literal["sensor_read"] = "sensor_read"
    sensor: SensorName
    request: SensorDocument = {}


class SensorReading(Reply):
    """The instrument's `reading` (its own JSON contract), with the joint angles q (n,) rad
    at the reading and controller time (s)."""

    kind: Literal["sensor_reading"] = "sensor_reading"
    sensor: SensorName
    q: JointVector
    time: FiniteFloat
    reading: SensorDocument
