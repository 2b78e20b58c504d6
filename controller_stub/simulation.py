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
    sim.on_io_edge: Callable[[int, bool, float, (n,)], None] | None
                                               # set by the server; called for each IO edge
                                               # (line, new value, sim time, latched q)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller_stub import probe as probe_mod
from controller_stub.physics import HiddenEffects, Physics
from controller_stub.render import (
    CameraModel,
    ChessboardPattern,
    DiskPattern,
    Renderer,
    chessboard_views,
)
from controller_stub.robot_model import get_robot, make_transform, matrix_to_rpy
from controller_stub.scenario import RandomSpec, Scenario


class SimulationRefused(Exception):  # noqa: N818 (name fixed by the contract)
    """The simulated controller refuses a request (limit, estop, injected fault).

    `code` is a short machine-readable reason (e.g. "offset_limit", "joint_limit", "estop",
    "refused_fault"); the message says it in words.
    """

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class MoveResult:
    """Outcome of a joint move.

    completed: True if the target was reached; False with `reason` (code) if aborted.
    q: (n,) reported joint angles where the robot stopped.
    duration_s: simulated motion time (the server sleeps duration_s * time_scale).
    """

    completed: bool
    q: np.ndarray
    duration_s: float
    reason: str | None = None


@dataclass(frozen=True)
class GuardedMoveResult:
    """Outcome of a guarded move toward q_target that stops at a rising IO edge.

    contact: True if the edge came before the end of travel.
    q_latched: (n,) reported angles latched at the edge (late by the trigger latency), or None.
    q: (n,) reported angles where the robot stopped.
    speed_mps: Cartesian speed of the probe tip at the contact (m/s), or None.
    """

    contact: bool
    q_latched: np.ndarray | None
    q: np.ndarray
    duration_s: float
    io_line: int
    speed_mps: float | None = None
    reason: str | None = None


@dataclass(frozen=True)
class StereoFrame:
    """One stereo exposure: 8-bit grey images (H, W) and the reported joints at exposure."""

    left: np.ndarray
    right: np.ndarray
    q: np.ndarray
    time: float


@dataclass(frozen=True)
class PathEdge:
    """A change of the probe's digital input at path parameter s (0..1 of the whole path).

    time: sim time of the change (s); q: (n,) reported angles there; emit: False for an edge
    the controller does not see (lost-edge fault): the input changes silently.
    """

    s: float
    value: bool
    time: float
    q: np.ndarray
    emit: bool = True


@dataclass(frozen=True)
class GuardedContact:
    """The contact a guarded move will latch: touch at path parameter s_contact, latch at
    s_latch (trigger latency later), stop at s_stop. q_latched: (n,) reported angles at the
    latch; time_latch: sim time of the latch (s); speed_mps: tip speed at the touch (m/s)."""

    s_contact: float
    s_latch: float
    s_stop: float
    q_latched: np.ndarray
    time_latch: float
    speed_mps: float


@dataclass(frozen=True)
class MotionPlan:
    """A motion computed by `Simulation.begin_move` and not yet executed (`finish_move`).

    The path is q(s) = q_start + s * (q_target - q_start), s in [0, 1], reported rad, over
    path_duration_s of simulated time. Unless stopped early the motion ends at s = s_end (1,
    or the stop after a guarded contact) after duration_s = s_end * path_duration_s; a
    `fraction` of the motion means s = fraction * s_end. io_line: None for move_joints, the
    guarded line otherwise. edges: input changes along the path in order; contact: the
    guarded contact, or None.
    """

    q_start: np.ndarray
    q_target: np.ndarray
    t_start: float
    path_duration_s: float
    s_end: float
    io_line: int | None
    edges: tuple[PathEdge, ...]
    contact: GuardedContact | None = None

    @property
    def duration_s(self) -> float:
        """Simulated time of the motion if it is not stopped early (s)."""
        return self.s_end * self.path_duration_s

    def q_at(self, fraction: float) -> np.ndarray:
        """(n,) reported angles after `fraction` (clipped to [0, 1]) of the motion."""
        s = min(max(float(fraction), 0.0), 1.0) * self.s_end
        return self.q_start + s * (self.q_target - self.q_start)


OnIoEdge = Callable[[int, bool, float, np.ndarray], None]

# Independent random streams (so adding draws to one feature never changes another).
_STREAM_TRUTH, _STREAM_VIEWS, _STREAM_PROBE, _STREAM_LEFT, _STREAM_RIGHT = range(1, 6)


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, stream])


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


class Simulation:
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
        rng_truth = _rng(scenario.seed, _STREAM_TRUTH)
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
        self._rng_probe = _rng(scenario.seed, _STREAM_PROBE)
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
        """Simulated clock (s); advances only by motion durations."""
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

    # ------------------------------------------------------------------ motion

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

    def _begin_motion(self, q_target: Any, speed: float) -> tuple[np.ndarray, float]:
        """Common checks; returns (target (n,), duration (s)). Counts the move."""
        target = self._check_vector(q_target, "q_target")
        if not (isinstance(speed, int | float) and 0.0 < float(speed) <= 1.0):
            raise SimulationRefused("invalid_argument", f"speed {speed!r} not in (0, 1]")
        if self._estopped:
            raise SimulationRefused("estop", "emergency stop active; reset it before moving")
        index = self._move_count
        self._move_count += 1
        if index in self.scenario.faults.refuse_move_indices:
            raise SimulationRefused("refused_fault", f"move {index} refused (injected fault)")
        outside = (target < self._q_min) | (target > self._q_max)
        if np.any(outside):
            i = int(np.argmax(outside))
            raise SimulationRefused(
                "joint_limit",
                f"joint {i + 1}: target {target[i]:.6f} rad outside "
                f"[{self._q_min[i]:.6f}, {self._q_max[i]:.6f}]",
            )
        return target, self.motion_duration(self._q, target, float(speed))

    def motion_duration(self, q_from: np.ndarray, q_to: np.ndarray, speed: float) -> float:
        """Simulated time (s) of a joint move: max_i |dq_i| / (speed * max_speed_i)."""
        return float(np.max(np.abs(np.asarray(q_to) - q_from) / (speed * self._max_speed)))

    def _finish_motion(self, q_start: np.ndarray, q_end: np.ndarray, duration: float) -> None:
        moved = np.sign(q_end - q_start)
        self._approach = np.where(moved != 0, moved, self._approach)
        self._q = q_end.copy()
        self._time += duration
        self._completed_moves += 1
        after = self.scenario.faults.estop_after_moves
        if after is not None and not self._estop_fault_fired and self._completed_moves >= after:
            self._estop_fault_fired = True
            self._estopped = True

    def move_joints(self, q_target: Any, speed: float) -> MoveResult:
        """Move to q_target (n,) reported rad at `speed` (fraction of max joint speed).

        Raises SimulationRefused: "estop", "joint_limit", "refused_fault", "invalid_argument".
        The probe IO line follows contact along the path (rising/falling edges reported).
        """
        result = self.finish_move(self.begin_move(q_target, speed))
        assert isinstance(result, MoveResult)
        return result

    def begin_move(self, q_target: Any, speed: float, io_line: int | None = None) -> MotionPlan:
        """Plan a motion without executing it: a joint move (io_line None, see move_joints)
        or a guarded move until a rising edge on `io_line` (see guarded_move).

        The checks, move counters, faults and the probe noise draw happen here, exactly as
        in the immediate calls; the robot does not move (joint_positions() still reports
        the start) until `finish_move(plan, fraction)`. One plan at a time: another
        begin_move before finish_move is refused with "busy".
        """
        if self._active_plan is not None:
            raise SimulationRefused("busy", "another motion is in progress")
        if io_line is not None and not 0 <= int(io_line) < self._n_io:
            raise SimulationRefused(
                "invalid_argument", f"io_line {io_line} out of range 0..{self._n_io - 1}"
            )
        target, duration = self._begin_motion(q_target, speed)
        if io_line is None:
            plan = self._plan_move(target, duration)
        else:
            plan = self._plan_guarded_move(target, duration, int(io_line))
        self._active_plan = plan
        return plan

    def finish_move(
        self, plan: MotionPlan, fraction: float = 1.0
    ) -> MoveResult | GuardedMoveResult:
        """Execute `plan` up to `fraction` (clipped to [0, 1]) of it; 1 = to its end.

        The robot stops at q = q_start + s * (q_target - q_start), s = fraction * s_end; the
        clock advances by s * path_duration_s; only the IO edges with s_edge <= s happen. A
        move stopped early (fraction < 1, e.g. an abort) reports completed=False /
        reason "aborted"; a stopped guarded move reports a contact only if the trigger
        latched before the stop (a touch after the latch point is not reported; a touch
        before it but not yet latched sets the input without an IO edge event). Raises
        SimulationRefused("invalid_argument") if `plan` is not the motion in progress.
        """
        if plan is not self._active_plan:
            raise SimulationRefused("invalid_argument", "finish_move: not the motion in progress")
        self._active_plan = None
        fraction = min(max(float(fraction), 0.0), 1.0)
        stopped = fraction < 1.0
        s = fraction * plan.s_end
        for edge in plan.edges:
            if edge.s <= s:
                self._set_probe_input(edge.value, edge.time, edge.q, emit=edge.emit)
        if plan.io_line is not None:
            return self._finish_guarded(plan, s, stopped)
        q_end = plan.q_start + s * (plan.q_target - plan.q_start) if stopped else plan.q_target
        duration = s * plan.path_duration_s
        self._finish_motion(plan.q_start, q_end, duration)
        return MoveResult(
            completed=not stopped,
            q=q_end.copy(),
            duration_s=duration,
            reason="aborted" if stopped else None,
        )

    def _plan_move(self, target: np.ndarray, duration: float) -> MotionPlan:
        """A joint move: the probe IO line follows contact along the path."""
        q_start = self._q.copy()
        t_start = self._time
        edges = tuple(
            PathEdge(c.s, c.rising, t_start + c.s * duration, q_start + c.s * (target - q_start))
            for c in self._path_crossings(q_start, target, duration, t_start)
        )
        return MotionPlan(q_start, target, t_start, duration, 1.0, None, edges)

    # ------------------------------------------------------------------ probe

    def _gap_function(
        self, q_start: np.ndarray, target: np.ndarray, t_start: float, duration: float, extra: float
    ) -> probe_mod.GapFunction:
        """Gap (m) along the path s in [0, 1]: |tip - P_b| - (R + r + extra), < 0 inside.

        Uses the backlash state of this motion (moving joints approach in their direction)
        and the clock at each path point (thermal drift)."""
        moved = np.sign(target - q_start)
        approach = np.where(moved != 0, moved, self._approach)
        zero_error = self.current_zero_errors()
        pr = self.scenario.probe
        contact = pr.sphere_radius + pr.stylus_radius + extra
        drifting = self.physics.drifting

        def gap(s: np.ndarray) -> np.ndarray:
            s = np.asarray(s, float)
            q_rep = q_start[None, :] + s[:, None] * (target - q_start)[None, :]
            times = t_start + s * duration if drifting else t_start
            qp = self.physics.physical_angles(q_rep, zero_error, approach, times)
            tips = probe_mod.tip_positions(self.physics.flange_pose(qp, times), self.tip_flange)
            return np.linalg.norm(tips - self.sphere_centre, axis=1) - contact

        return gap

    def _tip_lipschitz(self, q_start: np.ndarray, target: np.ndarray) -> float:
        """Upper bound of |d tip / d s| (m) along the path: sum_i |dq_i| * (reach to tip),
        with a margin for the joint-space effects."""
        reach = (
            float(np.sum(np.linalg.norm(self.model.origin_xyz, axis=1)))
            + float(np.linalg.norm(self.model.flange_xyz))
            + float(np.linalg.norm(self.tip_flange))
        )
        return 1.2 * reach * float(np.sum(np.abs(target - q_start))) + 1e-9

    def _path_crossings(
        self,
        q_start: np.ndarray,
        target: np.ndarray,
        duration: float,
        t_start: float,
        extra: float = 0.0,
    ) -> list[probe_mod.Crossing]:
        if duration <= 0.0:
            return []
        gap = self._gap_function(q_start, target, t_start, duration, extra)
        return probe_mod.find_crossings(gap, self._tip_lipschitz(q_start, target))

    def _set_probe_input(self, value: bool, t: float, q: np.ndarray, emit: bool) -> None:
        line = self.scenario.probe.io_line
        if self._inputs[line] == value:
            return
        self._inputs[line] = value
        if emit and self.on_io_edge is not None:
            self.on_io_edge(line, value, t, q.copy())

    def _update_probe_input(self, emit: bool) -> None:
        tip = self.tip_position()
        pr = self.scenario.probe
        inside = np.linalg.norm(tip - self.sphere_centre) <= pr.sphere_radius + pr.stylus_radius
        self._set_probe_input(bool(inside), self._time, self._q, emit)

    def guarded_move(self, q_target: Any, speed: float, io_line: int) -> GuardedMoveResult:
        """Move toward q_target until a rising edge on `io_line` (the probe trigger).

        The contact is the first time the stylus tip sphere touches the reference sphere
        (contact distance R + r plus the probe's repeatability noise). The joints are latched
        `probe_trigger_latency_s` after the true contact; the robot stops `probe.stop_time_s`
        after the latch (it keeps moving along the path until then). A lost-edge fault or no
        contact runs to the end of travel and returns contact=False. The IO edge callback
        gets (line, True, latch time, latched q). Equivalent to
        finish_move(begin_move(q_target, speed, io_line)).
        """
        result = self.finish_move(self.begin_move(q_target, speed, int(io_line)))
        assert isinstance(result, GuardedMoveResult)
        return result

    def _plan_guarded_move(self, target: np.ndarray, duration: float, io_line: int) -> MotionPlan:
        """A guarded move (see guarded_move): the edges up to the contact, and the contact."""
        index = self._guarded_count
        self._guarded_count += 1
        lose_edge = index in self.scenario.faults.lose_io_edge_indices
        probe_line = self.scenario.probe.io_line
        q_start = self._q.copy()
        t_start = self._time
        noise = float(self._rng_probe.normal(0.0, self.scenario.probe.repeatability_sigma))
        crossings = self._path_crossings(q_start, target, duration, t_start, extra=noise)
        latency = self.effects.probe_trigger_latency_s
        edges: list[PathEdge] = []
        for c in crossings:
            t_c = t_start + c.s * duration
            q_c = q_start + c.s * (target - q_start)
            if not c.rising:
                edges.append(PathEdge(c.s, False, t_c, q_c))
                continue
            if io_line != probe_line or lose_edge:
                # the edge happens on the probe line, but the guarded move does not see it
                edges.append(PathEdge(c.s, True, t_c, q_c, emit=not lose_edge))
                continue
            s_latch = min(1.0, c.s + latency / duration)
            s_stop = min(1.0, s_latch + self.scenario.probe.stop_time_s / duration)
            contact = GuardedContact(
                s_contact=c.s,
                s_latch=s_latch,
                s_stop=s_stop,
                q_latched=q_start + s_latch * (target - q_start),
                time_latch=t_start + s_latch * duration,
                speed_mps=self._tip_speed(q_start, target, c.s, duration),
            )
            return MotionPlan(
                q_start, target, t_start, duration, s_stop, io_line, tuple(edges), contact
            )
        return MotionPlan(q_start, target, t_start, duration, 1.0, io_line, tuple(edges))

    def _finish_guarded(self, plan: MotionPlan, s: float, stopped: bool) -> GuardedMoveResult:
        """The end of a guarded move stopped at path parameter s (edges already applied)."""
        assert plan.io_line is not None
        contact = plan.contact
        duration = s * plan.path_duration_s
        q_end = plan.q_start + s * (plan.q_target - plan.q_start)
        if contact is not None and contact.s_latch <= s:
            probe_line = self.scenario.probe.io_line
            self._inputs[probe_line] = True
            if self.on_io_edge is not None:
                self.on_io_edge(probe_line, True, contact.time_latch, contact.q_latched.copy())
            self._finish_motion(plan.q_start, q_end, duration)
            self._update_probe_input(emit=True)
            return GuardedMoveResult(
                contact=True,
                q_latched=contact.q_latched.copy(),
                q=q_end,
                duration_s=duration,
                io_line=plan.io_line,
                speed_mps=contact.speed_mps,
                reason="aborted" if stopped else None,
            )
        if contact is not None and contact.s_contact <= s:
            # touched, but stopped before the trigger latched: no contact reported
            q_touch = plan.q_start + contact.s_contact * (plan.q_target - plan.q_start)
            t_touch = plan.t_start + contact.s_contact * plan.path_duration_s
            self._set_probe_input(True, t_touch, q_touch, emit=False)
        if not stopped:
            q_end = plan.q_target.copy()
        self._finish_motion(plan.q_start, q_end, duration)
        return GuardedMoveResult(
            contact=False,
            q_latched=None,
            q=q_end.copy(),
            duration_s=duration,
            io_line=plan.io_line,
            reason="aborted" if stopped else "no_contact",
        )

    def _tip_speed(
        self, q_start: np.ndarray, target: np.ndarray, s: float, duration: float
    ) -> float:
        """Cartesian tip speed (m/s) at path parameter s (central difference)."""
        h = 1e-6
        s_pair = np.array([max(0.0, s - h), min(1.0, s + h)])
        q_rep = q_start[None, :] + s_pair[:, None] * (target - q_start)[None, :]
        moved = np.sign(target - q_start)
        approach = np.where(moved != 0, moved, self._approach)
        qp = self.physics.physical_angles(q_rep, self.current_zero_errors(), approach, self._time)
        tips = probe_mod.tip_positions(self.physics.flange_pose(qp, self._time), self.tip_flange)
        return float(np.linalg.norm(tips[1] - tips[0]) / ((s_pair[1] - s_pair[0]) * duration))

    # ------------------------------------------------------------------ cameras

    def renderers(self) -> tuple[Renderer, Renderer]:
        """(left, right) renderers with the truth intrinsics (built on first use)."""
        if self._renderers is None:
            cam = self.scenario.camera
            level = self.scenario.target.background_level
            self._renderers = (
                Renderer(
                    self.camera,
                    cam.pixel_noise_sigma,
                    cam.blur_sigma,
                    level,
                    _rng(self.scenario.seed, _STREAM_LEFT),
                ),
                Renderer(
                    self.camera,
                    cam.pixel_noise_sigma,
                    cam.blur_sigma,
                    level,
                    _rng(self.scenario.seed, _STREAM_RIGHT),
                ),
            )
        return self._renderers

    def chessboard_poses(self) -> np.ndarray:
        """(n_views, 4, 4) T_leftcamera_board of the rig-calibration views (truth)."""
        if self._board_views is None:
            board = self.scenario.chessboard
            self._board_views = chessboard_views(
                self.camera,
                self.T_left_right,
                self.board_pattern,
                board.n_views,
                (board.distance_min, board.distance_max),
                math.radians(board.max_tilt_deg),
                _rng(self.scenario.seed, _STREAM_VIEWS),
            )
        return self._board_views.copy()

    def chessboard_corners(self) -> np.ndarray:
        """(rows*cols, 3) inner corners in the board frame (m), row-major."""
        return self.board_pattern.corners()

    def capture_stereo(self, pattern: str = "target", view: int = 0) -> StereoFrame:
        """Render a stereo pair (left, right (H, W) uint8).

        pattern "target": the circular target seen from the robot's physical pose.
        pattern "chessboard": the `view`-th chessboard pose (relative to the left camera,
        independent of the robot). Raises SimulationRefused("invalid_argument") otherwise.
        """
        T_right_left = np.linalg.inv(self.T_left_right)
        left_r, right_r = self.renderers()
        if pattern == "target":
            T_left_target = np.linalg.inv(self.camera_pose()) @ self.T_base_target
            left = left_r.render_disk(T_left_target, self.disk_pattern)
            right = right_r.render_disk(T_right_left @ T_left_target, self.disk_pattern)
        elif pattern == "chessboard":
            n_views = self.scenario.chessboard.n_views
            if not (isinstance(view, int) and 0 <= view < n_views):
                raise SimulationRefused(
                    "invalid_argument", f"chessboard view {view!r} not in 0..{n_views - 1}"
                )
            T_left_board = self.chessboard_poses()[view]
            left = left_r.render_chessboard(T_left_board, self.board_pattern)
            right = right_r.render_chessboard(T_right_left @ T_left_board, self.board_pattern)
        else:
            raise SimulationRefused("invalid_argument", f"unknown pattern {pattern!r}")
        return StereoFrame(left=left, right=right, q=self._q.copy(), time=self._time)

    def camera_description(self) -> dict[str, Any]:
        """What the controller reports about its camera: never the hidden truth."""
        sc = self.scenario
        cam, tgt, board = sc.camera, sc.target, sc.chessboard
        return {
            "image_width": cam.image_width,
            "image_height": cam.image_height,
            "baseline_nominal": cam.baseline,
            "T_flange_camera_nominal": {"xyz": list(cam.mount.xyz), "rpy": list(cam.mount.rpy)},
            "target": {
                "radius": tgt.radius,
                "centre_nominal": list(tgt.centre),
                "normal": list(tgt.normal),
                "plate_radius": tgt.plate_radius,
            },
            "chessboard": {
                "cols": board.cols,
                "rows": board.rows,
                "square_size": board.square_size,
                "n_views": board.n_views,
            },
            "probe": {
                "tip_nominal": list(sc.probe.tip),
                "stylus_radius": sc.probe.stylus_radius,
                "sphere_centre_nominal": list(sc.probe.sphere_centre),
                "sphere_radius": sc.probe.sphere_radius,
                "io_line": sc.probe.io_line,
                "repeatability": sc.probe.repeatability_sigma,
            },
        }

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
        }
