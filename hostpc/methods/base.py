"""The interface between a measurement method and the shared calibration runner.

A method is one module with one `Method` subclass. It knows its sensor and nothing of the
procedure around it:

    prepare(robot, progress)        sensor set-up before any pose (stereo_target: the rig,
                                    calibrated from chessboard captures unless given);
                                    persist what it made in `run_dir` so resume never redoes it
    candidates(state, rng)          a large pool of reachable joint poses (N_c, n) from which
                                    the planner picks the informative ones
    design_dataset(q)               a Dataset at poses q with predicted measurements and their
                                    expected covariances (nominal model): the planner's and the
                                    identifiability check's Jacobian comes from it; k samples
                                    per pose (the same k for every pose), pose-major
    acquire(robot, phase, index, q, q_from)
                                    drive to one pose and measure: the kind's typed sample
                                    (a frozen dataclass, `Sample`) journaled through its
                                    `to_json` (`SampleRecord.measured`), or skipped with the
                                    reason
    dataset_document(records)       the journaled samples (their JSON form) as a
                                    `zerocal-dataset/1` document
    dataset(records)                the journaled samples as the run's Dataset (built-in
                                    kinds: read back with the kind's `from_json` and built
                                    from the typed samples; default: from dataset_document)

Optional hooks (defaults in `Method`):

    default_effects()               the effect spec fitted when the user gives no --effects
                                    (None: the dataset's default model)
    pose_groups(pool)               candidates that must be measured together (sphere_probe:
                                    the 5 contacts of one orientation): the planner then
                                    selects, orders and verifies whole groups
    sample_clock()                  a `SampleClock` if the samples' `t` counts controller time
                                    from the run's start (the runner sets the origin)

What a method needs of the robot beyond `RobotAdapter` it declares in `needs` (e.g.
dual_loop: `Need.TARGETS`, the controller's `measure_targets`); the runner checks it once,
before `prepare` (hostpc.robots.base.check_needs).

The runner (`hostpc.calibrate.runner`) owns everything else: reading the controller's state
and offsets, planning (`hostpc.planning.design`), the identifiability check, the journal
and resume, the fit, the guarded push, verification, the result document and the report.
Methods never print; they report through the `Progress` they are given.

Units: SI and radians (docs/conventions.md); q arrays (N, n) in the controller's frame.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

from hostpc.dataset import Dataset, Samples
from hostpc.json_object import JsonObject
from hostpc.methods.cell import Cell
from hostpc.planning.design import PoseGroups, ShortPlan
from hostpc.robots.base import MoveOutcome, Need, RobotAdapter, RobotState

Phase = Literal["fit", "verify"]
SKIP_REASONS = ("joint_limit", "refused_fault", "invalid_argument")
"""Controller refusals of a move that skip that one pose (the run goes on)."""


@dataclass(frozen=True)
class RunSettings:
    """What the user asked for; recorded in the run folder so a resume uses the same.

    n_poses / n_verify: fit poses and fresh verification poses; seed: of the candidate pool
    and every random choice; effects: the fit's effect spec (None: default model);
    speed: motion speed, fraction of max; push: write the compensated offsets;
    force: push despite a guard rail (correction beyond max_correction_deg, a fit that did
    not converge or does not explain the data); verify_alpha: the verification's false-FAIL
    rate; verify_tolerance_mm: a station's RMS tolerance (mm) or None; verify_factor: the
    verification test's noise = this x the stated noise (verify.py); criterion: planner
    criterion ("D" or "random"); n_candidates: size of the candidate pool; options: method-specific
    settings (e.g. stereo_target "depth": "triangulate" | "sgbm"); target_sigma_deg: stop
    adding fit poses once every identifiable joint offset's predicted sigma is <= this
    (deg; n_poses is then the most), None: n_poses poses. priors / hold: the fit's
    `--prior NAME=VALUE+-SIGMA` and `--hold NAME` (hostpc.fitting.priors; a joint they
    decide is never pushed as measured); require_joints: `--require-joints` ("all", "1,2,6"
    or None): a listed joint not calibrated from the data makes the verdict JOINTS_MISSING.
    swapped: `--swapped J3` joints (1-based) declared swapped: their push limit is
    swap_limit_deg instead of max_correction_deg (hostpc.calibrate.swaps).
    """

    method: str
    n_poses: int = 60
    n_verify: int = 10
    seed: int = 0
    effects: str | None = None
    plugins: tuple[str, ...] = ()
    loss: str = "linear"
    cv_folds: int = 5
    speed: float = 0.5
    push: bool = True
    force: bool = False
    max_correction_deg: float = 2.0
    verify_factor: float = 1.0
    verify_alpha: float = 0.01
    verify_tolerance_mm: float | None = None
    criterion: str = "D"
    n_candidates: int = 1500
    options: JsonObject = field(default_factory=dict)  # per kind: its own keys (run.json)
    target_sigma_deg: float | None = None
    priors: tuple[str, ...] = ()
    hold: tuple[str, ...] = ()
    require_joints: str | None = None
    swapped: tuple[int, ...] = ()
    swap_limit_deg: float = 45.0

    def to_dict(self) -> JsonObject:
        """JSON form."""
        data = dataclasses.asdict(self)
        data["plugins"] = list(self.plugins)
        data["priors"], data["hold"] = list(self.priors), list(self.hold)
        data["swapped"] = list(self.swapped)
        data["options"] = dict(self.options)
        return data

    @classmethod
    def from_dict(cls, data: JsonObject) -> RunSettings:
        """Inverse of to_dict (unknown keys ignored, so old run folders stay readable)."""
        names = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in data.items() if k in names}
        values["plugins"] = tuple(values.get("plugins", ()))
        values["priors"] = tuple(values.get("priors", ()))
        values["hold"] = tuple(values.get("hold", ()))
        values["swapped"] = tuple(int(j) for j in values.get("swapped", ()))
        values["options"] = dict(values.get("options", {}))
        return cls(**values)


@dataclass(frozen=True)
class Plan:
    """The poses of a run, fixed at the start and recorded in the run folder.

    q: (N, n) fit poses in visiting order; q_verify: (K, n) verification poses (none of
    them a fit pose); info: what the planner reports (criterion, pool size, predicted
    joint-offset sigmas, structural null directions) as JSON-ready values; q_more: (M, n)
    further fit poses measured only if the fit of q does not explain its measurements (a
    target-sigma plan: the rest of the nested selection, so diagnostics get the data to
    see the missing effect), none of them a verification pose; q_verify_grown: (K + L, n)
    the verification poses of the plan once it grew by q_more: q_verify's poses and L
    further ones (a model that failed its fit needs a verification with more power,
    docs/calibrate.md), in the grown path's visiting order and with its angles (a
    full-turn joint's angle is the 2 pi equivalent nearest the path after q_more, not
    after q: `hostpc.planning.tour.unwrap_plan`).
    """

    q: np.ndarray
    q_verify: np.ndarray
    info: JsonObject = field(default_factory=dict)
    q_more: np.ndarray | None = None
    q_verify_grown: np.ndarray | None = None

    @property
    def more(self) -> np.ndarray:
        """(M, n) the further fit poses (M = 0 without any)."""
        return (self.q_more if self.q_more is not None
                else np.zeros((0, self.q.shape[1] if self.q.ndim == 2 else 0)))

    def verify_poses(self, extended: bool) -> np.ndarray:
        """(K, n) this run's verification poses: q_verify, or q_verify_grown after the
        plan was extended by q_more."""
        if extended and self.q_verify_grown is not None and self.q_verify_grown.shape[0]:
            return self.q_verify_grown
        return self.q_verify

    def to_dict(self) -> JsonObject:
        """JSON form (radians)."""
        data = {"q": self.q.tolist(), "q_verify": self.q_verify.tolist(),
                "info": dict(self.info)}
        for key, value in (("q_more", self.q_more), ("q_verify_grown", self.q_verify_grown)):
            if value is not None and value.shape[0]:
                data[key] = value.tolist()
        return data

    @classmethod
    def from_dict(cls, data: JsonObject) -> Plan:
        """Inverse of to_dict."""
        n = len(data["q"][0]) if data["q"] else len(data["q_verify"][0])
        q = np.asarray(data["q"], dtype=float).reshape(-1, n)
        q_verify = np.asarray(data["q_verify"], dtype=float).reshape(-1, n)
        more = {key: np.asarray(data[key], dtype=float).reshape(-1, n)
                for key in ("q_more", "q_verify_grown") if data.get(key)}
        if data.get("q_verify_more"):  # an older run's plan: the further poses alone
            more["q_verify_grown"] = np.vstack([q_verify, np.asarray(
                data["q_verify_more"], dtype=float).reshape(-1, n)])
        return cls(q=q, q_verify=q_verify, info=dict(data.get("info", {})), **more)


class Sample(Protocol):
    """A measured sample of one kind as a typed value (each kind's frozen dataclass, e.g.
    ``hostpc.kinds.stereo_target.sample.StereoSample``); its JSON form, the sample in
    dataset-file form key for key as the journal has always held it (so an old run
    resumes), is what the journal holds; the kind reads it back with ``from_json``."""

    def to_json(self) -> JsonObject:
        """The sample's dataset-file form (SI)."""


def floats(values: Sequence[float] | np.ndarray) -> tuple[float, ...]:
    """A typed sample's vector field from a list or array (JSON numbers, floats)."""
    return tuple(np.asarray(values, dtype=float).reshape(-1).tolist())


def matrix(values: Sequence[Sequence[float]] | np.ndarray) -> tuple[tuple[float, ...], ...]:
    """A typed sample's matrix field from nested lists or a 2-D array (floats)."""
    return tuple(tuple(row) for row in np.asarray(values, dtype=float).tolist())


def optional_json(**fields: Any) -> JsonObject:
    """A typed sample's optional fields that are set, in order, as JSON (tuples as
    lists): what its ``to_json`` appends after the fields every sample has."""
    def plain(value: Any) -> Any:
        return [plain(v) for v in value] if isinstance(value, tuple) else value

    return {name: plain(value) for name, value in fields.items() if value is not None}


def optional_floats(data: Mapping[str, Any], name: str) -> tuple[float, ...] | None:
    """A JSON sample's optional vector field (``floats``), None where absent."""
    value = data.get(name)
    return None if value is None else floats(value)


def optional_matrix(data: Mapping[str, Any], name: str) -> tuple[tuple[float, ...], ...] | None:
    """A JSON sample's optional matrix field (``matrix``), None where absent."""
    value = data.get(name)
    return None if value is None else matrix(value)


def optional_stack(values: Sequence[Any | None], shape: tuple[int, ...]) -> np.ndarray | None:
    """(N, *shape) typed samples' optional arrays (e.g. ``uv``) as a ``Samples`` column:
    NaN where a sample has none; None where none has one."""
    if all(v is None for v in values):
        return None
    out = np.full((len(values), *shape), np.nan)
    for i, value in enumerate(values):
        if value is not None:
            out[i] = value
    return out


class PointSample(Protocol):
    """A typed sample that measures a 3-D point (stereo_target, world_point)."""

    @property
    def q(self) -> tuple[float, ...]: ...
    @property
    def p(self) -> tuple[float, ...]: ...
    @property
    def cov(self) -> tuple[tuple[float, ...], ...]: ...
    @property
    def t(self) -> float | None: ...
    @property
    def approach(self) -> tuple[float, ...] | None: ...


def point_samples(samples: Sequence[PointSample], n_joints: int, **more: Any) -> Samples:
    """Typed point samples as a dataset's ``Samples`` (q, p, cov, t, approach), with a
    kind's further columns ``more`` (``Samples`` arguments)."""
    n = len(samples)
    return Samples(
        q=np.array([s.q for s in samples], dtype=float).reshape(n, n_joints),
        p=np.array([s.p for s in samples], dtype=float).reshape(n, 3),
        cov=np.array([s.cov for s in samples], dtype=float).reshape(n, 3, 3),
        t=optional_values([s.t for s in samples]),
        approach=optional_rows([s.approach for s in samples], n_joints), **more)


def optional_values(values: Sequence[float | None]) -> np.ndarray:
    """(N,) a typed samples' optional number as a ``Samples`` column: NaN where absent."""
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def optional_rows(rows: Sequence[Sequence[float] | None], width: int) -> np.ndarray:
    """(N, width) typed samples' optional vectors (e.g. ``approach``) as a ``Samples``
    column: NaN rows where absent."""
    out = np.full((len(rows), width), np.nan)
    for i, row in enumerate(rows):
        if row is not None:
            out[i, :len(row)] = row
    return out


@dataclass(frozen=True)
class SampleRecord:
    """One pose's outcome, as journaled.

    phase / index: which plan pose; ok: measured; sample: the sample in dataset-file form
    (SI units; the `to_json` of the kind's typed sample, `Sample`; stereo_target: q, p,
    cov, t, approach, uv); reason: why it was skipped;
    q_end: (n,) where the robot is after this pose (for the next pose's approach signs).
    """

    phase: Phase
    index: int
    ok: bool
    sample: JsonObject | None = None
    reason: str | None = None
    q_end: Sequence[float] | None = None

    def to_dict(self) -> JsonObject:
        """JSON form (one journal line)."""
        return {
            "event": "sample",
            "phase": self.phase,
            "index": self.index,
            "status": "ok" if self.ok else "skipped",
            "sample": dict(self.sample) if self.sample is not None else None,
            "reason": self.reason,
            "q_end": list(self.q_end) if self.q_end is not None else None,
        }

    @classmethod
    def from_dict(cls, data: JsonObject) -> SampleRecord:
        """Inverse of to_dict; ValueError naming the field if `data` is not a record."""
        phase, index, status = data.get("phase"), data.get("index"), data.get("status")
        if phase not in ("fit", "verify"):
            raise ValueError(f"phase {phase!r} is not 'fit' or 'verify'")
        if not isinstance(index, int) or isinstance(index, bool) or index < 0:
            raise ValueError(f"index {index!r} is not a non-negative integer")
        if status not in ("ok", "skipped"):
            raise ValueError(f"status {status!r} is not 'ok' or 'skipped'")
        sample = data.get("sample")
        if status == "ok" and not isinstance(sample, Mapping):
            raise ValueError("a measured record has no sample object")
        q_end = data.get("q_end")
        if q_end is not None and not (isinstance(q_end, list) and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in q_end)):
            raise ValueError(f"q_end {str(q_end)[:40]!r} is not a list of numbers")
        return cls(
            phase=phase,
            index=index,
            ok=status == "ok",
            sample=data.get("sample"),
            reason=data.get("reason"),
            q_end=data.get("q_end"),
        )

    @classmethod
    def measured(cls, phase: Phase, index: int, sample: Sample,
                 q_end: Sequence[float] | None) -> SampleRecord:
        """The record of a measured pose: its typed sample in the journal's (JSON) form."""
        return cls(phase, index, True, sample=sample.to_json(), q_end=q_end)


class Progress(Protocol):
    """Where the runner and methods report progress (the CLI draws it on stderr)."""

    def stage(self, name: str, total: int | None = None) -> None:
        """A new stage begins (`total` steps, or None if unknown)."""

    def advance(self, done: int, note: str = "") -> None:
        """`done` steps of the current stage are finished."""

    def message(self, text: str) -> None:
        """A line worth keeping (a warning, a skipped pose, a decision)."""

    def close(self) -> None:
        """The run is over (clear the updating line)."""


class NullProgress:
    """A Progress that reports nothing (library use, tests)."""

    def stage(self, name: str, total: int | None = None) -> None:
        """Ignored."""

    def advance(self, done: int, note: str = "") -> None:
        """Ignored."""

    def message(self, text: str) -> None:
        """Ignored."""

    def close(self) -> None:
        """Ignored."""


def approach_signs(q_from: np.ndarray | None, q_to: np.ndarray) -> list[float]:
    """(n,) sign of each joint's last motion into q_to (+1 where it did not move, or no
    previous pose): the `approach` context of a sample."""
    if q_from is None:
        return [1.0] * int(np.size(q_to))
    signs = np.sign(np.asarray(q_to, float) - np.asarray(q_from, float))
    return [float(s) if s != 0 else 1.0 for s in signs]


class SampleClock(Protocol):
    """A method whose samples' `t` counts controller time (s) from the run's start."""

    def set_time_origin(self, t0: float) -> None:
        """Controller time (s) at the start of the run: sample `t` counts from here."""


class Method(ABC):
    """A measurement method (see the module docstring). One instance per run.

    settings: the run's settings; cell: the nominal cell; run_dir: the run folder, where
    the method keeps what `prepare` made (e.g. `rig.json`).
    """

    name: ClassVar[str]
    """The dataset `method` this produces (stereo_target, sphere_probe, dual_loop)."""
    default_target_sigma_deg: ClassVar[float | None] = None
    """`hostpc calibrate` without --poses stops adding fit poses at this predicted joint
    offset sigma (deg; None: a fixed pose count)."""
    plans_whole_groups: ClassVar[bool] = False
    """The plan takes whole groups of poses (`pose_groups`: sphere_probe's orientations of
    5 contacts), so it has no per-pose stop at a target sigma (--target-sigma refused)."""
    short_plan: ClassVar[ShortPlan] = ShortPlan()
    """How a target-sigma plan keeps its robot time short: how it selects its fit poses
    and whether it shortens them (`hostpc.planning.design.ShortPlan`)."""
    needs: ClassVar[tuple[Need, ...]] = ()
    """Calls beyond `RobotAdapter` the method makes (hostpc.robots.base capabilities),
    checked by the runner before `prepare`."""
    staged: ClassVar[bool] = False
    """The runner may measure the plan again in stages, its poses shifted by the current
    joint offset estimate, when a joint is found far off (hostpc.calibrate.swaps: a motor
    swap). A method opts in when it can follow the shift (`set_joint_estimate`):
    stereo_target, world_point, sphere_probe; dual_loop (a kinematic tree) does not."""

    @classmethod
    def short_plan_warning(cls, n_fit: int) -> str | None:
        """What a short plan (`--poses N` alone) of `n_fit` fit poses lacks for this method,
        one line (None: nothing)."""
        return None

    def __init__(self, settings: RunSettings, cell: Cell, run_dir: Path) -> None:
        self.settings = settings
        self.cell = cell
        self.run_dir = Path(run_dir)

    def set_joint_estimate(self, estimate: np.ndarray, new_stage: bool = False) -> None:
        """Planning hook of a staged method: from now on the robot's joints are off by
        `estimate` ((n,) rad, the runner's current joint offset estimate) when it is sent
        to commanded poses; what the method predicts from the nominal model while it
        acquires (which marker faces the tracker, the contact to make) uses it.
        new_stage: the poses measured from now on are a new fit set (what the method
        kept of the last one, e.g. sphere_probe's start frames, no longer holds). The
        default ignores it."""
        return None

    def check_inputs(self) -> None:
        """Validate method inputs that need no robot (files given on the command line);
        raise InputError. Called before connecting. The default checks nothing."""
        return None

    @abstractmethod
    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Sensor set-up before the first pose; persist results in run_dir (resumable)."""

    @abstractmethod
    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """(N_c, n) reachable candidate poses within the controller's limits."""

    @abstractmethod
    def design_dataset(self, q: np.ndarray) -> Dataset:
        """A dataset at poses q (N, n) with nominal predicted measurements and expected
        covariances, for Jacobians (planning, identifiability). Not a measurement. k
        samples per pose (the same k for every pose; dual_loop: 2, both arms), pose-major:
        the planner stacks a pose's samples into one block (`planning.design.per_pose`)."""

    @abstractmethod
    async def acquire(
        self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
        q_from: np.ndarray | None,
    ) -> SampleRecord:
        """Drive to q (n,) and measure. q_from: where the robot is (None if unknown).
        A failed detection is a skipped record; a lost link raises ConnectionFailed."""

    @abstractmethod
    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> JsonObject:
        """The samples (dataset-file form, in order) as a `zerocal-dataset/1` document."""

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled samples (dataset-file form, in order) as the run's Dataset. A kind
        with typed samples reads them with its `from_json` and builds the Dataset from
        them; the default reads `dataset_document` (a plugin's method)."""
        from hostpc.dataset import dataset_from_dict

        return dataset_from_dict(self.dataset_document(samples),
                                 plugins=self.settings.plugins)

    def refusal_hint(self) -> str | None:
        """What to try before `--force` when the run's push is refused, from this method's
        inputs (stereo_target: a cached rig, the first suspect), one clause; None: nothing."""
        return None

    def default_effects(self) -> str | None:
        """The effect spec fitted (and planned for) when the settings give none; None: the
        dataset's default model (joint offsets + the unknown frames)."""
        return None

    def separation_candidates(self, state: RobotState, rng: np.random.Generator
                              ) -> np.ndarray:
        """(N_c, n) the pool a separating experiment chooses from (``hostpc calibrate
        --separate``); the default is ``candidates``. A kind whose pool is persisted and
        small may draw more (sphere_probe)."""
        return self.candidates(state, rng)

    def pose_groups(self, pool: np.ndarray) -> PoseGroups | None:
        """Groups of the candidate poses (N_c, n) that are only measured together, or None
        (every pose stands alone). The default has none."""
        return None

    def sample_clock(self) -> SampleClock | None:
        """The method's time origin if its samples' `t` counts controller time (the runner
        sets it); None (the default): its samples are timed otherwise."""
        return None

    def describe(self) -> JsonObject:
        """JSON-ready facts about the method's set-up for the result document."""
        return {}


async def move_or_skip(robot: RobotAdapter, speed: float, phase: Phase, index: int,
                       q: np.ndarray, q_from: np.ndarray | None) -> MoveOutcome | SampleRecord:
    """Move to q (n,) rad; the MoveOutcome of a completed move, else the SampleRecord of a
    skipped pose: the controller refused the move for one of SKIP_REASONS (q_end: where the
    robot was, `q_from`) or the move stopped early (q_end: where it stopped). Any other
    refusal is raised."""
    from hostpc.transport import ControllerRefusedError  # the I/O layer, loaded on first move

    try:
        outcome = await robot.move_joints(q, speed)
    except ControllerRefusedError as exc:
        if exc.reason in SKIP_REASONS:
            return SampleRecord(phase, index, False, reason=f"move refused: {exc.reason}",
                                q_end=None if q_from is None else [float(v) for v in q_from])
        raise
    if not outcome.completed:
        return SampleRecord(phase, index, False,
                            reason=f"move stopped: {outcome.reason or 'not completed'}",
                            q_end=[float(v) for v in outcome.q])
    return outcome
