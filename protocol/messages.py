"""Every message of the zerocal wire protocol: pydantic models in one discriminated union.

The discriminator is the `kind` field. A request carries an `id` (chosen by the client,
unique per connection); its reply names it in `reply_to`. Events (`io_edge`) are pushed by
the server and answer nothing. `error` may answer any request (and carries `reply_to=None`
when the offending frame could not be parsed far enough to find its id).

Units follow docs/conventions.md: joint angles and offsets in radians (reported frame),
times in seconds. Images do not travel in JSON: a `capture_done` header describes them
(`ImageInfo`) and the pixels follow as binary attachments of the same frame, in order.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, TypeAdapter

PROTOCOL_VERSION = 1
"""Version negotiated by hello; a peer with another version is refused (version_mismatch)."""

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
JointVector = Annotated[list[FiniteFloat], Field(max_length=64)]
"""(n,) joint angles or offsets, radians, joint 1 first."""
RequestId = Annotated[int, Field(ge=0, le=2**53)]
Nonce = Annotated[str, Field(pattern=r"^[0-9a-f]{32,128}$")]
Digest = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]
ShortText = Annotated[str, Field(max_length=200)]
Text = Annotated[str, Field(max_length=4000)]
Bits = Annotated[list[bool], Field(max_length=1024)]
Pattern = Literal["target", "chessboard"]
ImageEncoding = Literal["raw", "png"]


class _Message(BaseModel):
    """Base of every message: unknown fields are refused; attachments ride alongside."""

    model_config = ConfigDict(extra="forbid")
    kind: str
    _attachments: tuple[bytes | memoryview, ...] = PrivateAttr(default=())

    @property
    def attachments(self) -> tuple[bytes | memoryview, ...]:
        """Binary attachments sent in the same frame (empty for most messages)."""
        return self._attachments

    def with_attachments(self, *attachments: bytes | memoryview) -> _Message:
        """Attach binary payloads (not copied); returns self for chaining."""
        self._attachments = tuple(attachments)
        return self

    def expected_attachments(self) -> int:
        """How many attachments a frame carrying this message must have."""
        return 0


class Request(_Message):
    """A client-to-server message that expects exactly one reply naming its `id`."""

    id: RequestId
    read_only: ClassVar[bool] = False
    """True if the request is allowed before auth: a cheap read that neither moves the robot
    nor writes state (`capture` is a read but not cheap, so it needs auth)."""


class Reply(_Message):
    """A server-to-client answer to the request whose id is `reply_to`."""

    reply_to: RequestId


# --- handshake -----------------------------------------------------------------------------


class Hello(Request):
    """First message of a connection: protocol version and the client's auth nonce."""

    kind: Literal["hello"] = "hello"
    protocol_version: int
    client_name: ShortText = "zerocal"
    client_nonce: Nonce


class HelloReply(Reply):
    """Version accepted; the server's nonce for the HMAC challenge-response."""

    kind: Literal["hello_reply"] = "hello_reply"
    protocol_version: int
    server_name: ShortText
    robot_name: ShortText
    server_nonce: Nonce


class Auth(Request):
    """Proof of the shared token: hex HMAC-SHA256 (protocol.auth.client_proof)."""

    kind: Literal["auth"] = "auth"
    proof: Digest


class AuthReply(Reply):
    """Session authenticated; the server proves it knows the token too (mutual auth)."""

    kind: Literal["auth_reply"] = "auth_reply"
    server_proof: Digest


# --- state and IO --------------------------------------------------------------------------


class GetState(Request):
    """Ask for the controller state."""

    kind: Literal["get_state"] = "get_state"
    read_only: ClassVar[bool] = True


class State(Reply):
    """Controller state. Angles in rad (reported frame); limits are (lower, upper) per joint.

    mode: "idle", "moving" (a motion is in progress) or "estop".
    camera: what the controller reports of its stereo camera (image size, nominal mount).
    """

    kind: Literal["state"] = "state"
    robot_name: ShortText
    n_joints: int
    mode: Literal["idle", "moving", "estop"]
    time: FiniteFloat
    q: JointVector
    zero_offsets: JointVector
    q_min: JointVector
    q_max: JointVector
    digital_inputs: Bits
    digital_outputs: Bits
    camera: dict[str, Any]
    authenticated: bool


class ReadIo(Request):
    """Read the digital inputs and outputs."""

    kind: Literal["read_io"] = "read_io"
    read_only: ClassVar[bool] = True


class IoState(Reply):
    """Digital inputs and outputs (line 0 first) at sim time `time`."""

    kind: Literal["io_state"] = "io_state"
    digital_inputs: Bits
    digital_outputs: Bits
    time: FiniteFloat


class IoEdge(_Message):
    """Event pushed to authenticated clients when a digital input changes.

    q_latched: (n,) reported joint angles latched at the edge (rad).
    """

    kind: Literal["io_edge"] = "io_edge"
    line: int
    value: bool
    time: FiniteFloat
    q_latched: JointVector


# --- motion --------------------------------------------------------------------------------


class MoveJoints(Request):
    """Move to joint angles q (rad) at `speed`, a fraction (0, 1] of the maximum speed."""

    kind: Literal["move_joints"] = "move_joints"
    q: JointVector
    speed: Annotated[float, Field(gt=0.0, le=1.0)]


class MoveDone(Reply):
    """Motion finished: completed, or stopped early with `reason` (e.g. "aborted", "estop").

    q: (n,) reported angles where the robot stopped; duration_s: simulated motion time.
    """

    kind: Literal["move_done"] = "move_done"
    completed: bool
    q: JointVector
    duration_s: FiniteFloat
    reason: ShortText | None = None


class GuardedMove(Request):
    """Move toward q (rad) until a rising edge on digital input `io_line`."""

    kind: Literal["guarded_move"] = "guarded_move"
    q: JointVector
    speed: Annotated[float, Field(gt=0.0, le=1.0)]
    io_line: Annotated[int, Field(ge=0, le=1023)]


class GuardedMoveDone(Reply):
    """Guarded move finished. contact=False means "no contact" at the end of travel.

    q_latched: (n,) angles latched at the edge (None without contact); q: where it stopped;
    speed_mps: tip speed at contact (m/s) if known.
    """

    kind: Literal["guarded_move_done"] = "guarded_move_done"
    contact: bool
    q_latched: JointVector | None
    q: JointVector
    io_line: int
    duration_s: FiniteFloat
    speed_mps: FiniteFloat | None = None
    reason: ShortText | None = None


class Abort(Request):
    """Stop the motion in progress (any client's). Needs an authenticated session: an
    anonymous peer must not be able to stop a calibration (the operator's own session and
    the controller's e-stop remain the safety stop)."""

    kind: Literal["abort"] = "abort"


class Aborted(Reply):
    """`was_moving` says whether a motion was actually stopped."""

    kind: Literal["aborted"] = "aborted"
    was_moving: bool


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


class MeasureTargets(Request):
    """Measure every target the controller's camera sees now, already triangulated.

    For a controller whose vision front end delivers points instead of images (the
    humanoid's head camera, dual_loop). Needs an authenticated session, like `capture`.
    """

    kind: Literal["measure_targets"] = "measure_targets"


class TargetObservation(BaseModel):
    """One triangulated target: `chain` names the kinematic chain that carries it (e.g.
    "left", "right"); p: (3,) m in the camera (left optical) frame; cov: (3, 3) m^2."""

    model_config = ConfigDict(extra="forbid")
    chain: ShortText
    p: Vector3
    cov: Matrix3


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


class GetOffsets(Request):
    """Read the controller's joint zero offsets."""

    kind: Literal["get_offsets"] = "get_offsets"
    read_only: ClassVar[bool] = True


class Offsets(Reply):
    """Current zero offsets (rad): q_reported = encoder + offset."""

    kind: Literal["offsets"] = "offsets"
    offsets: JointVector


class SetOffsets(Request):
    """Write all zero offsets (rad). Refused beyond the controller's offset limit."""

    kind: Literal["set_offsets"] = "set_offsets"
    offsets: JointVector


class OffsetsSet(Reply):
    """Offsets written: `previous` ones and the `rollback_id` that restores them."""

    kind: Literal["offsets_set"] = "offsets_set"
    offsets: JointVector
    previous: JointVector
    rollback_id: ShortText


class RollbackOffsets(Request):
    """Restore the offsets that were in force before the write `rollback_id`."""

    kind: Literal["rollback_offsets"] = "rollback_offsets"
    rollback_id: ShortText


class OffsetsRolledBack(Reply):
    """Offsets restored to `offsets`; `replaced` is what was in force before the rollback."""

    kind: Literal["offsets_rolled_back"] = "offsets_rolled_back"
    offsets: JointVector
    replaced: JointVector


# --- liveness and errors -------------------------------------------------------------------


class Heartbeat(Request):
    """Liveness check; cheap, allowed in any state after hello."""

    kind: Literal["heartbeat"] = "heartbeat"
    read_only: ClassVar[bool] = True


class HeartbeatReply(Reply):
    """Alive; `time` is the controller's simulated clock (s)."""

    kind: Literal["heartbeat_reply"] = "heartbeat_reply"
    time: FiniteFloat


class ErrorReply(_Message):
    """A request failed or the peer broke the protocol.

    code: an `ErrorCode` value; reason: the controller's specific reason for `refused`
    (e.g. "joint_limit", "offset_limit", "estop", "refused_fault"); reply_to: the request
    id, or None when the offending frame had no readable id.
    """

    kind: Literal["error"] = "error"
    reply_to: RequestId | None = None
    code: ShortText
    message: Text
    reason: ShortText | None = None


Message = Annotated[
    Hello
    | HelloReply
    | Auth
    | AuthReply
    | GetState
    | State
    | ReadIo
    | IoState
    | IoEdge
    | MoveJoints
    | MoveDone
    | GuardedMove
    | GuardedMoveDone
    | Abort
    | Aborted
    | Capture
    | CaptureDone
    | MeasureTargets
    | TargetsMeasured
    | MeasureTracker
    | TrackerMeasured
    | GetOffsets
    | Offsets
    | SetOffsets
    | OffsetsSet
    | RollbackOffsets
    | OffsetsRolledBack
    | Heartbeat
    | HeartbeatReply
    | ErrorReply,
    Field(discriminator="kind"),
]
"""Any message; parse with `MESSAGE_ADAPTER.validate_json(header)`."""

MESSAGE_ADAPTER: TypeAdapter[Any] = TypeAdapter(Message)

REQUEST_TYPES: dict[str, type[Request]] = {
    cls.model_fields["kind"].default: cls
    for cls in (
        Hello,
        Auth,
        GetState,
        ReadIo,
        MoveJoints,
        GuardedMove,
        Abort,
        Capture,
        MeasureTargets,
        MeasureTracker,
        GetOffsets,
        SetOffsets,
        RollbackOffsets,
        Heartbeat,
    )
}
"""Request kind -> model."""

REPLY_KIND: dict[str, str] = {
    "hello": "hello_reply",
    "auth": "auth_reply",
    "get_state": "state",
    "read_io": "io_state",
    "move_joints": "move_done",
    "guarded_move": "guarded_move_done",
    "abort": "aborted",
    "capture": "capture_done",
    "measure_targets": "targets_measured",
    "measure_tracker": "tracker_measured",
    "get_offsets": "offsets",
    "set_offsets": "offsets_set",
    "rollback_offsets": "offsets_rolled_back",
    "heartbeat": "heartbeat_reply",
}
"""Request kind -> the kind of its success reply (any request may also get `error`)."""

EVENT_KINDS: frozenset[str] = frozenset({"io_edge"})
"""Server-pushed messages that answer no request."""

READ_ONLY_KINDS: frozenset[str] = frozenset(
    kind for kind, cls in REQUEST_TYPES.items() if cls.read_only
)
"""Requests allowed in a session that has said hello but not authenticated."""
