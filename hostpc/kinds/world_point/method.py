"""world_point: a laser tracker in the cell measures a reflector (SMR) on the flange.

Per pose: move, `measure_tracker`, and record the sample `q` (joint angles at the
measurement), `marker` (the reflector's name), `p` (m, in the tracker's frame = `world`),
`cov` (m^2, the tracker's own anisotropic noise), `t` and `approach`. A reflector whose beam
is lost (line of sight outside its acceptance cone) is journaled as a skipped pose.

Nominal frames, in order (later wins): the tracker's description (`world_base`: its
registration of the robot base; `reflectors`: the nest positions in the flange), then the
`--cell` file's `world` ({xyz, rpy}) and `markers` ({name: [x, y, z]}). `--known world`
says the base-in-world registration is surveyed, `--known markers` that the reflector sits
in a dowel-pinned nest of known position; what is not known is estimated by the fit.

Which zero offsets this can find depends on that (:func:`identifiable_offsets`): joint 1's
zero is only defined against a known base-in-world registration (otherwise a turn of the
base about joint 1's axis is the same data), the last joint's only against a marker known
in the flange frame (otherwise the marker's position about the last axis absorbs it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, dataset_to_dict
from hostpc.errors import ControllerError, InputError
from hostpc.files import write_json_atomic
from hostpc.kinds.world_point.file_face import WorldPointFile
from hostpc.kinds.world_point.sample import WorldPointSample, world_point_samples
from hostpc.kinematics import forward, get_robot, pose_to_transform
from hostpc.methods.approach_moves import ApproachMoves
from hostpc.methods.base import (
    Method,
    Phase,
    Progress,
    SampleRecord,
    floats,
    matrix,
)
from hostpc.planning.design import ShortPlan, sine_swings
from hostpc.robots.base import Need, RobotAdapter, RobotState, tracker_of

TRACKER_FILE = "tracker.json"
LOS_MARGIN_DEG = 10.0
"""Candidates keep the reflector this far inside its acceptance cone (nominal model), so
the real robot's small errors never lose the beam at a planned pose."""
POOL_SPREAD = 1.2
"""rad: candidates lie within this of the robot's pose on every joint but the last (and
inside the limits), so the tour's moves stay short. Over the whole +-170 deg a short plan's
poses sat 100-170 deg apart: about 1 s per move at --speed 0.5 against 0.4 s of settling
and reading per pose (20.3 s of robot time for 8 + 4 poses in the held-out worlds of
docs/performance.md, "world_point and dual_loop"), and the sigma of that plan was too small
(MSE / sigma^2 1.77 on joint 4 over 40 worlds). The last joint keeps its whole range: its
turn carries the reflector about its axis, which is all that defines its zero with a
known nest."""


PATH_FREQUENCIES = (2.0, 3.0, 2.5, 3.5, 4.0, 1.5)
"""Swings of each joint (from the first) along one candidate path (`smooth_path`): all
different, so the joints' angles are not correlated along it."""
PATH_CYCLES = 1.0
"""Each joint swings PATH_CYCLES x its PATH_FREQUENCIES along one path."""
PATHS = 20
"""At most this many paths (random phases) fill the candidate pool: the reflector faces the
tracker along about a fifth of a path."""


def smooth_path(low: np.ndarray, high: np.ndarray, n: int, rng: np.random.Generator
                ) -> np.ndarray:
    """(n, len(low)) poses along one smooth path through the box [low, high]: joint j
    swings between its bounds as a sine of PATH_CYCLES * PATH_FREQUENCIES[j] periods over
    the path (random phases), so neighbours on the path differ by little in every joint."""
    swing = sine_swings(n, PATH_CYCLES * np.resize(np.asarray(PATH_FREQUENCIES), low.size),
                        rng)
    return np.asarray(0.5 * (low + high) + 0.5 * (high - low) * swing)


def identifiable_offsets(n_joints: int, known: Sequence[str]) -> tuple[list[int], list[str]]:
    """(joints whose zero offset the data define, 1-based; one sentence per joint that is
    not) for a world_point cell with the frames ``known``."""
    joints = list(range(1, n_joints + 1))
    notes = []
    if "world" not in known:
        joints.remove(1)
        notes.append("joint 1's zero needs a known base-in-world registration (--known world)")
    if "markers" not in known:
        joints.remove(n_joints)
        notes.append(f"joint {n_joints}'s zero needs a reflector known in the flange frame "
                     "(a dowel-pinned nest: --known markers)")
    return joints, notes


def spherical_covariance(p: np.ndarray, sigma_distance: float, sigma_angle: float
                         ) -> np.ndarray:
    """(N, 3, 3) covariance of points p (N, 3) (m, tracker frame) measured as distance plus
    two angles: ``sigma_distance^2`` along the line of sight, ``(r sigma_angle)^2`` across."""
    r = np.linalg.norm(p, axis=1)
    u = p / np.maximum(r, 1e-9)[:, None]
    radial = u[:, :, None] * u[:, None, :]
    across = (r * sigma_angle) ** 2
    cov: np.ndarray = sigma_distance**2 * radial + across[:, None, None] * (np.eye(3) - radial)
    return cov


class WorldPointMethod(Method):
    """See the module docstring. options: none beyond the run settings."""

    name: ClassVar[str] = "world_point"
    default_target_sigma_deg: ClassVar[float | None] = 0.002
    needs: ClassVar[tuple[Need, ...]] = (Need.TRACKER,)
    staged: ClassVar[bool] = True
    short_plan: ClassVar[ShortPlan] = ShortPlan(shorten="tour")

    def __init__(self, settings: Any, cell: Any, run_dir: Path) -> None:
        super().__init__(settings, cell, run_dir)
        self._chain = get_robot(cell.robot)
        self._description: dict[str, Any] | None = None
        self._t0 = 0.0
        # an approach-dependent effect (backlash) in the model: each joint arrives from
        # both sides, through via-points where needed (methods/approach_moves.py)
        self._moves = ApproachMoves(settings, self._chain)
        self._joint_estimate = np.zeros(self._chain.n)  # set_joint_estimate

    def set_joint_estimate(self, estimate: np.ndarray, new_stage: bool = False) -> None:
        """The reflector facing the tracker is chosen with the joints' estimate."""
        self._joint_estimate = np.asarray(estimate, float)

    def sample_clock(self) -> WorldPointMethod:
        return self

    def set_time_origin(self, t0: float) -> None:
        """Controller time (s) at the start of the run: sample `t` counts from here."""
        self._t0 = float(t0)

    @property
    def tracker_path(self) -> Path:
        return self.run_dir / TRACKER_FILE

    # ---------------------------------------------------------------- set-up

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Read the tracker's description (kept in the run folder for a resume)."""
        import json


        if self.tracker_path.is_file():
            self._description = json.loads(self.tracker_path.read_text(encoding="utf-8"))
        else:
            reading = await tracker_of(robot, f"--method {self.name}").measure_tracker()
            self._description = dict(reading.description)
            write_json_atomic(self.tracker_path, self._description)
        joints, notes = identifiable_offsets(self._chain.n, self.cell.known)
        progress.message(f"world_point: known {', '.join(self.cell.known) or 'nothing'}; "
                         f"offsets defined for joints {', '.join(map(str, joints))}")
        for note in notes:
            progress.message(f"world_point: {note}")

    @property
    def description(self) -> dict[str, Any]:
        if self._description is None:
            raise ControllerError("world_point: prepare() was not run")
        return self._description

    def world(self) -> dict[str, list[float]]:
        """Nominal base-in-world pose {xyz, rpy} (cell file, else the tracker's)."""
        spec = self.cell.raw.get("world") or self.description.get("world_base")
        if not isinstance(spec, Mapping) or "xyz" not in spec:
            raise InputError("cell: no base-in-world registration (world) from the tracker "
                             "or the --cell file")
        return {"xyz": [float(v) for v in spec["xyz"]],
                "rpy": [float(v) for v in spec.get("rpy", [0.0, 0.0, 0.0])]}

    def markers(self) -> dict[str, list[float]]:
        """Nominal reflector positions in the flange {name: [x, y, z]} (m)."""
        spec = self.cell.raw.get("markers") or self.description.get("reflectors")
        if not isinstance(spec, Mapping) or not spec:
            raise InputError("cell: no reflector positions (markers) from the tracker or the "
                             "--cell file")
        return {str(k): [float(v) for v in xyz] for k, xyz in spec.items()}

    # ---------------------------------------------------------------- planning

    def _visible_marker(self, q: np.ndarray) -> np.ndarray:
        """(N,) index into markers() of the reflector best inside its cone at each pose
        (nominal model), -1 where none is inside by LOS_MARGIN_DEG."""
        world = self.world()
        T_world_flange = pose_to_transform(world["xyz"], world["rpy"]) @ forward(
            self._chain, q).T_base_flange
        axes = self.description.get("axes", {})
        limit = math.cos(math.radians(float(self.description.get("acceptance_deg", 45.0))
                                      - LOS_MARGIN_DEG))
        best = np.full(q.shape[0], -1)
        best_cos = np.full(q.shape[0], limit)
        for k, (name, xyz) in enumerate(self.markers().items()):
            p = T_world_flange[:, :3, :3] @ np.asarray(xyz) + T_world_flange[:, :3, 3]
            axis = T_world_flange[:, :3, :3] @ np.asarray(axes.get(name, [0.0, 0.0, 1.0]))
            cos = np.einsum("ni,ni->n", axis, -p) / (
                np.linalg.norm(axis, axis=1) * np.linalg.norm(p, axis=1))
            better = cos >= best_cos
            best[better], best_cos[better] = k, cos[better]
        return best

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """Poses near the robot's pose (POOL_SPREAD) and within the limits (10 deg margin)
        that see a reflector: the pieces of smooth paths through that box (`smooth_path`,
        up to PATHS of them) where the reflector faces the tracker, each piece in its path
        order. Neighbours on a path differ by little in every joint, so the travel-aware
        selection finds informative poses a short move apart (a move's time is its largest
        joint motion: between two random poses of the box some joint always moves far):
        robot time 14.3-17.3 s in world 201 for planning seeds 0-5, against 15.6-21.2 s
        from uniform random poses (docs/performance.md)."""
        self._moves.bound(state.q_min, state.q_max)
        margin = math.radians(10.0)
        spread = np.full(state.q.size, POOL_SPREAD)
        spread[-1] = math.pi
        low = np.maximum(np.maximum(state.q_min + margin, -math.pi), state.q - spread)
        high = np.minimum(np.minimum(state.q_max - margin, math.pi), state.q + spread)
        pool = []
        wanted = self.settings.n_candidates
        for _ in range(PATHS):
            q = smooth_path(low, high, wanted, rng)
            pool.append(q[self._visible_marker(q) >= 0])
            if sum(len(p) for p in pool) >= wanted:
                break
        return np.concatenate(pool)[:wanted]

    def _noise(self) -> tuple[float, float]:
        d = self.description
        return float(d.get("sigma_distance", 1e-5)), float(d.get("sigma_angle", 5e-6))

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Nominal predicted points at q (N, n) (one reflector per pose) with the tracker's
        noise model."""
        world = self.world()
        names = list(self.markers())
        chosen = np.maximum(self._visible_marker(q), 0)
        positions = np.array([self.markers()[names[k]] for k in chosen])
        T = pose_to_transform(world["xyz"], world["rpy"]) @ forward(self._chain,
                                                                     q).T_base_flange
        p = np.einsum("nij,nj->ni", T[:, :3, :3], positions) + T[:, :3, 3]
        cov = spherical_covariance(p, *self._noise())
        return self.samples_dataset(
            [WorldPointSample(q=floats(q[k]), marker=names[chosen[k]], p=floats(p[k]),
                              cov=matrix(cov[k]), t=float(k)) for k in range(q.shape[0])])

    # ---------------------------------------------------------------- acquisition

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        """Move to q and read the tracker (see the module docstring)."""
        outcome = await self._moves.move(robot, phase, index, q, q_from)
        if isinstance(outcome, SampleRecord):
            return outcome
        reading = await tracker_of(robot, f"--method {self.name}").measure_tracker()
        names = list(self.markers())
        wanted = names[max(int(self._visible_marker(
            np.asarray(q, float)[None] + self._joint_estimate)[0]), 0)]
        name = wanted if wanted in reading.points else next(iter(reading.points), None)
        if name is None:
            lost = ", ".join(reading.lost) or "no reflector"
            return SampleRecord(phase, index, False, reason=f"beam lost: {lost}",
                                q_end=outcome.q.tolist())
        p, cov = reading.points[name]
        sample = WorldPointSample(q=floats(reading.q), marker=name, p=floats(p),
                                  cov=matrix(cov), t=float(reading.time) - self._t0,
                                  approach=floats(self._moves.signs(q_from, reading.q)))
        return SampleRecord.measured(phase, index, sample, q_end=outcome.q.tolist())

    # ---------------------------------------------------------------- dataset

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """A `zerocal-dataset/1` world_point document with the nominal frames and `known`
        (`dataset`, written)."""
        return dataset_to_dict(self.dataset(samples))

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled samples as the run's Dataset, built from the typed samples (the
        same as reading ``dataset_document``). A subclass with its own samples and file
        form (a plugin kind on world_point's instrument: tests/kinds_example/tracker_range)
        is read from its document."""
        if type(self).dataset_document is not WorldPointMethod.dataset_document:
            return super().dataset(samples)
        return self.samples_dataset([WorldPointSample.from_json(s) for s in samples])

    def samples_dataset(self, typed: Sequence[WorldPointSample]) -> Dataset:
        """`dataset` of typed samples."""
        world = self.world()
        dataset = Dataset(
            method=self.name, robot=RobotDescription(name=self.cell.robot),
            frames={"world": FramePose(xyz=np.asarray(world["xyz"]),
                                       rpy=np.asarray(world["rpy"])),
                    "markers": {k: np.asarray(v, dtype=float)
                                for k, v in self.markers().items()}},
            samples=world_point_samples(typed, self._chain.n),
            known=tuple(k for k in self.cell.known if k in ("world", "markers")))
        WorldPointFile().check_samples(dataset.samples, dataset.frames)
        return dataset

    def describe(self) -> dict[str, Any]:
        """What is known and which offsets the data define, for the result document."""
        joints, notes = identifiable_offsets(self._chain.n, self.cell.known)
        return {"known": list(self.cell.known), "identifiable_offsets": joints,
                "not_identifiable": notes}
