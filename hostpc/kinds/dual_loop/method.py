"""dual_loop: a humanoid's head camera measures a target on each arm's flange.

The robot is a kinematic tree (`hostpc.kinematics.humanoid`, e.g. `humanoid_upper`): a
pan-tilt head carrying a stereo camera and two arms, one combined joint vector
`head (2), left (7), right (7)` in the controller's order. The controller triangulates the
targets itself and answers `measure_targets` (docs/protocol.md) with every target in view,
each with its covariance; the method never sees images. Both loops are solved jointly by
the shared runner (`hostpc.fit`, Mahalanobis: each point whitened by its own covariance).

Per plan pose: move all 16 joints, `measure_targets`, and record one observation per arm
whose target is in view, a `TargetObservation` (`chain`, `q_head`, `q_arm`, `p` (m, camera
frame), `cov` (m^2), `t` (s since the run started), `approach` (the arm's joints);
hostpc.kinds.dual_loop.sample). The journal keeps one record per pose,
`PoseObservations` in its JSON form `{"observations": [...]}`; `dataset` flattens them into
the samples of a Dataset. A pose with no target in view is journaled as skipped.

Planning: every candidate measures both arms in one move, one settle and one capture:
`hostpc.kinds.dual_loop.planning.plan_paired_poses` (both arms around the home pose, the
head aimed between their targets, nominal model), kept when both targets fall inside both
images (the camera's nominal focal length, baseline and image size) and all joints are
inside the controller's limits. The design dataset has two samples per pose, left then
right (`Method.design_dataset`'s pose-major form: the planner stacks them into one block
per pose), each with the expected stereo covariance: lateral `z s / f`, depth
`sqrt(2) z^2 s / (f b)` for a centroid precision `s` (option `pixel_sigma`, default 0.15
px).

Frames (docs/dual-loop.md): `camera` (`T_headend_camera`), `left_base`, `right_base`
(`T_headbase_armbase`) and `left_target`, `right_target` (point in the flange), nominal from
the built-in tree, overridden by the controller's description (`T_headend_camera_nominal`)
and the `--cell` file (same names); `known` lists those held fixed. With nothing known, six
zero offsets cannot be told apart from the frames (`head.q1`, `head.q2`, each arm's `q1` and
`q7`): the fit holds them at nominal and the push leaves them unchanged.

Head camera calibration: a controller that reports its own calibration of the stereo pair
(`calibration`: a rig document and its (24, 24) covariance, in the camera description or
the `--cell` file) and each target's pixel centres (`uv`) gets that covariance propagated
into the fit's parameter covariance, with the correlation it induces across samples: the
dataset carries the `rig_uncertainty` block of stereo_target (hostpc.fitting.shared_errors,
docs/vision.md section 3.4). The pixel floor is then a weighting only, as for stereo_target.

Units: SI and radians (docs/conventions.md).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, dataset_to_dict
from hostpc.errors import InputError
from hostpc.kinds.dual_loop.model import ARMS, DUAL_LOOP_FRAMES
from hostpc.kinds.dual_loop.planning import nominal_frames, plan_paired_poses
from hostpc.kinds.dual_loop.sample import (
    PoseObservations,
    TargetObservation,
    observation_samples,
)
from hostpc.kinematics.humanoid import get_tree
from hostpc.kinematics.rotations import pose_to_transform
from hostpc.kinematics.tree import KinematicTree
from hostpc.methods.base import (
    Method,
    Phase,
    Progress,
    RunSettings,
    SampleRecord,
    floats,
    matrix,
    move_or_skip,
)
from hostpc.methods.cell import Cell
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from hostpc.robots.base import (
    Need,
    RobotAdapter,
    RobotState,
    TargetMeasurement,
    check_needs,
    targets_of,
)

PLANNING_PIXEL_SIGMA = 0.15
"""Planning noise model: centroid precision (px per image coordinate) of the controller's
stereo front end (the simulator's value)."""
DEFAULT_FOCAL_PX = 1400.0
DEFAULT_BASELINE = 0.12
DEFAULT_IMAGE_SIZE = (1280, 1024)
IMAGE_MARGIN_PX = 20.0
"""A planned target must project at least this far inside both images (nominal model)."""
"""Controller refusals that skip one pose instead of ending the run."""
POSE_FRAMES = ("camera", "left_base", "right_base")
POINT_FRAMES = ("left_target", "right_target")


def cell_frames(cell: Cell, tree: KinematicTree) -> dict[str, FramePose | np.ndarray]:
    """The nominal dual_loop frames: the built-in tree's, overridden by the cell description
    (`camera` or the controller's `T_headend_camera_nominal`, `left_base`, `right_base` as
    `{"xyz", "rpy"}`; `left_target`, `right_target` as `[x, y, z]`; SI units)."""
    frames = nominal_frames(tree.name)
    raw = dict(cell.raw)
    for name in POSE_FRAMES:
        spec = raw.get(name)
        if spec is None and name == "camera":
            spec = raw.get("T_headend_camera_nominal")
        if spec is None:
            continue
        if not isinstance(spec, Mapping):
            raise InputError(f"cell {name}: expected {{\"xyz\": [..], \"rpy\": [..]}}, "
                             f"got {spec!r}")
        frames[name] = FramePose(xyz=_vector(spec.get("xyz"), f"{name}.xyz"),
                                 rpy=_vector(spec.get("rpy", [0.0, 0.0, 0.0]), f"{name}.rpy"))
    for name in POINT_FRAMES:
        if raw.get(name) is not None:
            frames[name] = _vector(raw[name], name)
    return frames


def _vector(value: Any, where: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"cell {where}: expected 3 numbers, got {value!r}") from None
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise InputError(f"cell {where}: expected 3 finite numbers, got {value!r}")
    return array


def tree_with_frames(tree: KinematicTree, frames: Mapping[str, FramePose | np.ndarray]
                     ) -> KinematicTree:
    """The tree with its dual_loop frames (and the arms' mounts) set to `frames`."""
    transforms: dict[str, np.ndarray] = {}
    for name in POSE_FRAMES:
        pose = frames[name]
        assert isinstance(pose, FramePose)
        transforms[name] = pose_to_transform(pose.xyz, pose.rpy)
    for name in POINT_FRAMES:
        transforms[name] = np.asarray(frames[name], dtype=float)
    branches = tuple(
        dataclasses.replace(b, T_parent_base=transforms[f"{b.name}_base"])
        if f"{b.name}_base" in transforms else b
        for b in tree.branches)
    return KinematicTree(name=tree.name, branches=branches, frames=transforms)


def camera_calibration(spec: Any) -> tuple[Any, np.ndarray] | None:
    """(StereoRig, (24, 24) covariance) of a `calibration` entry ({"rig": <rig document>,
    "covariance": [[...]]}), None if absent; a malformed entry is one InputError line."""
    if spec is None:
        return None
    from hostpc.vision.rig import rig_from_dict
    from hostpc.vision.rig_uncertainty import N_RIG

    if not isinstance(spec, Mapping):
        raise InputError(f"camera calibration: expected {{\"rig\": .., \"covariance\": ..}}, "
                         f"got {type(spec).__name__}")
    rig = rig_from_dict(spec.get("rig"), "camera calibration rig")
    try:
        covariance = np.asarray(spec.get("covariance"), dtype=float)
    except (TypeError, ValueError):
        raise InputError("camera calibration covariance: not a numeric matrix") from None
    if covariance.shape != (N_RIG, N_RIG) or not np.all(np.isfinite(covariance)):
        raise InputError(f"camera calibration covariance: expected {N_RIG} x {N_RIG} finite "
                         f"numbers, got shape {covariance.shape}")
    if not np.allclose(covariance, covariance.T, rtol=1e-9, atol=0.0) or \
            np.min(np.linalg.eigvalsh(0.5 * (covariance + covariance.T))) < \
            -1e-9 * max(1e-300, float(np.max(np.abs(covariance)))):
        raise InputError("camera calibration covariance: not symmetric positive "
                         "semi-definite")
    return rig, covariance


class DualLoopMethod(Method):
    """See the module docstring. options: `pixel_sigma` (px, the planning noise model),
    `pixel_floor` (px per image coordinate, added to each measured covariance as for
    stereo_target; 0 = the controller's covariance as reported)."""

    name: ClassVar[str] = "dual_loop"
    default_target_sigma_deg: ClassVar[float | None] = 0.02
    needs: ClassVar[tuple[Need, ...]] = (Need.TARGETS,)

    def __init__(self, settings: RunSettings, cell: Cell, run_dir: Path) -> None:
        super().__init__(settings, cell, run_dir)
        self.tree = get_tree(cell.robot)
        self.frames = cell_frames(cell, self.tree)
        self.planning_tree = tree_with_frames(self.tree, self.frames)
        unknown = [k for k in cell.known if k not in DUAL_LOOP_FRAMES]
        if unknown:
            raise InputError(f"--known {','.join(unknown)}: not a dual_loop frame (expected "
                             f"{', '.join(DUAL_LOOP_FRAMES)} or none)")
        self.known = tuple(cell.known)
        raw = dict(cell.raw)
        self.focal_px = float(raw.get("focal_px", raw.get("focal_px_nominal",
                                                            DEFAULT_FOCAL_PX)))
        self.baseline = float(cell.baseline or DEFAULT_BASELINE)
        self.image_size = tuple(cell.image_size or DEFAULT_IMAGE_SIZE)
        self.pixel_sigma = float(settings.options.get("pixel_sigma", PLANNING_PIXEL_SIGMA))
        self.pixel_floor = float(settings.options.get("pixel_floor", 0.0) or 0.0)
        if not (self.focal_px > 0 and self.baseline > 0 and self.pixel_sigma > 0):
            raise InputError("dual_loop: focal length, baseline and pixel_sigma must be "
                             "positive")
        self.calibration = camera_calibration(raw.get("calibration"))
        self._t0 = 0.0
        self._progress: Progress | None = None  # prepare's, for the dataset's notes

    def sample_clock(self) -> DualLoopMethod:
        return self

    def set_time_origin(self, t0: float) -> None:
        """Controller time (s) at the start of the run: sample `t` counts from here."""
        self._t0 = float(t0)

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Nothing to set up; the robot must triangulate targets itself (`needs`: the
        runner checks it before this; checked here too for use without the runner)."""
        check_needs(robot, self.needs, f"--method {self.name}")
        progress.message(f"dual_loop: {self.tree.name}, known frames: "
                         f"{', '.join(self.known) or 'none'}")
        self._progress = progress
        progress.message("head camera calibration: " + (
            "reported with its covariance (its error enters the sigmas)"
            if self.calibration is not None else
            "not reported by the controller (the sigmas cover the pixel noise only)"))

    # ---------------------------------------------------------------- planning

    def _check_joints(self, n: int) -> None:
        if n != self.tree.n:
            raise InputError(f"the controller reports {n} joints, but {self.tree.name} has "
                             f"{self.tree.n} ({', '.join(b.name for b in self.tree.branches)})")

    def camera_points(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Nominal target of each arm in the camera frame at combined poses q (N, n):
        side -> (N, 3) m."""
        tree = self.planning_tree
        frames = tree.root_transforms(np.asarray(q, dtype=float))
        T_hb_camera = frames["head"][1] @ tree.frames["camera"]
        R, t = T_hb_camera[:, :3, :3], T_hb_camera[:, :3, 3]
        out = {}
        for side in ARMS:
            T = frames[side][1]
            p = T[:, :3, :3] @ tree.frames[f"{side}_target"] + T[:, :3, 3]
            out[side] = np.einsum("nji,nj->ni", R, p - t)
        return out

    def visible(self, p: np.ndarray) -> np.ndarray:
        """(N,) points p (N, 3) (camera frame) inside both images with the margin."""
        width, height = self.image_size
        z = p[:, 2]
        zs = np.where(z > 0.05, z, 1.0)
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        u_left = self.focal_px * p[:, 0] / zs + cx
        u_right = self.focal_px * (p[:, 0] - self.baseline) / zs + cx
        v = self.focal_px * p[:, 1] / zs + cy
        m = IMAGE_MARGIN_PX
        ok = (z > 0.05) & (v > m) & (v < height - 1 - m)
        for u in (u_left, u_right):
            ok &= (u > m) & (u < width - 1 - m)
        return np.asarray(ok)

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """(N_c, n) combined poses that measure both arms, in order along one smooth path
        (`plan_paired_poses`: both arms swinging about home, the head aimed between their
        targets); both targets inside both images, all joints within the controller's
        limits."""
        self._check_joints(int(state.q.size))
        q = plan_paired_poses(int(self.settings.n_candidates), rng, tree=self.planning_tree)
        points = self.camera_points(q)
        keep = np.all((q >= state.q_min) & (q <= state.q_max), axis=1)
        for side in ARMS:
            keep &= self.visible(points[side])
        if not np.any(keep):
            raise InputError("dual_loop planning: no pose sees both arms' targets; check "
                             "the cell frames")
        return q[keep]

    def expected_covariance(self, p: np.ndarray, sigma_px: float) -> np.ndarray:
        """(N, 3, 3) covariance of points p (N, 3) (camera frame) triangulated from image
        centres with sigma_px per coordinate (diagonal approximation)."""
        z = np.maximum(np.abs(p[:, 2]), 1e-3)
        cov = np.zeros((p.shape[0], 3, 3))
        lateral = z * sigma_px / self.focal_px
        cov[:, 0, 0] = cov[:, 1, 1] = lateral**2
        cov[:, 2, 2] = (z**2 * math.sqrt(2.0) * sigma_px / (self.focal_px * self.baseline)) ** 2
        return cov

    def floor_covariance(self, p: np.ndarray) -> np.ndarray:
        """(3, 3) the pixel floor's covariance at a point p (3,), with the calibrated focal
        length and baseline when the controller reports its calibration (the same model
        shared_errors.floor_covariance takes back out), else the nominal ones."""
        if self.calibration is None:
            return self.expected_covariance(p[None, :], self.pixel_floor)[0]
        rig = self.calibration[0]
        z = max(abs(float(p[2])), 1e-3)
        fx, baseline = float(rig.K_left[0, 0]), float(np.linalg.norm(rig.T))
        lateral = (z * self.pixel_floor / fx) ** 2
        depth = (z**2 * math.sqrt(2.0) * self.pixel_floor / (fx * baseline)) ** 2
        return np.diag([lateral, lateral, depth])

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Two samples per pose q (N, n), left then right (pose-major: the planner stacks
        a pose's samples into one block), with the nominal predicted points and the
        planning covariance."""
        q = np.asarray(q, dtype=float)

        def samples(p: np.ndarray, cov: np.ndarray) -> list[TargetObservation]:
            return [self._observation(ARMS[k % 2], q[k // 2], p[k], cov[k], float(k // 2),
                                      None, None) for k in range(2 * q.shape[0])]

        placeholder = np.broadcast_to(np.array([0.0, 0.0, 0.5]), (2 * q.shape[0], 3))
        eye = np.broadcast_to(np.eye(3) * 1e-8, (2 * q.shape[0], 3, 3))
        problem = build_problem(self.observations_dataset(samples(placeholder, eye)),
                                "joint_offsets")
        p, _ = predict(problem, np.zeros(problem.layout.size), jacobian=False)
        cov = self.expected_covariance(p, self.pixel_sigma)
        return self.observations_dataset(samples(p, cov))

    # ---------------------------------------------------------------- acquisition

    def _observation(self, side: str, q: np.ndarray, p: np.ndarray, cov: np.ndarray,
                     t: float, q_from: np.ndarray | None, uv: np.ndarray | None
                     ) -> TargetObservation:
        """One observation (SI) of the target on arm `side` at q (n,)."""
        arm = self.tree.joint_slice(side)
        approach = None
        if q_from is not None:
            signs = np.sign(q[arm] - np.asarray(q_from, dtype=float)[arm])
            approach = tuple(float(s) if s != 0 else 1.0 for s in signs)
        return TargetObservation(
            chain=side, q_head=floats(q[self.tree.joint_slice("head")]), q_arm=floats(q[arm]),
            p=floats(p), cov=matrix(cov), t=t, approach=approach,
            uv=None if uv is None else matrix(np.asarray(uv, dtype=float).reshape(2, 2)))

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        """Move to q (n,), measure the targets in view: one observation per arm seen."""
        outcome = await move_or_skip(robot, self.settings.speed, phase, index, q, q_from)
        if isinstance(outcome, SampleRecord):
            return outcome
        q_end = [float(v) for v in outcome.q]
        camera = targets_of(robot, f"--method {self.name}")  # checked by the runner (needs)
        measurement: TargetMeasurement = await camera.measure_targets()
        q_seen = np.asarray(measurement.q, dtype=float)
        self._check_joints(int(q_seen.size))
        observations = []
        for target in sorted(measurement.targets, key=lambda t: t.chain):
            if target.chain not in ARMS:
                continue
            cov = np.asarray(target.cov, dtype=float)
            if self.pixel_floor > 0:
                cov = cov + self.floor_covariance(np.asarray(target.p))
            observations.append(self._observation(
                target.chain, q_seen, np.asarray(target.p), cov,
                float(measurement.t) - self._t0, q_from,
                None if target.uv is None else np.asarray(target.uv, dtype=float)))
        if not observations:
            return SampleRecord(phase, index, False, reason="no target in view", q_end=q_end)
        return SampleRecord.measured(phase, index, PoseObservations(tuple(observations)),
                                     q_end=q_end)

    # ---------------------------------------------------------------- dataset

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """A `zerocal-dataset/1` dual_loop document (`dataset`, written)."""
        return dataset_to_dict(self.dataset(samples))

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled records' observations (or plain samples) in order as a Dataset
        with the nominal frames and `known`, built from the typed observations."""
        return self.observations_dataset(
            [o for record in samples for o in PoseObservations.from_json(record).observations])

    def observations_dataset(self, observations: Sequence[TargetObservation]) -> Dataset:
        """`dataset` of typed observations."""
        frames = {name: self.frames[name] for name in DUAL_LOOP_FRAMES}
        return Dataset(method=self.name, robot=RobotDescription(name=self.tree.name),
                       frames=frames, samples=observation_samples(observations),
                       known=tuple(self.known),
                       extra_fields=self._camera_uncertainty(observations))

    def _camera_uncertainty(self, samples: Sequence[TargetObservation]) -> dict[str, Any]:
        """The dataset's `rig_uncertainty` block (the head camera's calibration, its
        covariance and the pixel floor the covariances include), or nothing when the
        controller reports no calibration or a sample has no `uv`."""
        if self.calibration is None or not samples:
            return {}
        missing = sum(s.uv is None for s in samples)
        if missing:
            if self._progress is not None:
                self._progress.message(
                    f"head camera calibration not propagated: {missing} of {len(samples)} "
                    "target observations came without pixel centres (uv); the sigmas cover "
                    "the pixel noise only")
            return {}
        from hostpc.vision.rig_uncertainty import uncertainty_document

        rig, covariance = self.calibration
        return {"rig_uncertainty": uncertainty_document(rig, covariance, self.pixel_floor)}

    def describe(self) -> dict[str, Any]:
        """The tree, frames and camera model for the result document (SI)."""
        return {"dual_loop": {
            "tree": self.tree.name,
            "joints": list(self.tree.joint_labels),
            "frames": {name: ({"xyz": value.xyz.tolist(), "rpy": value.rpy.tolist()}
                              if isinstance(value, FramePose)
                              else np.asarray(value, dtype=float).tolist())
                       for name, value in self.frames.items()},
            "known": list(self.known),
            "camera": {"focal_px": self.focal_px, "baseline": self.baseline,
                       "image_size": list(self.image_size)},
            "planning_pixel_sigma": self.pixel_sigma,
            "pixel_floor": self.pixel_floor,
        }}
