"""The simulated controller's world: robot, truth, motion, sensors.

Synchronous and free of I/O: the asyncio server (`server.py`) is a thin shell that turns
protocol requests into calls on one `Simulation` and paces motions in wall time
(`duration_s * time_scale`): it plans a motion with `begin_move`, and `finish_move` moves the
robot at the end, or part-way if the motion was aborted. Everything here is reproducible
from the scenario's seed.

Angles are radians, lengths metres, times seconds (docs/conventions.md). "Reported" joint
angles are what a real controller reports: `q_reported = encoder + zero_offset`. The physical
angle differs from the reported one by the injected zero error and by the hidden effects.
The simulation never imports hostpc: it has its own forward model (`robot_model.py`).

`Simulation` holds the world state (physics views, truth; the offsets and their history, IO,
limits, clock and the busy check it shares with every simulated controller come from
`controller_state.ControllerState`, whose `SimulatedController` protocol is this contract in
types); its behaviour comes one concept per module: joint moves and motion plans
(`motion.py`), guarded moves and the probe input (`guarded.py`), the stereo camera
(`cameras.py`). The names of the contract are importable from here.

INTERFACE CONTRACT (the server depends on exactly these names):

    sim = Simulation(scenario)                 # scenario: controller_stub.scenario.spec.Scenario
    sim.robot_name -> str ; sim.n_joints -> int ; sim.time -> float (simulated clock, s)
    sim.time_scale -> float                    # wall seconds per simulated second of motion
    sim.joint_positions() -> (n,) reported angles
    sim.joint_limits() -> ((n,), (n,))         # lower, upper (reported frame)
    sim.zero_offsets() -> (n,)
    sim.set_zero_offsets(offsets) -> (n,) previous offsets   # raises SimulationRefused
    sim.digital_inputs() -> list[bool] ; sim.digital_outputs() -> list[bool]
    sim.set_digital_output(index, value) -> None
    sim.move_joints(q_target, speed) -> MoveResult            # speed: fraction of max (0, 1]
    sim.guarded_move(q_target, speed, io_line) -> GuardedMoveResult
    sim.begin_move(q_target, speed, io_line=None) -> MotionPlan   # deferred motion (server):
    sim.finish_move(plan, fraction=1.0) -> MoveResult | GuardedMoveResult  # stop part-way
    sim.capture_stereo(pattern="target", view=0) -> StereoFrame   # pattern: target|chessboard
    sim.camera_description() -> dict          # what the controller reports of its camera
                                               # (image size, nominal mount); never the truth
    sim.estop() -> None ; sim.reset_estop() -> None ; sim.estopped -> bool
    sim.offset_history() -> list[(id, (n,))]   # every offset set held, id 0 = original
    sim.rollback(id) -> (n,) previous offsets  # restore a history entry (SimulationRefused)
    sim.last_history_id -> int                 # the entry held now
    sim.undo_write(id) -> (n,) replaced offsets  # restore the entry before write `id`
    sim.busy -> bool                           # a begun motion is not finished
    sim.truth() -> dict                        # JSON-serialisable; for --truth-out only
    sim.measure_tracker() -> dict              # optional: the laser tracker (tracker.py)
    sim.on_io_edge: Callable[[int, bool, float, (n,)], None] | None
                                               # set by the server; called for each IO edge
                                               # (line, new value, sim time, latched q)
"""


from __future__ import annotations

import math
from typing import Any

import numpy as np

from controller_stub.errors import SimulationRefused
from controller_stub.geometry import make_transform, matrix_to_rpy
from controller_stub.scenario.spec import RandomSpec, Scenario
from controller_stub.sensors import sphere_probe as probe_mod
from controller_stub.sensors.render import CameraModel, ChessboardPattern, DiskPattern, Renderer
from controller_stub.sensors.stereo_target import StereoCameraMixin, StereoFrame
from controller_stub.sensors.world_point import TrackerMixin
from controller_stub.streams import STREAM_PROBE, STREAM_TRUTH, stream_rng
from controller_stub.world.controller_state import ControllerState, OnIoEdge, SimulatedController
from controller_stub.world.guarded import GuardedMoveMixin
from controller_stub.world.humanoid import HumanoidSimulation
from controller_stub.world.motion import (
    GuardedContact,
    GuardedMoveResult,
    MotionMixin,
    MotionPlan,
    MoveResult,
    PathEdge,
)
from controller_stub.world.physics import HiddenEffects, Physics
from controller_stub.world.robot_model import get_robot

__all__ = [
    "GuardedContact",
    "GuardedMoveResult",
    "MotionPlan",
    "MoveResult",
    "OnIoEdge",
    "PathEdge",
    "SimulatedController",
    "Simulation",
    "SimulationRefused",
    "StereoFrame",
    "create_simulation",
]

def _plane_frame(origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(4, 4) frame at `origin` whose z axis is `normal` (x chosen orthogonal, deterministic)."""
    z = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - (helper @ z) * z
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = origin
    return T


def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    return {"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist()}


def create_simulation(scenario: Scenario) -> SimulatedController:
    """The simulation of `scenario`: a `Simulation`, or for robot "humanoid_upper" a
    `controller_stub.world.humanoid.HumanoidSimulation` (the same contract over the combined
    16-joint vector, plus `measure_targets()`)."""
    if scenario.robot == "humanoid_upper":
        return HumanoidSimulation(scenario)
    return Simulation(scenario)


class Simulation(
    MotionMixin, GuardedMoveMixin, StereoCameraMixin, TrackerMixin, ControllerState
):
    """The simulated controller's world. See the module docstring for the contract.

    State: the encoder positions (as reported angles and the current zero offsets), the
    direction each joint last moved (backlash), the simulated clock, digital IO, estop and
    the fault counters. Everything random is drawn from the scenario's seed.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.model = get_robot(scenario.robot)
        n = self.model.n_joints
        truth = scenario.truth
        rng_truth = stream_rng(scenario.seed, STREAM_TRUTH)
        if isinstance(truth.zero_errors, RandomSpec):
            half = math.radians(truth.zero_errors.random_deg)
            zero_errors = rng_truth.uniform(-half, half, n)
        else:
            zero_errors = np.asarray(truth.zero_errors, dtype=float)
        self.effects = HiddenEffects.from_spec(truth, n)
        self.physics = Physics(self.model, self.effects)

        motion = scenario.motion
        if motion.max_joint_speed is None:
            max_speed = self.model.max_speed.astype(float)
        else:
            max_speed = np.broadcast_to(np.asarray(motion.max_joint_speed, float), (n,)).copy()
        super().__init__(
            scenario,
            zero_errors=zero_errors,
            q_min=np.asarray(motion.q_min if motion.q_min is not None else self.model.q_min),
            q_max=np.asarray(motion.q_max if motion.q_max is not None else self.model.q_max),
            max_speed=max_speed,
            start=motion.initial_q if motion.initial_q is not None else self.model.home,
        )
        self._approach = np.ones(n)
        self._estop_fault_fired = False
        self._move_count = 0
        self._completed_moves = 0
        self._guarded_count = 0
        self._rng_probe = stream_rng(scenario.seed, STREAM_PROBE)

        cam = scenario.camera
        self.camera = CameraModel(
            width=cam.image_width,
            height=cam.image_height,
            fx=cam.fx,
            fy=cam.fy,
            cx=cam.cx,
            cy=cam.cy,
            distortion=tuple(float(v) for v in cam.distortion),  # type: ignore[arg-type]
        )
        self.T_flange_camera_nominal = make_transform(cam.mount.xyz, cam.mount.rpy)
        self.T_flange_camera = self.T_flange_camera_nominal @ make_transform(
            cam.mount_error.xyz, cam.mount_error.rpy
        )
        self.T_left_right = make_transform([cam.baseline, 0.0, 0.0], cam.right_rpy)
        self.target_centre = np.asarray(scenario.target.centre, float) + np.asarray(
            scenario.target.centre_error, float
        )
        pr = scenario.probe
        self.tip_flange = np.asarray(pr.tip, float) + np.asarray(pr.tip_error, float)
        self.sphere_centre = np.asarray(pr.sphere_centre, float) + np.asarray(
            pr.sphere_centre_error, float
        )
        tgt = scenario.target
        self.T_base_target = _plane_frame(self.target_centre, np.asarray(tgt.normal, float))
        self.disk_pattern = DiskPattern(
            tgt.radius, tgt.plate_radius, tgt.dot_level, tgt.plate_level
        )
        board = scenario.chessboard
        self.board_pattern = ChessboardPattern(
            board.cols, board.rows, board.square_size, board.dark_level, board.light_level
        )
        self._board_views: np.ndarray | None = None  # drawn lazily (rejection sampling)
        self._renderers: tuple[Renderer, Renderer] | None = None  # built on first capture
        self._update_probe_input(emit=False)

    # ------------------------------------------------------------------ simple state

    @property
    def robot_name(self) -> str:
        return self.model.name

    # ------------------------------------------------------------------ physics views

    def physical_angles(self, q_reported: np.ndarray | None = None) -> np.ndarray:
        """(n,) physical joint angles for reported angles (default: the current pose), with
        the current offsets, backlash state and clock."""
        q = self._q if q_reported is None else np.asarray(q_reported, float).reshape(-1)
        return self.physics.physical_angles(
            q[None, :], self.current_zero_errors(), self._approach, self._time
        )[0]

    def flange_pose(self) -> np.ndarray:
        """(4, 4) true T_base_flange at the current pose."""
        return self.physics.flange_pose(self.physical_angles()[None, :], self._time)[0]

    def camera_pose(self) -> np.ndarray:
        """(4, 4) true T_base_leftcamera at the current pose."""
        return self.flange_pose() @ self.T_flange_camera

    def tip_position(self) -> np.ndarray:
        """(3,) true stylus tip centre in base (m) at the current pose."""
        return probe_mod.tip_positions(self.flange_pose()[None], self.tip_flange)[0]

    # ------------------------------------------------------------------ truth

    def truth(self) -> dict[str, Any]:
        """The hidden truth, JSON-serialisable (for --truth-out and tests only)."""
        sc = self.scenario
        cam = sc.camera
        delta_d, delta_a = self.physics.length_deltas(self._time)
        return {
            "robot": self.model.name,
            "time_s": self._time,
            "zero_errors": self.current_zero_errors().tolist(),
            "zero_errors_initial": self._zero_error_initial.tolist(),
            "zero_offsets": self._offsets.tolist(),
            "zero_offsets_initial": self._offsets_initial.tolist(),
            "q_reported": self._q.tolist(),
            "q_physical": self.physical_angles().tolist(),
            "approach": self._approach.tolist(),
            "camera": {
                "image_width": cam.image_width,
                "image_height": cam.image_height,
                "fx": cam.fx,
                "fy": cam.fy,
                "cx": cam.cx,
                "cy": cam.cy,
                "distortion": list(cam.distortion),
                "baseline": cam.baseline,
                "T_left_right": _pose_dict(self.T_left_right),
                "T_flange_camera": _pose_dict(self.T_flange_camera),
                "T_flange_camera_nominal": _pose_dict(self.T_flange_camera_nominal),
            },
            "target": {
                "centre": self.target_centre.tolist(),
                "radius": sc.target.radius,
                "normal": list(sc.target.normal),
            },
            "probe": {
                "stylus_tip": self.tip_flange.tolist(),
                "stylus_radius": sc.probe.stylus_radius,
                "sphere_centre": self.sphere_centre.tolist(),
                "sphere_radius": sc.probe.sphere_radius,
                "repeatability_sigma": sc.probe.repeatability_sigma,
            },
            "effects": self.effects.as_dict(),
            "link_length_deltas_now": {"d": delta_d.tolist(), "a": delta_a.tolist()},
            "tracker": self.tracker.truth(),
        }
