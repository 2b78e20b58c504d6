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

`Simulation` holds the world state (offsets and their history, IO, physics views, truth); its
behaviour comes one concept per module: joint moves and motion plans (`motion.py`), guarded
moves and the probe input (`guarded.py`), the stereo camera (`cameras.py`). The names of the
contract are importable from here.

INTERFACE CONTRACT (the server depends on exactly these names):

    sim = Simulation(scenario)                 # scenario: controller_stub.scenario.Scenario
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
    sim.truth() -> dict                        # JSON-serialisable; for --truth-out only
    sim.measure_tracker() -> dict              # optional: the laser tracker (tracker.py)
    sim.on_io_edge: Callable[[int, bool, float, (n,)], None] | None
                                               # set by the server; called for each IO edge
                                               # (line, new value, sim time, latched q)
"""


from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from controller_stub import probe as probe_mod
from controller_stub.cameras import StereoCameraMixin, StereoFrame
from controller_stub.errors import SimulationRefused
from controller_stub.guarded import GuardedMoveMixin
from controller_stub.motion import (
    GuardedContact,
    GuardedMoveResult,
    MotionMixin,
    MotionPlan,
    MoveResult,
    PathEdge,
)
from controller_stub.physics import HiddenEffects, Physics
from controller_stub.render import CameraModel, ChessboardPattern, DiskPattern, Renderer
from controller_stub.robot_model import get_robot, make_transform, matrix_to_rpy
from controller_stub.scenario import RandomSpec, Scenario
from controller_stub.streams import STREAM_PROBE, STREAM_TRUTH, stream_rng
from controller_stub.tracker import TrackerMixin

__all__ = [
    "GuardedContact",
    "GuardedMoveResult",
    "MotionPlan",
    "MoveResult",
    "OnIoEdge",
    "PathEdge",
    "Simulation",
    "SimulationRefused",
    "StereoFrame",
    "create_simulation",
]

OnIoEdge = Callable[[int, bool, float, np.ndarray], None]


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


def create_simulation(scenario: Scenario) -> Any:
    """The simulation of `scenario`: a `Simulation`, or for robot "humanoid_upper" a
    `controller_stub.humanoid.HumanoidSimulation` (the same contract over the combined
    16-joint vector, plus `measure_targets()`)."""
    if scenario.robot == "humanoid_upper":
        from controller_stub.humanoid import HumanoidSimulation

        return HumanoidSimulation(scenario)
    return Simulation(scenario)


class Simulation(MotionMixin, GuardedMoveMixin, StereoCameraMixin, TrackerMixin):
    """The simulated controller's world. See the module docstring for the contract.

    State: the encoder positions (as reported angles and the current zero offsets), the
    direction each joint last moved (backlash), the simulated clock, digital IO, estop and
    the fault counters. Everything random is drawn from the scenario's seed.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.model = get_robot(scenario.robot)
        n = self.model.n_joints
        self._n = n
        truth = scenario.truth
        rng_truth = stream_rng(scenario.seed, STREAM_TRUTH)
        if isinstance(truth.zero_errors, RandomSpec):
            half = math.radians(truth.zero_errors.random_deg)
            self._zero_error_initial = rng_truth.uniform(-half, half, n)
        else:
            self._zero_error_initial = np.asarray(truth.zero_errors, dtype=float)
        self.effects = HiddenEffects.from_spec(truth, n)
        self.physics = Physics(self.model, self.effects)

        motion = scenario.motion
        self._q_min = np.asarray(
            motion.q_min if motion.q_min is not None else self.model.q_min, float
        )
        self._q_max = np.asarray(
            motion.q_max if motion.q_max is not None else self.model.q_max, float
        )
        if motion.max_joint_speed is None:
            self._max_speed = self.model.max_speed.astype(float)
        else:
            self._max_speed = np.broadcast_to(
                np.asarray(motion.max_joint_speed, float), (n,)
            ).copy()

        server = scenario.server
        self._offsets_initial = (
            np.zeros(n)
            if server.initial_offsets is None
            else np.asarray(server.initial_offsets, float)
        )
        self._offsets = self._offsets_initial.copy()
        self._history: list[tuple[int, np.ndarray]] = [(0, self._offsets.copy())]
        self._next_history_id = 1
        start = motion.initial_q if motion.initial_q is not None else self.model.home
        self._q = np.clip(np.asarray(start, float), self._q_min, self._q_max)
        self._approach = np.ones(n)
        self._time = 0.0

        self._n_io = server.n_digital_io
        self._inputs = [False] * self._n_io
        self._outputs = [False] * self._n_io
        self._estopped = False
        self._estop_fault_fired = False
        self._move_count = 0
        self._completed_moves = 0
        self._guarded_count = 0
        self._rng_probe = stream_rng(scenario.seed, STREAM_PROBE)
        self.on_io_edge: OnIoEdge | None = None
        self._active_plan: MotionPlan | None = None  # begun, not yet finished

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

    @property
    def n_joints(self) -> int:
        return self._n

    @property
    def time(self) -> float:
        """Simulated clock (s): robot time. Advances by motion durations, by the settling
        after each completed joint move (`motion.settle_s`) and by each stereo capture
        (`motion.capture_s`)."""
        return self._time

    @property
    def time_scale(self) -> float:
        return float(self.scenario.motion.time_scale)

    @property
    def estopped(self) -> bool:
        return self._estopped

    def joint_positions(self) -> np.ndarray:
        """(n,) reported joint angles (rad)."""
        return self._q.copy()

    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """((n,), (n,)) lower and upper limits in the reported frame (rad)."""
        return self._q_min.copy(), self._q_max.copy()

    def max_joint_speed(self) -> np.ndarray:
        """(n,) maximum joint speeds (rad/s)."""
        return self._max_speed.copy()

    def zero_offsets(self) -> np.ndarray:
        """(n,) current controller zero offsets (rad): q_reported = encoder + offset."""
        return self._offsets.copy()

    def estop(self) -> None:
        self._estopped = True

    def reset_estop(self) -> None:
        self._estopped = False

    # ------------------------------------------------------------------ zero offsets

    def set_zero_offsets(self, offsets: np.ndarray | list[float]) -> np.ndarray:
        """Write new zero offsets (n,) rad; returns the previous ones.

        The encoders do not move, so the reported angles shift by (new - old) and the same
        reported command afterwards reaches a different physical pose. Refused with
        "offset_limit" if any joint would differ from the ORIGINAL offsets by more than
        server.offset_limit_rad, "invalid_argument" for a wrong shape or non-finite values,
        "busy" while a motion from begin_move is not finished.
        """
        if self._active_plan is not None:
            raise SimulationRefused("busy", "cannot change the zero offsets while moving")
        new = self._check_vector(offsets, "offsets")
        limit = self.scenario.server.offset_limit_rad
        change = np.abs(new - self._offsets_initial)
        if np.any(change > limit):
            i = int(np.argmax(change))
            raise SimulationRefused(
                "offset_limit",
                f"joint {i + 1}: offset change {math.degrees(change[i]):.3f} deg from the "
                f"original exceeds the limit {math.degrees(limit):.3f} deg",
            )
        previous = self._offsets.copy()
        self._q = self._q + (new - self._offsets)
        self._offsets = new
        self._history.append((self._next_history_id, new.copy()))
        self._next_history_id += 1
        return previous

    def offset_history(self) -> list[tuple[int, np.ndarray]]:
        """Every offset set the controller has held, oldest first: (id, (n,) offsets).

        id 0 is the original set; every successful set_zero_offsets / rollback appends one.
        """
        return [(i, o.copy()) for i, o in self._history]

    def rollback(self, history_id: int) -> np.ndarray:
        """Restore the offsets recorded under `history_id`; returns the previous offsets.

        Raises SimulationRefused("unknown_history_id") for an id never recorded.
        """
        for i, offsets in self._history:
            if i == history_id:
                return self.set_zero_offsets(offsets)
        raise SimulationRefused("unknown_history_id", f"no offset history entry {history_id}")

    def current_zero_errors(self) -> np.ndarray:
        """(n,) rad: constant part of q_phys - q_reported with the CURRENT offsets."""
        return self._zero_error_initial + self._offsets_initial - self._offsets

    # ------------------------------------------------------------------ IO

    def digital_inputs(self) -> list[bool]:
        return list(self._inputs)

    def digital_outputs(self) -> list[bool]:
        return list(self._outputs)

    def set_digital_output(self, index: int, value: bool) -> None:
        if not 0 <= int(index) < self._n_io:
            raise SimulationRefused(
                "invalid_argument", f"digital output {index} out of range 0..{self._n_io - 1}"
            )
        self._outputs[int(index)] = bool(value)

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

    # ------------------------------------------------------------------ argument checks

    def _check_vector(self, values: Any, name: str) -> np.ndarray:
        try:
            v = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise SimulationRefused("invalid_argument", f"{name}: not a numeric vector") from None
        if v.shape != (self._n,):
            raise SimulationRefused(
                "invalid_argument", f"{name}: expected {self._n} values, got {v.size}"
            )
        if not np.all(np.isfinite(v)):
            raise SimulationRefused("invalid_argument", f"{name}: non-finite value")
        return v

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
