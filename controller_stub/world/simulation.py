"""The simulated controller's world: robot, truth, motion, sensors.

Synchronous and free of I/O: the asyncio server (`network/server.py`) is a thin shell that turns
protocol requests into calls on one `Simulation` and paces motions in wall time
(`duration_s * time_scale`): it plans a motion with `begin_move`, and `finish_move` moves the
robot at the end, or part-way if the motion was aborted. Everything here is reproducible
from the scenario's seed.

Angles are radians, lengths metres, times seconds (docs/conventions.md). "Reported" joint
angles are what a real controller reports: `q_reported = encoder + zero_offset`. The physical
angle differs from the reported one by the injected zero error and by the hidden effects.
The simulation never imports hostpc: it has its own forward model (`robot_model.py`).

`Simulation` is composed of collaborators that each own their state and talk through
explicit methods: `state` (`controller_state.ControllerState`: offsets and their history, IO,
limits, clock, the motion in progress; its `SimulatedController` protocol is this contract
in types), `body` (`arm.ArmBody`: the forward model, the hidden physics, the backlash
approach), `motion` (`joint_motion.JointMotion`: joint moves and their fault counters),
`guarded` (`guarded.GuardedMoves`: the probe input along a path, guarded-move plans),
and the sensors `probe` (`sensors/sphere_probe.py`), `stereo` (`sensors/stereo_target.py`)
and `tracker` (`sensors/world_point.py`). The contract's types live where they are defined
(`controller_state.py`, `motion.py`, `controller_stub.errors`).

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
    sim.begin_move(q_target, speed, io_line=None, acceleration=None) -> MotionPlan  # deferred:
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
    sim.tracker -> TrackerSensor | None        # the laser tracker: .measure_tracker() -> dict
    sim.targets -> TargetSensor | None         # triangulated targets: .measure_targets()
                                               # (None here; the humanoid's head camera)
    sim.on_io_edge: Callable[[int, bool, float, (n,)], None] | None
                                               # set by the server; called for each IO edge
                                               # (line, new value, sim time, latched q)
"""


from __future__ import annotations

import math
from typing import Any

import numpy as np

from controller_stub.scenario.spec import RandomSpec, Scenario
from controller_stub.sensors.sphere_probe import TouchProbe
from controller_stub.sensors.stereo_target import StereoCamera, StereoFrame, camera_description
from controller_stub.sensors.world_point import STREAM_TRACKER, Tracker
from controller_stub.streams import STREAM_PROBE, STREAM_TRUTH, stream_rng
from controller_stub.world.arm import ArmBody
from controller_stub.world.controller_base import ControllerBase
from controller_stub.world.controller_state import (
    ControllerState,
    SimulatedController,
    TargetSensor,
)
from controller_stub.world.guarded import GuardedMoves
from controller_stub.world.humanoid import HumanoidSimulation
from controller_stub.world.joint_motion import JointMotion
from controller_stub.world.motion import (
    GuardedMoveResult,
    MotionPlan,
    MoveResult,
)
from controller_stub.world.physics import HiddenEffects, Physics
from controller_stub.world.robot_model import RobotModel, get_robot


def create_simulation(scenario: Scenario) -> SimulatedController:
    """The simulation of `scenario`: a `Simulation`, or for robot "humanoid_upper" a
    `controller_stub.world.humanoid.HumanoidSimulation` (the same contract over the combined
    16-joint vector, with a `targets` sensor)."""
    if scenario.robot == "humanoid_upper":
        return HumanoidSimulation(scenario)
    return Simulation(scenario)


class Simulation(ControllerBase):
    """The simulated controller's world. See the module docstring for the contract.

    Everything random is drawn from the scenario's seed, one stream per feature.
    """

    def __init__(self, scenario: Scenario) -> None:
        model = get_robot(scenario.robot)
        n = model.n_joints
        truth = scenario.truth
        rng_truth = stream_rng(scenario.seed, STREAM_TRUTH)
        if isinstance(truth.zero_errors, RandomSpec):
            half = math.radians(truth.zero_errors.random_deg)
            zero_errors = rng_truth.uniform(-half, half, n)
        else:
            zero_errors = np.asarray(truth.zero_errors, dtype=float)
        motion = scenario.motion
        if motion.max_joint_speed is None:
            max_speed = model.max_speed.astype(float)
        else:
            max_speed = np.broadcast_to(np.asarray(motion.max_joint_speed, float), (n,)).copy()
        super().__init__(ControllerState(
            scenario,
            zero_errors=zero_errors,
            q_min=np.asarray(motion.q_min if motion.q_min is not None else model.q_min),
            q_max=np.asarray(motion.q_max if motion.q_max is not None else model.q_max),
            max_speed=max_speed,
            start=motion.initial_q if motion.initial_q is not None else model.home,
        ))
        self.body = ArmBody(model, HiddenEffects.from_spec(truth, n), self.state)
        pr = scenario.probe
        self.probe = TouchProbe(
            tip_flange=np.asarray(pr.tip, float) + np.asarray(pr.tip_error, float),
            sphere_centre=np.asarray(pr.sphere_centre, float)
            + np.asarray(pr.sphere_centre_error, float),
            sphere_radius=pr.sphere_radius,
            stylus_radius=pr.stylus_radius,
            io_line=pr.io_line,
        )
        self.guarded = GuardedMoves(scenario, self.state, self.body, self.probe,
                                    stream_rng(scenario.seed, STREAM_PROBE))
        self.motion = JointMotion(scenario, self.state, self.body, self.guarded)
        self.stereo = StereoCamera(scenario)
        self.tracker = Tracker(scenario.tracker, stream_rng(scenario.seed, STREAM_TRACKER),
                               arm=self)
        self.targets: TargetSensor | None = None  # no triangulating camera on the arm
        self.guarded.update_input(emit=False)

    # ------------------------------------------------------------------ simple state

    @property
    def robot_name(self) -> str:
        return self.body.model.name

    @property
    def model(self) -> RobotModel:
        """The simulator's own forward model of the arm (nominal geometry)."""
        return self.body.model

    @property
    def physics(self) -> Physics:
        """The arm's physics (hidden effects applied)."""
        return self.body.physics

    # ------------------------------------------------------------------ physics views

    def physical_angles(self, q_reported: np.ndarray | None = None) -> np.ndarray:
        """(n,) physical joint angles for reported angles (default: the current pose), with
        the current offsets, backlash state and clock."""
        return self.body.physical_angles(q_reported)

    def flange_pose(self) -> np.ndarray:
        """(4, 4) true T_base_flange at the current pose."""
        return self.body.flange_pose()

    def camera_pose(self) -> np.ndarray:
        """(4, 4) true T_base_leftcamera at the current pose."""
        return self.flange_pose() @ self.stereo.T_flange_camera

    def tip_position(self) -> np.ndarray:
        """(3,) true stylus tip centre in base (m) at the current pose."""
        return self.probe.tips(self.flange_pose()[None])[0]

    # ------------------------------------------------------------------ motion

    def move_joints(self, q_target: Any, speed: float) -> MoveResult:
        """See `JointMotion.move_joints`."""
        return self.motion.move_joints(q_target, speed)

    def guarded_move(self, q_target: Any, speed: float, io_line: int) -> GuardedMoveResult:
        """See `JointMotion.guarded_move`."""
        return self.motion.guarded_move(q_target, speed, io_line)

    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None,
                   acceleration: float | None = None) -> MotionPlan:
        """See `JointMotion.begin_move`."""
        return self.motion.begin_move(q_target, speed, io_line, acceleration)

    def finish_move(
        self, plan: MotionPlan, fraction: float = 1.0
    ) -> MoveResult | GuardedMoveResult:
        """See `JointMotion.finish_move`."""
        return self.motion.finish_move(plan, fraction)

    # ------------------------------------------------------------------ camera

    def capture_stereo(self, pattern: str = "target", view: int = 0) -> StereoFrame:
        """Render a stereo pair (`StereoCamera.render`): pattern "target" from the robot's
        physical pose, "chessboard" the `view`-th rig-calibration view. The robot first
        settles if it moved (`settle_for_measurement`); the frame is stamped at the start
        of the exposure; the clock then advances by the scenario's `motion.capture_s`
        (robot time spent standing still for the capture)."""
        self.settle_for_measurement()
        left, right = self.stereo.render(pattern, view, self.camera_pose)
        frame = StereoFrame(left=left, right=right, q=self.state.joint_positions(),
                            time=self.state.time)
        self.hold_for_capture()  # exposure + readout
        return frame

    def camera_description(self) -> dict[str, Any]:
        """What the controller reports about its camera: never the hidden truth."""
        return camera_description(self.scenario)

    # ------------------------------------------------------------------ truth

    def truth(self) -> dict[str, Any]:
        """The hidden truth, JSON-serialisable (for --truth-out and tests only)."""
        sc = self.scenario
        state = self.state
        delta_d, delta_a = self.physics.length_deltas(state.time)
        return {
            "robot": self.model.name,
            "time_s": state.time,
            "zero_errors": state.current_zero_errors().tolist(),
            "zero_errors_initial": state.zero_errors_initial().tolist(),
            "zero_offsets": state.zero_offsets().tolist(),
            "zero_offsets_initial": state.offsets_initial().tolist(),
            "q_reported": state.joint_positions().tolist(),
            "q_physical": self.physical_angles().tolist(),
            "approach": self.body.approach.tolist(),
            **self.stereo.truth(),
            "probe": {
                "stylus_tip": self.probe.tip_flange.tolist(),
                "stylus_radius": sc.probe.stylus_radius,
                "sphere_centre": self.probe.sphere_centre.tolist(),
                "sphere_radius": sc.probe.sphere_radius,
                "repeatability_sigma": sc.probe.repeatability_sigma,
            },
            "effects": self.body.effects.as_dict(),
            "link_length_deltas_now": {"d": delta_d.tolist(), "a": delta_a.tolist()},
            "tracker": self.tracker.truth(),
        }
