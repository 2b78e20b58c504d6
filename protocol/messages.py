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

from pydantic import Field, TypeAdapter

from protocol.measurement_messages import (
    Capture,
    CaptureDone,
    MeasureTargets,
    MeasureTracker,
    SensorRead,
    SensorReading,
    TargetsMeasured,
    TrackerMeasured,
)
from protocol.message_base import (
    Bits,
    Digest,
    FiniteFloat,
    JointVector,
    Nonce,
    Reply,
    Request,
    RequestId,
    ShortText,
    Text,
    _Message,
)


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
    max_joint_speed: (n,) rad/s, each joint's speed at speed fraction 1, when the controller
    reports it (the host plans robot time with it; absent: a UR's 180 deg/s).
    max_joint_acceleration: (n,) rad/s^2, each joint's acceleration in every move (a move
    ramps up to its speed and down to rest: a trapezoidal velocity profile), when the
    controller reports it (absent: a UR's default movej acceleration, 1.4 rad/s^2).
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
    max_joint_speed: JointVector | None = None
    max_joint_acceleration: JointVector | None = None


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
    | SensorRead
    | SensorReading
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
        SensorRead,
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
    "sensor_read": "sensor_reading",
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
