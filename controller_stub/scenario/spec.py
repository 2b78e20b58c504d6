"""Scenario files: the simulated world's configuration and hidden truth.

A scenario is YAML or JSON. Everything is SI (metres, radians, seconds) unless a field name
says otherwise (`random_deg`). Every field has a default, so `{}` is a valid scenario (the
UR5e with small random zero errors). Hidden values (zero errors, mount error, target error,
stylus/sphere errors, hidden effects) are only ever reported through `Simulation.truth()`.

Validation failures raise `ScenarioError` with one line that names the field, e.g.
`truth.backlash: expected 6 values for robot 'ur5e', got 5`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from controller_stub.scenario.tracker import TrackerSpec

RobotName = Literal["ur5e", "ur10e", "industrial6", "humanoid_upper"]

ROBOT_JOINTS: dict[str, int] = {"ur5e": 6, "ur10e": 6, "industrial6": 6,
                                "humanoid_upper": 16}  # head 2 + left 7 + right 7

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
NonNegative = Annotated[float, Field(ge=0.0)]


class ScenarioError(ValueError):
    """A scenario file is malformed; the message names the offending field."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class PoseSpec(_Model):
    """A rigid transform as translation (m) and roll-pitch-yaw (rad, conventions.md)."""

    xyz: Vec3 = [0.0, 0.0, 0.0]
    rpy: Vec3 = [0.0, 0.0, 0.0]


class RandomSpec(_Model):
    """Values drawn uniformly in +-random_deg degrees from the scenario seed."""

    random_deg: NonNegative


class LinkLengthSpec(_Model):
    """Per-joint deltas of the DH/MDH lengths d_i and a_i (m), or their rates (m/s)."""

    d: list[float] | None = None
    a: list[float] | None = None


class TruthSpec(_Model):
    """Hidden truth: zero errors and optional hidden physical effects.

    zero_errors: (n,) rad, physical = reported + zero_error (at the scenario's initial
        controller offsets), or a RandomSpec.
    joint_compliance: (n,) rad/Nm, dq_i = c_i * tau_i(q_phys).
    backlash: (n,) rad, dq_i = b_i * approach_i (approach +1 if the joint last moved in +).
    transmission_harmonic: (n, 4) [a1, b1, a2, b2] per joint, rad.
    encoder_scale: (n,) dq_i = s_i * q_reported_i.
    link_length_errors: d, a deltas (m), each (n,).
    thermal_drift: d, a growth rates (m/s of simulated time), each (n,).
    probe_trigger_latency_s: the joints are latched this late after the true contact.
    """

    zero_errors: list[float] | RandomSpec = RandomSpec(random_deg=0.5)
    joint_compliance: list[float] | None = None
    backlash: list[Annotated[float, Field(ge=0.0)]] | None = None
    transmission_harmonic: (
        list[Annotated[list[float], Field(min_length=4, max_length=4)]] | None
    ) = None
    encoder_scale: list[float] | None = None
    link_length_errors: LinkLengthSpec | None = None
    thermal_drift: LinkLengthSpec | None = None
    probe_trigger_latency_s: NonNegative = 0.0


class CameraSpec(_Model):
    """Stereo camera: truth intrinsics (pixels), rig and mount.

    The right camera sits at +baseline along the left camera's x axis, rotated by
    right_rpy relative to the left one (T_left_right = [R(right_rpy), (baseline, 0, 0)]).
    mount is the NOMINAL T_flange_leftcamera; mount_error is the hidden truth delta:
    T_true = T_nom @ [R(mount_error.rpy), mount_error.xyz].
    """

    image_width: Annotated[int, Field(ge=16, le=8192)] = 1280
    image_height: Annotated[int, Field(ge=16, le=8192)] = 1024
    fx: Annotated[float, Field(gt=0.0)] = 1400.0
    fy: Annotated[float, Field(gt=0.0)] = 1400.0
    cx: float = 641.3
    cy: float = 509.7
    distortion: Annotated[list[float], Field(min_length=5, max_length=5)] = [
        -0.08,
        0.05,
        0.0004,
        -0.0003,
        0.0,
    ]
    baseline: Annotated[float, Field(gt=0.0)] = 0.12
    right_rpy: Vec3 = [0.0015, -0.004, 0.001]
    mount: PoseSpec = PoseSpec(xyz=[0.0, -0.06, 0.04], rpy=[0.0, 0.0, 0.0])
    mount_error: PoseSpec = PoseSpec(xyz=[0.0012, -0.0008, 0.0015], rpy=[0.003, -0.002, 0.004])
    pixel_noise_sigma: NonNegative = 2.0
    blur_sigma: NonNegative = 0.7


class TargetSpec(_Model):
    """Circular dark dot on a bright plate, fixed in the base frame.

    centre: nominal centre in base (m); centre_error: hidden truth delta (m).
    normal: plate normal in base (facing the camera side). Grey levels 0..255.
    """

    centre: Vec3 = [0.45, 0.15, 0.0]
    centre_error: Vec3 = [0.0007, -0.0011, 0.0004]
    radius: Annotated[float, Field(gt=0.0)] = 0.01
    normal: Vec3 = [0.0, 0.0, 1.0]
    plate_radius: Annotated[float, Field(gt=0.0)] = 0.05
    dot_level: Annotated[float, Field(ge=0.0, le=255.0)] = 30.0
    plate_level: Annotated[float, Field(ge=0.0, le=255.0)] = 220.0
    background_level: Annotated[float, Field(ge=0.0, le=255.0)] = 120.0

    @model_validator(mode="after")
    def _check(self) -> TargetSpec:
        if self.plate_radius <= self.radius:
            raise ValueError("plate_radius must exceed radius")
        if math.hypot(*self.normal) < 1e-9:
            raise ValueError("normal must be non-zero")
        return self


class ChessboardSpec(_Model):
    """Chessboard for stereo rig calibration; views are poses relative to the LEFT camera."""

    cols: Annotated[int, Field(ge=3, le=40)] = 9
    rows: Annotated[int, Field(ge=3, le=40)] = 6
    square_size: Annotated[float, Field(gt=0.0)] = 0.025
    n_views: Annotated[int, Field(ge=1, le=500)] = 20
    distance_min: Annotated[float, Field(gt=0.0)] = 0.3
    distance_max: Annotated[float, Field(gt=0.0)] = 0.8
    max_tilt_deg: Annotated[float, Field(ge=0.0, le=70.0)] = 35.0
    views_seed: int | None = None
    """The seed the board poses are drawn with; None: the scenario's. A station that shows
    its camera the same board poses robot after robot: worlds sharing a views_seed."""
    dark_level: Annotated[float, Field(ge=0.0, le=255.0)] = 25.0
    light_level: Annotated[float, Field(ge=0.0, le=255.0)] = 230.0

    @model_validator(mode="after")
    def _check(self) -> ChessboardSpec:
        if self.distance_max < self.distance_min:
            raise ValueError("distance_max must be >= distance_min")
        return self


class ProbeSpec(_Model):
    """Touch probe (stylus on the flange) and reference sphere (fixed in base).

    tip: nominal stylus tip centre in the flange frame (m); tip_error: hidden delta.
    sphere_centre: nominal in base (m); sphere_centre_error: hidden delta.
    stop_time_s: how long the robot keeps moving at constant speed after the latched edge.
    """

    tip: Vec3 = [0.0, 0.0, 0.12]
    tip_error: Vec3 = [0.0004, -0.0003, 0.0006]
    stylus_radius: NonNegative = 0.0015
    sphere_centre: Vec3 = [0.45, -0.15, 0.05]
    sphere_centre_error: Vec3 = [-0.0005, 0.0008, 0.0003]
    sphere_radius: Annotated[float, Field(gt=0.0)] = 0.0125
    io_line: Annotated[int, Field(ge=0, le=15)] = 0
    repeatability_sigma: NonNegative = 1e-6
    stop_time_s: NonNegative = 0.01


class MotionSpec(_Model):
    """Joint limits (rad, reported frame; default per robot), speed and pacing.

    max_joint_speed: rad/s, a scalar or per joint (default per robot).
    max_joint_acceleration: rad/s^2, a scalar or per joint: every joint move ramps up to its
    speed and down to rest at it (a trapezoidal velocity profile, docs/simulator.md). The
    default 4.0 is a UR e-Series arm's with a light flange payload (a probe, a target);
    UR's own movej default is 1.4, which a UR host sends (the UR personality moves at the
    smaller of the two).
    time_scale: wall seconds per simulated second (0 = instantaneous).
    initial_q: (n,) reported start pose (default per robot).
    settle_s: simulated time the robot must have stood still since its last completed
    motion before it is measured (vibrations die out): charged at the measurement (a
    capture, a target measurement, a tracker or sensor reading, the start of a guarded
    move), as much of it as the robot has not stood still already; none after a move
    that a move follows (docs/simulator.md "Robot time").
    capture_s: simulated time of one stereo capture (exposure and readout of the pair),
    target measurement or laser tracker reading.
    Both advance the simulated clock (robot time), not the wall-time pacing of motions.
    """

    q_min: list[float] | None = None
    q_max: list[float] | None = None
    max_joint_speed: (
        Annotated[float, Field(gt=0.0)] | list[Annotated[float, Field(gt=0.0)]] | None
    ) = None
    max_joint_acceleration: (
        Annotated[float, Field(gt=0.0)] | list[Annotated[float, Field(gt=0.0)]]
    ) = 4.0
    time_scale: NonNegative = 0.0
    initial_q: list[float] | None = None
    settle_s: NonNegative = 0.3
    capture_s: NonNegative = 0.1


class ServerSpec(_Model):
    """Server settings (used by network/server.py / network/modbus_io.py).

    max_frame_bytes: largest frame from an authenticated client (before auth: 64 KiB).
    token: the shared secret (not empty). handshake_timeout_s: a client must say hello and
    authenticate, and finish any frame it starts, within this time (s). idle_timeout_s: a
    session that sends nothing for this long (no request of its own in flight) is closed
    (s). max_sessions: concurrent sessions, of which at most max_unauthenticated_sessions
    unauthenticated (a newcomer evicts the oldest of those).
    max_requests_in_flight: per session; beyond it the server stops reading that client.
    modbus_writable: Modbus clients may write coils / holding registers (default read-only).
    """

    token: Annotated[str, Field(min_length=1)] = "zerocal-sim"
    max_frame_bytes: Annotated[int, Field(ge=1024)] = 64 * 1024 * 1024
    offset_limit_rad: Annotated[float, Field(gt=0.0)] = math.radians(5.0)
    modbus_port: Annotated[int, Field(ge=0, le=65535)] = 5020
    n_digital_io: Annotated[int, Field(ge=1, le=64)] = 8
    initial_offsets: list[float] | None = None
    handshake_timeout_s: Annotated[float, Field(gt=0.0)] = 5.0
    idle_timeout_s: Annotated[float, Field(gt=0.0)] = 300.0
    max_sessions: Annotated[int, Field(ge=1)] = 32
    max_unauthenticated_sessions: Annotated[int, Field(ge=1)] = 16
    max_requests_in_flight: Annotated[int, Field(ge=1)] = 8
    modbus_writable: bool = False


class FaultSpec(_Model):
    """Injected faults. Counters are 0-based."""

    drop_after_requests: Annotated[int, Field(ge=0)] | None = None
    reply_delay_s: NonNegative = 0.0
    refuse_move_indices: list[Annotated[int, Field(ge=0)]] = []
    lose_io_edge_indices: list[Annotated[int, Field(ge=0)]] = []
    estop_after_moves: Annotated[int, Field(ge=0)] | None = None


class HumanoidSpec(_Model):
    """The humanoid_upper world (robot: humanoid_upper; controller_stub/world/humanoid.py).

    Hidden truth deltas of the dual_loop frames (nominal values: the design in
    humanoid.py): poses T_true = T_nom @ [R(rpy), xyz]; points p_true = p_nom + error (m,
    in the flange frame). The head camera is a rectified stereo pair (focal_px, baseline,
    principal point at the image centre) whose target centroids carry Gaussian pixel noise
    pixel_sigma (px, each image coordinate). The controller triangulates with its own
    calibration of that pair, which errs: each camera's fx, fy, cx, cy by Gaussian errors of
    calibration_sigma_px and the baseline by calibration_sigma_baseline (m), drawn from the
    seed; it reports the calibration and that covariance (0 = an exact calibration).
    """

    camera_error: PoseSpec = PoseSpec(xyz=[0.0015, -0.001, 0.002], rpy=[0.004, -0.003, 0.005])
    left_base_error: PoseSpec = PoseSpec(xyz=[-0.002, 0.0015, 0.001],
                                         rpy=[-0.003, 0.002, 0.004])
    right_base_error: PoseSpec = PoseSpec(xyz=[0.001, -0.002, -0.0015],
                                          rpy=[0.002, 0.004, -0.003])
    left_target_error: Vec3 = [0.0008, -0.0006, 0.001]
    right_target_error: Vec3 = [-0.0007, 0.0009, -0.0005]
    focal_px: Annotated[float, Field(gt=0.0)] = 1400.0
    baseline: Annotated[float, Field(gt=0.0)] = 0.12
    image_width: Annotated[int, Field(ge=16, le=8192)] = 1280
    image_height: Annotated[int, Field(ge=16, le=8192)] = 1024
    pixel_sigma: NonNegative = 0.15
    calibration_sigma_px: NonNegative = 0.0
    calibration_sigma_baseline: NonNegative = 0.0


class Scenario(_Model):
    """The whole simulated world. See the module docstring."""

    seed: int = 0
    robot: RobotName = "ur5e"
    truth: TruthSpec = TruthSpec()
    camera: CameraSpec = CameraSpec()
    target: TargetSpec = TargetSpec()
    chessboard: ChessboardSpec = ChessboardSpec()
    probe: ProbeSpec = ProbeSpec()
    motion: MotionSpec = MotionSpec()
    server: ServerSpec = ServerSpec()
    faults: FaultSpec = FaultSpec()
    humanoid: HumanoidSpec = HumanoidSpec()
    tracker: TrackerSpec = TrackerSpec()  # the laser tracker (sensors/world_point.py)
    sensors: dict[str, dict[str, Any]] = {}
    """Settings of the kinds' own simulated sensors by name, each the sensor's own
    (controller_stub/sensors/registry.py: `setup.settings`)."""

    @model_validator(mode="after")
    def _check_lengths(self) -> Scenario:
        n = ROBOT_JOINTS[self.robot]
        checks: list[tuple[str, Any]] = [
            ("truth.zero_errors", self.truth.zero_errors),
            ("truth.joint_compliance", self.truth.joint_compliance),
            ("truth.backlash", self.truth.backlash),
            ("truth.transmission_harmonic", self.truth.transmission_harmonic),
            ("truth.encoder_scale", self.truth.encoder_scale),
            ("motion.q_min", self.motion.q_min),
            ("motion.q_max", self.motion.q_max),
            ("motion.initial_q", self.motion.initial_q),
            ("server.initial_offsets", self.server.initial_offsets),
        ]
        if isinstance(self.motion.max_joint_speed, list):
            checks.append(("motion.max_joint_speed", self.motion.max_joint_speed))
        if isinstance(self.motion.max_joint_acceleration, list):
            checks.append(("motion.max_joint_acceleration", self.motion.max_joint_acceleration))
        for name, spec in (
            ("truth.link_length_errors", self.truth.link_length_errors),
            ("truth.thermal_drift", self.truth.thermal_drift),
        ):
            if spec is not None:
                checks += [(f"{name}.d", spec.d), (f"{name}.a", spec.a)]
        for name, value in checks:
            if isinstance(value, list) and len(value) != n:
                raise _FieldError(
                    name, f"expected {n} values for robot '{self.robot}', got {len(value)}"
                )
        if self.motion.q_min is not None and self.motion.q_max is not None:
            for i, (lo, hi) in enumerate(zip(self.motion.q_min, self.motion.q_max, strict=True)):
                if lo >= hi:
                    raise _FieldError("motion.q_max", f"joint {i + 1}: q_max <= q_min")
        if self.probe.io_line >= self.server.n_digital_io:
            raise _FieldError("probe.io_line", "index beyond server.n_digital_io")
        return self


class _FieldError(ValueError):
    """Cross-field validation error that carries its own dotted field name."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.detail = message


def _one_line(exc: ValidationError) -> str:
    """The most specific pydantic error as `dotted.field: message` (for a union, the member
    whose error goes deepest, e.g. `truth.zero_errors.random_deg`)."""
    errors = exc.errors()
    for err in errors:
        ctx_error = (err.get("ctx") or {}).get("error")
        if isinstance(ctx_error, _FieldError):
            return str(ctx_error)

    def clean(err: Any) -> list[str]:
        return [str(p) for p in err["loc"] if not _is_union_tag(p)]

    err = max(errors, key=lambda e: len(clean(e)))
    loc = ".".join(clean(err))
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    return f"{loc or '<root>'}: {msg}"


def _is_union_tag(part: Any) -> bool:
    """pydantic inserts union member names ('list[float]', 'RandomSpec') into error locs."""
    return isinstance(part, str) and (
        "[" in part or part[:1].isupper() or part.startswith("constrained")
    )


def scenario_from_dict(data: Any) -> Scenario:
    """Validate a plain mapping into a Scenario; raises ScenarioError naming the field."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(f"<root>: expected a mapping, got {type(data).__name__}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(_one_line(exc)) from None


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario from a .yaml/.yml/.json file; raises ScenarioError (names the field)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario file ({exc.strerror})") from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ScenarioError(f"{path}: not valid YAML/JSON ({first})") from None
    return scenario_from_dict(data)


def default_scenario() -> Scenario:
    """The packaged default scenario (scenarios/default.yaml; built-in defaults if absent)."""
    path = Path(__file__).parent / "scenarios" / "default.yaml"
    return load_scenario(path) if path.is_file() else Scenario()
