"""The simulated humanoid upper body: a pan-tilt head with a stereo camera and two 7-DoF arms.

The stub's OWN model of the ``humanoid_upper`` design (never imports hostpc). Each chain is
a :class:`~controller_stub.world.robot_model.RobotModel` in URDF form (fixed joint origins, then a
rotation about the local z axis), derived BY HAND from the design's DH tables
(docs/dual-loop.md) exactly as robot_model.py does for the UR robots:
``O_1 = I``, ``O_k = [Rx(alpha_{k-1}), (a_{k-1}, 0, d_{k-1})]``, ``O_flange = [Rx(alpha_n),
(a_n, 0, d_n)]``, so each chain's base and flange are its DH frames 0 and n.

    head  (DH a, alpha, d):  (0, +pi/2, 0.12), (0.06, 0, 0)
      O_1 = I, O_2 = xyz (0, 0, 0.12) rpy (pi/2, 0, 0), O_f = xyz (0.06, 0, 0)
    arm   (DH a = 0; alpha = -pi/2, pi/2, pi/2, -pi/2, -pi/2, pi/2, 0;
           d = 0, 0, 0.28, 0, 0.25, 0, 0.10)
      O_1 = I, O_2 = rpy (-pi/2,0,0), O_3 = rpy (pi/2,0,0), O_4 = xyz (0,0,0.28) rpy (pi/2,0,0),
      O_5 = rpy (-pi/2,0,0), O_6 = xyz (0,0,0.25) rpy (-pi/2,0,0), O_7 = rpy (pi/2,0,0),
      O_f = xyz (0, 0, 0.10)

The world: the head base is fixed (the torso); each arm base hangs from it at the true
``T_headbase_armbase``; the stereo camera (left optical frame: x right, y down, z forward)
sits at the true ``T_headend_camera``; one target point per flange. All four frames and
all 16 joint zero errors are hidden truth (scenario ``humanoid`` and ``truth.zero_errors``,
combined joint order head 1-2, left 1-7, right 1-7).

Measurement (:meth:`HeadCamera.measure_targets`, the simulation's `targets` sensor; the pair
itself is `sensors/dual_loop.py`): the stub returns each visible target already
triangulated, with its covariance, instead of images. The camera is a
rectified pinhole pair (focal ``f`` px, principal point at the image centre, right camera
at ``+baseline`` along the left camera's x). The true point is projected into both images,
each centroid coordinate gets Gaussian noise ``pixel_sigma``, and the point is triangulated:

    z = f b / (u_L - u_R),  x = (u_L - c_x) z / f,  y = ((v_L + v_R) / 2 - c_y) z / f

Its covariance is the first-order propagation of the pixel noise through that function
(evaluated at the measured point): depth noise grows with z^2, lateral noise with z, and x
and z are correlated. A target is visible when it is in front of the camera and inside both
images. Rendering the two targets into images (``capture_stereo``) is not implemented for
the humanoid: it refuses with ``unsupported``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.geometry import make_transform, matrix_to_rpy
from controller_stub.scenario.spec import RandomSpec, Scenario
from controller_stub.sensors.dual_loop import CALIBRATION_PARAMETERS, StereoTriangulator
from controller_stub.streams import stream_rng  # the stub's seeded streams
from controller_stub.world.controller_base import ControllerBase
from controller_stub.world.controller_state import (
    ControllerState,
    TrackerSensor,
)
from controller_stub.world.motion import GuardedMoveResult, MotionPlan, MoveResult
from controller_stub.world.robot_model import LengthSite, RobotModel, forward

HALF_PI = math.pi / 2
DEG = math.pi / 180

CHAINS = ("head", "left", "right")
N_JOINTS = {"head": 2, "left": 7, "right": 7}
ARMS = ("left", "right")
STREAM_CALIBRATION = 12
"""The seed's random stream of the head camera's calibration error."""

# nominal frames of the design (xyz m, rpy rad)
CAMERA_NOMINAL = ((0.02, 0.04, 0.0), (0.0, -HALF_PI, math.pi - 0.15))
BASE_NOMINAL = {"left": ((0.0, 0.20, -0.10), (math.pi, 0.0, 0.0)),
                "right": ((0.0, -0.20, -0.10), (math.pi, 0.0, 0.0))}
TARGET_NOMINAL = {"left": (0.0, 0.03, 0.04), "right": (0.0, 0.03, 0.04)}
HOME = np.array([0.0, -0.45,
                 0.1, 0.05, 0.1, -1.45, 0.0, 0.8, 0.0,
                 -0.1, 0.05, -0.1, -1.45, 0.0, 0.8, 0.0])


def _no_sites(n: int) -> tuple[LengthSite, ...]:
    return tuple(LengthSite(i + 1, (0.0, 0.0, 1.0)) for i in range(n))


def head_model() -> RobotModel:
    """The pan-tilt head (see the module docstring)."""
    limits_lo = np.array([-100.0, -70.0]) * DEG
    limits_hi = np.array([100.0, 35.0]) * DEG
    return RobotModel(
        name="humanoid_upper.head",
        origin_xyz=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.12]]),
        origin_rpy=np.array([[0.0, 0.0, 0.0], [HALF_PI, 0.0, 0.0]]),
        flange_xyz=np.array([0.06, 0.0, 0.0]),
        flange_rpy=np.zeros(3),
        d_sites=_no_sites(2),
        a_sites=_no_sites(2),
        mass=np.array([0.6, 1.2]),
        com_body=np.zeros((2, 3)),
        q_min=limits_lo,
        q_max=limits_hi,
        max_speed=np.array([3.0, 3.0]),
        home=HOME[:2].copy(),
    )


def arm_model(side: str) -> RobotModel:
    """One 7-DoF arm (the same design on both sides; see the module docstring)."""
    limits = np.array([170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 175.0]) * DEG
    rx = [0.0, -HALF_PI, HALF_PI, HALF_PI, -HALF_PI, -HALF_PI, HALF_PI]
    z = [0.0, 0.0, 0.0, 0.28, 0.0, 0.25, 0.0]
    home = HOME[2:9] if side == "left" else HOME[9:16]
    return RobotModel(
        name=f"humanoid_upper.{side}",
        origin_xyz=np.array([[0.0, 0.0, zi] for zi in z]),
        origin_rpy=np.array([[r, 0.0, 0.0] for r in rx]),
        flange_xyz=np.array([0.0, 0.0, 0.10]),
        flange_rpy=np.zeros(3),
        d_sites=_no_sites(7),
        a_sites=_no_sites(7),
        mass=np.array([2.0, 1.8, 1.5, 1.2, 0.8, 0.5, 0.4]),
        com_body=np.zeros((7, 3)),
        q_min=-limits,
        q_max=limits,
        max_speed=np.full(7, 2.0),
        home=np.array(home),
    )


def _span(chain: str) -> slice:
    start = 0
    for name in CHAINS:
        if name == chain:
            return slice(start, start + N_JOINTS[name])
        start += N_JOINTS[name]
    raise KeyError(chain)


class HumanoidSimulation(ControllerBase):
    """The simulated humanoid controller: the Simulation contract over the combined joint
    vector (head 2, left 7, right 7; reported angles, rad) with a `targets` sensor (the head
    camera, :class:`HeadCamera`) and no tracker. Offsets, their history, limits, IO, e-stop,
    clock and the busy check are its `state`
    (:class:`~controller_stub.world.controller_state.ControllerState`).

    Motion is ideal (no hidden joint-space physics): the physical angle is the reported one
    plus the current zero error.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.models = {"head": head_model(), "left": arm_model("left"),
                       "right": arm_model("right")}
        n = sum(N_JOINTS.values())
        spec = scenario.humanoid
        truth = scenario.truth
        if isinstance(truth.zero_errors, RandomSpec):
            half = math.radians(truth.zero_errors.random_deg)
            errors = stream_rng(scenario.seed, 1).uniform(-half, half, n)
        else:
            errors = np.asarray(truth.zero_errors, dtype=float)
        motion = scenario.motion
        model_min = np.concatenate([self.models[c].q_min for c in CHAINS])
        model_max = np.concatenate([self.models[c].q_max for c in CHAINS])
        speeds = np.concatenate([self.models[c].max_speed for c in CHAINS])
        super().__init__(ControllerState(
            scenario,
            zero_errors=errors,
            q_min=np.asarray(motion.q_min if motion.q_min is not None else model_min),
            q_max=np.asarray(motion.q_max if motion.q_max is not None else model_max),
            max_speed=(speeds if motion.max_joint_speed is None else
                       np.broadcast_to(np.asarray(motion.max_joint_speed, float), (n,)).copy()),
            start=motion.initial_q if motion.initial_q is not None else HOME,
        ))
        self.T_headend_camera_nominal = make_transform(list(CAMERA_NOMINAL[0]),
                                                       list(CAMERA_NOMINAL[1]))
        self.T_headend_camera = self.T_headend_camera_nominal @ make_transform(
            spec.camera_error.xyz, spec.camera_error.rpy)
        self.T_headbase_armbase_nominal = {
            s: make_transform(list(BASE_NOMINAL[s][0]), list(BASE_NOMINAL[s][1])) for s in ARMS}
        base_errors = {"left": spec.left_base_error, "right": spec.right_base_error}
        self.T_headbase_armbase = {
            s: self.T_headbase_armbase_nominal[s]
            @ make_transform(base_errors[s].xyz, base_errors[s].rpy)
            for s in ARMS}
        target_errors = {"left": spec.left_target_error, "right": spec.right_target_error}
        self.target_flange = {s: np.asarray(TARGET_NOMINAL[s]) + np.asarray(target_errors[s])
                              for s in ARMS}
        calibration_sigma = np.array([spec.calibration_sigma_px] * 8
                                     + [spec.calibration_sigma_baseline])
        calibration_error = stream_rng(scenario.seed, STREAM_CALIBRATION).normal(
            0.0, 1.0, 9) * calibration_sigma
        self.stereo = StereoTriangulator(spec.focal_px, spec.baseline, spec.image_width,
                                         spec.image_height, spec.pixel_sigma,
                                         calibration_error, calibration_sigma)
        self.targets = HeadCamera(self.state, self.stereo, stream_rng(scenario.seed, 11),
                                  self.target_in_camera)
        self.tracker: TrackerSensor | None = None  # no laser tracker in this cell
        self._moves = 0

    @property
    def robot_name(self) -> str:
        return "humanoid_upper"

    # ------------------------------------------------------------------ motion

    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None,
                   acceleration: float | None = None) -> MotionPlan:
        """Plan a straight joint-space move to q_target (16,) reported rad at `speed`
        (fraction of max joint speed), ramped like the arm's (`motion.PathProfile`, the
        scenario's motion.max_joint_acceleration, capped at `acceleration` rad/s^2 if given);
        nothing moves until :meth:`finish_move`. Refused:
        "busy" (a motion is in progress), "estop", "invalid_argument", "joint_limit",
        "unsupported" for a guarded move (no touch probe)."""
        state = self.state
        state.refuse_if_busy()
        if io_line is not None:
            raise SimulationRefused("unsupported", "the humanoid has no touch probe")
        if state.estopped:
            raise SimulationRefused("estop", "emergency stop is active")
        target = state.check_vector(q_target, "q_target")
        if not 0.0 < float(speed) <= 1.0:
            raise SimulationRefused("invalid_argument", f"speed {speed} not in (0, 1]")
        state.check_joint_limits(target)
        q = state.joint_positions()
        profile = state.move_profile(q, target, float(speed), acceleration)
        plan = MotionPlan(q, target, state.time, profile, 1.0, None, ())
        state.hold_plan(plan)
        return plan

    def finish_move(self, plan: MotionPlan, fraction: float = 1.0) -> MoveResult:
        """Execute `plan` up to `fraction` (clipped to [0, 1]) of it: the robot stops there
        and a move stopped early reports completed=False / reason "aborted". A move that
        went somewhere, completed or aborted (an abort decelerates the body), leaves the
        robot to settle before its next measurement (`ControllerState.end_motion`: charged
        by `measure_targets`, not here), as on the arm."""
        self.state.release_plan(plan)
        fraction = min(max(float(fraction), 0.0), 1.0)
        stopped = fraction < 1.0
        q_end = plan.q_at(fraction)
        duration = fraction * plan.duration_s
        self.state.set_position(q_end)
        self.state.advance_clock(duration)
        if duration > 0.0:
            self.state.end_motion()
        self._moves += 1
        return MoveResult(completed=not stopped, q=q_end, duration_s=duration,
                          reason="aborted" if stopped else None)

    def move_joints(self, q_target: Any, speed: float) -> MoveResult:
        """Move to q_target (16,) reported rad at `speed` (fraction of max joint speed)."""
        return self.finish_move(self.begin_move(q_target, speed))

    def guarded_move(self, q_target: Any, speed: float, io_line: int) -> GuardedMoveResult:
        raise SimulationRefused("unsupported", "the humanoid has no touch probe")

    # ------------------------------------------------------------------ truth views

    def physical_angles(self) -> np.ndarray:
        """(16,) physical joint angles at the current pose (rad)."""
        physical: np.ndarray = self.state.joint_positions() + self.state.current_zero_errors()
        return physical

    def frames(self) -> dict[str, np.ndarray]:
        """True poses at the current pose, in the head base: ``camera`` (4, 4) and
        ``left``/``right`` target points (3,)."""
        q = self.physical_angles()
        out: dict[str, np.ndarray] = {}
        _, T_hb_he = forward(self.models["head"], q[_span("head")])
        out["camera"] = T_hb_he[0] @ self.T_headend_camera
        for side in ARMS:
            _, T_ab_af = forward(self.models[side], q[_span(side)])
            T = self.T_headbase_armbase[side] @ T_ab_af[0]
            out[side] = T[:3, :3] @ self.target_flange[side] + T[:3, 3]
        return out

    def target_in_camera(self, side: str) -> np.ndarray:
        """(3,) true target point of arm `side` in the camera frame (m)."""
        frames = self.frames()
        T = frames["camera"]
        point: np.ndarray = T[:3, :3].T @ (frames[side] - T[:3, 3])
        return point

    def capture_stereo(self, pattern: str = "target", view: int = 0) -> Any:
        raise SimulationRefused("unsupported", "humanoid_upper serves measure_targets, not "
                                "images")

    def camera_description(self) -> dict[str, Any]:
        """What the controller reports of its head camera: nominal values and its own
        calibration of the stereo pair with that calibration's covariance."""
        spec = self.scenario.humanoid
        return {
            "calibration": self.stereo.calibration(),
            "image_width": spec.image_width,
            "image_height": spec.image_height,
            "baseline_nominal": spec.baseline,
            "focal_px_nominal": spec.focal_px,
            "T_headend_camera_nominal": {"xyz": list(CAMERA_NOMINAL[0]),
                                         "rpy": list(CAMERA_NOMINAL[1])},
            "measures": "targets",
        }

    # ------------------------------------------------------------------ truth

    def truth(self) -> dict[str, Any]:
        """The hidden truth, JSON-serialisable (for --truth-out and tests only)."""

        def pose(T: np.ndarray) -> dict[str, list[float]]:
            return {"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist()}

        return {
            "robot": self.robot_name,
            "time_s": self.state.time,
            "joint_order": [f"{c}.q{j + 1}" for c in CHAINS for j in range(N_JOINTS[c])],
            "zero_errors": self.current_zero_errors().tolist(),
            "zero_errors_initial": self.state.zero_errors_initial().tolist(),
            "zero_offsets": self.state.zero_offsets().tolist(),
            "q_reported": self.state.joint_positions().tolist(),
            "q_physical": self.physical_angles().tolist(),
            "camera": pose(self.T_headend_camera),
            "left_base": pose(self.T_headbase_armbase["left"]),
            "right_base": pose(self.T_headbase_armbase["right"]),
            "left_target": self.target_flange["left"].tolist(),
            "right_target": self.target_flange["right"].tolist(),
            "stereo": {"focal_px": self.stereo.f, "baseline": self.stereo.b,
                       "pixel_sigma": self.stereo.sigma,
                       "calibration_error": dict(zip(
                           CALIBRATION_PARAMETERS,
                           self.stereo.calibration_error.tolist(),
                           strict=True))},
        }


class HeadCamera:
    """The humanoid's target sensor: the head's stereo pair triangulating the arms' targets.

    state: the controller state (e-stop, reported angles, clock); stereo: the pair
    (`sensors/dual_loop.py`); rng: its pixel-noise stream; target_in_camera: side -> (3,)
    true target point of that arm in the camera frame (m) at the current pose.
    """

    def __init__(self, state: ControllerState, stereo: StereoTriangulator,
                 rng: np.random.Generator, target_in_camera: Callable[[str], np.ndarray]
                 ) -> None:
        self.state = state
        self.stereo = stereo
        self._rng = rng
        self._target_in_camera = target_in_camera

    def measure_targets(self) -> dict[str, Any]:
        """Triangulate both targets at the current pose (see the module docstring).

        Returns ``{"q": (16,) reported angles, "time": s, "targets": {side: {"p": (3,) m,
        "cov": (3, 3) m^2, "uv": (2, 2) px}}}`` with an entry only for each visible target
        (uv: the noisy centres [[uL, vL], [uR, vR]] it was triangulated from)."""
        state = self.state
        if state.estopped:
            raise SimulationRefused("estop", "emergency stop is active")
        state.settle_for_measurement()  # the head and arms stand still before the capture
        targets: dict[str, dict[str, np.ndarray]] = {}
        for side in ARMS:
            p_true = self._target_in_camera(side)
            if not self.stereo.visible(p_true):
                continue
            p, cov, uv = self.stereo.measure(p_true, self._rng)
            targets[side] = {"p": p, "cov": cov, "uv": uv}
        measured = {"q": state.joint_positions(), "time": state.time, "targets": targets}
        state.advance_clock(float(state.scenario.motion.capture_s))  # one stereo capture
        return measured
