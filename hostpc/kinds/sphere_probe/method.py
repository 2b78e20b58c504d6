"""sphere_probe: joint zero offsets from touch-probe contacts on a reference sphere.

A ruby stylus on the flange (tip centre ``P_t`` in the flange frame) touches a precision
sphere (centre ``P_b`` in the base frame, radius R). The probe's IO line rises at contact
and the controller latches its joint angles. Procedure (patent steps S1-S13, see
docs/sphere-probe.md):

- plan (pure): for each of >= 20 probe orientations (flange rotations), 5 approach
  directions over the reachable cap of the sphere; start poses at a standoff from the
  surface, targets past it; joint angles by ``solve_ik`` on the nominal model, inside the
  joint limits; every free-space move checked on the nominal model not to touch the sphere.
- acquire (I/O, through a ``RobotAdapter``): per contact a joint move to the start pose and a
  guarded move toward the target (S1-S3, S6). A missed contact (no IO edge before the end of
  travel, or a lost edge) stops that move at the travel limit, is recorded, and the run
  goes on.
- dataset: one sample per contact (latched q, sigma, group, speed, approach, t); the
  closed-form initial estimates (S4, S7, S8-S9; ``sphere_geometry``) become the nominal
  frames, so ``hostpc fit`` starts the joint solve from them.
- solve (S11-S13): ``hostpc.fit`` with the usual effect plugins: joint offsets, P_b and P_t
  together (plus ``trigger_latency`` or any other effect the data asks for).

Modules: ``sphere_setup`` (ProbeSetup, PlanConfig), ``sphere_planning`` (orientations,
contact poses), ``sphere_acquisition`` (probe_contact / acquire), ``sphere_dataset``
(build_dataset, solve) and ``sphere_geometry`` (the closed-form estimates); this module is
the ``Method`` for the shared runner and re-exports the public names of the others.

Units SI (m, rad, s); frames per docs/conventions.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar, Final

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples, SphereFrame
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.kinds.sphere_probe.acquisition import (
    ContactRecord,
    probe_contact,
)
from hostpc.kinds.sphere_probe.dataset import (
    build_dataset,
)
from hostpc.kinds.sphere_probe.file_face import probe_blocks, reference_sphere
from hostpc.kinds.sphere_probe.planning.contacts import (
    STEP_SPEED,
    Location,
    PlannedContact,
    PlannedOrientation,
    ProbePlan,
    balance_probe_plan,
    contact_fraction,
    contact_pose,
    design_speeds,
    free_moves,
    path_clearance,
    plan_from_dict,
    plan_sphere_probe,
    plan_to_dict,
    retract,
    step_fractions,
)
from hostpc.kinds.sphere_probe.planning.setup import (
    CONTACTS_PER_ORIENTATION,
    METHOD,
    MIN_ORIENTATIONS,
    MIN_TARGET_ORIENTATIONS,
    PlanConfig,
    ProbeSetup,
)
from hostpc.kinds.sphere_probe.sample import ProbeSample
from hostpc.kinematics import Chain
from hostpc.methods.base import Method, Phase, Progress, RunSettings, SampleRecord, floats
from hostpc.methods.cell import Cell
from hostpc.planning.approach import travel_signs
from hostpc.planning.design import PoseGroups
from hostpc.planning.robot_time import Waypoints
from hostpc.robots.base import RobotAdapter, RobotState

POOL_FACTOR = 2
"""The candidate pool holds this many times the fit's orientations (plus the verification
ones), so the planner has orientations to choose from."""
DEFAULT_EFFECTS: Final = "+trigger_latency"
"""The method's default model: joint offsets + the unknown frames + the probe's trigger
latency (a touch-trigger probe always has one; the spread of approach speeds identifies it).
The Modbus stepping probe reads at rest (no latency) and uses the dataset's default."""
PROBE_IO = ("guarded", "modbus")
"""How contacts are taken: the controller's latched guarded move, or stepping while polling
the probe line over Modbus (``hostpc.kinds.sphere_probe.probe_modbus``)."""
DEFAULT_MODBUS_PORT = 502

PLAN_FILE = "probe_plan.json"
FRAMES_FILE = "probe_frames.json"


def _setup_from_cell(cell: Cell, options: dict[str, Any]) -> ProbeSetup:
    """The probe set-up from the cell's raw description (controller + --cell file) key
    ``probe`` (or top-level keys) and the method options."""
    raw = dict(cell.raw or {})
    probe = dict(raw.get("probe") or {})
    aliases = {"sphere_centre_nominal": "sphere_centre", "tip_nominal": "tip",
               "sphere_center": "sphere_centre"}
    for old, new in aliases.items():
        if old in probe and new not in probe:
            probe[new] = probe.pop(old)
    known = tuple(k for k in cell.known if k in ("sphere", "tool"))
    known = tuple(options.get("probe_known", known))
    return ProbeSetup.from_description(probe, known=known,
                                       **{k: options.get(k) for k in (
                                           "sphere_centre", "sphere_radius", "stylus_radius",
                                           "tip", "io_line", "repeatability",
                                           "latency_jitter")})


def parse_modbus_address(text: str, default_host: str = "") -> tuple[str, int]:
    """``HOST[:PORT]`` (or ``:PORT`` with ``default_host``) -> (host, port); the port
    defaults to 502. InputError naming the value if malformed."""
    value = str(text).strip()
    host, sep, port_text = value.rpartition(":")
    if not sep:
        host, port_text = value, ""
    host = host.strip("[]") or default_host
    if not host:
        raise InputError(f"--modbus {text!r}: no host (expected HOST[:PORT])")
    if not port_text:
        return host, DEFAULT_MODBUS_PORT
    try:
        port = int(port_text)
    except ValueError:
        raise InputError(f"--modbus {text!r}: port {port_text!r} is not a number") from None
    if not 0 < port < 65536:
        raise InputError(f"--modbus {text!r}: port {port} out of range 1..65535")
    return host, port


class SphereProbeMethod(Method):
    """sphere_probe as a ``hostpc.methods.base.Method`` for the shared runner.

    Every plan pose is one contact. ``candidates`` plans a pool of whole orientations
    (``POOL_FACTOR`` x the fit's, at least 20 (S6), plus enough for verification; 5
    contacts each, S1-S3) and returns each contact's nominal contact pose; ``pose_groups``
    makes the runner select, order and verify whole orientations. The plan (hover, start
    and target of every contact) is kept in ``run_dir/probe_plan.json`` so ``acquire`` finds
    a pose's contact on resume. The probe set-up comes from the cell description's
    ``probe`` key (SI): ``{"sphere_centre": [..], "sphere_radius": R, "stylus_radius": r,
    "tip": [..], "io_line": 0, "repeatability": 1e-6}``; ``known`` may list ``sphere`` /
    ``tool``. Options: ``probe_io`` ``"guarded"`` (default: the controller's latched
    guarded move) or ``"modbus"`` (step and poll the probe line over Modbus TCP at
    ``modbus`` ``"HOST:PORT"``, one connection per contact).
    """

    name: ClassVar[str] = METHOD
    default_target_sigma_deg: ClassVar[float | None] = 0.002
    plans_whole_groups: ClassVar[bool] = True
    staged: ClassVar[bool] = True

    def __init__(self, settings: RunSettings, cell: Cell, run_dir: Path) -> None:
        super().__init__(settings, cell, run_dir)
        self.options = dict(settings.options)
        self.setup = _setup_from_cell(cell, self.options)
        self.probe_io = str(self.options.get("probe_io") or "guarded")
        if self.probe_io not in PROBE_IO:
            raise InputError(f"--probe-io {self.probe_io!r}: expected one of "
                             f"{', '.join(PROBE_IO)}")
        self.modbus: tuple[str, int] | None = None
        if self.probe_io == "modbus":
            if not self.options.get("modbus"):
                raise InputError("--probe-io modbus needs the Modbus server (--modbus "
                                 "HOST:PORT)")
            self.modbus = parse_modbus_address(str(self.options["modbus"]))
        n_fit = max(MIN_ORIENTATIONS, math.ceil(settings.n_poses / CONTACTS_PER_ORIENTATION))
        n_verify = math.ceil(settings.n_verify / CONTACTS_PER_ORIENTATION)
        self.config = PlanConfig(n_orientations=POOL_FACTOR * n_fit + n_verify,
                                 seed=settings.seed, move_speed=float(settings.speed))
        self.chain = get_robot_chain(cell.robot)
        self.plan: ProbePlan | None = None
        self._contact_poses: np.ndarray | None = None
        self._t0 = time.monotonic()
        self._joint_estimate = np.zeros(self.chain.n)  # set_joint_estimate
        self._left: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        """(commanded retract point: its start or its hover, `retract`; commanded hover; the
        shift they were commanded under) of the last contact probed (acquire)."""
        self._clear: np.ndarray | None = None
        """Where this process found the robot (`prepare`: the run's start pose, or where a
        resume finds it) when that is clear of the sphere on the nominal model (unshifted);
        the transfers between two shifts go through it (`_between_shifts`)."""

    def set_joint_estimate(self, estimate: np.ndarray, new_stage: bool = False) -> None:
        """A contact is looked up at the pose the robot reaches and its hover, start and
        guarded-move target commanded less the joints' estimate (staging); a new stage's
        samples get their own start frames (`dataset_document`)."""
        self._joint_estimate = np.asarray(estimate, float)
        if new_stage:
            self.frames_path.unlink(missing_ok=True)

    @property
    def frames_path(self) -> Path:
        """The fit dataset's nominal (initially estimated) frames, shared by verify."""
        return self.run_dir / FRAMES_FILE

    @property
    def plan_path(self) -> Path:
        """This run's probe plan (every orientation and contact)."""
        return self.run_dir / PLAN_FILE

    def check_inputs(self) -> None:
        """The set-up was validated at construction."""

    def default_effects(self) -> str | None:
        """joint offsets + the unknown frames + trigger_latency for guarded moves (latched
        while moving); the dataset's default for the Modbus stepping probe (at rest)."""
        return DEFAULT_EFFECTS if self.probe_io == "guarded" else None

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Reload this run's probe plan on resume; note where the robot is if it is clear
        of the sphere (`_clear`); with ``probe_io`` modbus, check that the probe line can
        be read (before anything moves)."""
        import json

        q = np.asarray((await robot.state()).q, float)
        if self._clearance(q, q) >= self._transfer_margin:
            self._clear = q
        if self.plan_path.is_file():
            self.plan = plan_from_dict(json.loads(self.plan_path.read_text()))
            progress.message(f"probe plan: {self.plan_path} (from this run)")
        if self.modbus is not None:
            from hostpc.kinds.sphere_probe.probe_modbus import ModbusProbe

            host, port = self.modbus
            async with ModbusProbe(host, port, self.setup.io_line) as probe:
                level = await probe.triggered()
            progress.message(f"probe line: Modbus {host}:{port} discrete input "
                             f"{self.setup.io_line} ({'high' if level else 'low'})")

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """(N_c, n) nominal contact poses of a freshly planned run (persisted)."""

        if self.plan is None:
            plan = plan_sphere_probe(self.chain, self.setup, self.config, state.q,
                                     state.q_min, state.q_max)
            # backlash in the model: each joint reaches its contacts from both sides
            self.plan = balance_probe_plan(plan, self.chain, self.setup.tip,
                                           self.settings.effects, self.settings.plugins,
                                           state.q_min, state.q_max)
            write_json_atomic(self.plan_path, plan_to_dict(self.plan))
        return self._poses()

    def separation_candidates(self, state: RobotState, rng: np.random.Generator
                              ) -> np.ndarray:
        """This run's contacts and a fresh draw of as many orientations again (the same
        planner, the next seed), appended to the probe plan once (persisted: a resume finds
        them): the run's own pool keeps few orientations it did not measure."""
        pool = self.candidates(state, rng)
        assert self.plan is not None
        if len(self.plan.orientations) > self.config.n_orientations:
            return pool  # drawn before
        last = self.plan.orientations[-1].q_hover if self.plan.orientations else state.q
        try:
            fresh = plan_sphere_probe(self.chain, self.setup,
                                      replace(self.config, seed=self.config.seed + 1),
                                      last, state.q_min, state.q_max)
        except InputError:
            return pool
        fresh = balance_probe_plan(fresh, self.chain, self.setup.tip, self.settings.effects,
                                   self.settings.plugins, state.q_min, state.q_max)
        offset = 1 + max(o.group for o in self.plan.orientations)
        more = tuple(replace(o, group=o.group + offset,
                             contacts=tuple(replace(c, group=c.group + offset)
                                            for c in o.contacts))
                     for o in fresh.orientations)
        self.plan = replace(self.plan, orientations=self.plan.orientations + more)
        write_json_atomic(self.plan_path, plan_to_dict(self.plan))
        self._contact_poses = None
        return self._poses()

    def pose_groups(self, pool: np.ndarray) -> PoseGroups:
        """The orientation of each contact of the pool: the planner takes whole
        orientations (5 contacts, S1-S3): with a target sigma (the default) the fewest
        that reach it, at least MIN_TARGET_ORIENTATIONS; else at least MIN_ORIENTATIONS
        (S6)."""
        fewest = (MIN_ORIENTATIONS if self.settings.target_sigma_deg is None
                  else MIN_TARGET_ORIENTATIONS)
        return PoseGroups(labels=np.array([self._lookup(q)[1].group for q in pool]),
                          min_groups=fewest)

    def _poses(self) -> np.ndarray:
        """(N_contacts, n) nominal contact pose of every planned contact, plan order."""
        assert self.plan is not None, "candidates() or prepare() first"
        if self._contact_poses is None:
            self._contact_poses = np.array([contact_pose(c, self.config)
                                            for c in self.plan.contacts])
        return self._contact_poses

    def _lookup(self, q: np.ndarray) -> tuple[PlannedOrientation, PlannedContact]:
        poses = self._poses()
        assert self.plan is not None
        distance = np.max(np.abs(poses - np.asarray(q, float)[None, :]), axis=1)
        k = int(np.argmin(distance)) if distance.size else -1
        if k < 0 or distance[k] > 1e-6:
            raise InputError("sphere_probe: pose is not a contact of this run's probe plan")
        contact = self.plan.contacts[k]
        orientation = next(o for o in self.plan.orientations if o.group == contact.group)
        return orientation, contact

    def _located(self, q: np.ndarray | None) -> Location | None:
        """Where the stylus is at the plan-frame pose q (n,): at a contact's start (the
        retract point) or at an orientation's hover; None if elsewhere (or q None)."""
        if q is None or self.plan is None:
            return None
        q = np.asarray(q, float)
        for orientation in self.plan.orientations:
            if np.max(np.abs(orientation.q_hover - q)) < 1e-6:
                return orientation, None
            for contact in orientation.contacts:
                if np.max(np.abs(contact.q_start - q)) < 1e-6:
                    return orientation, contact
        return None

    def _retreat(self, q_from: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The commanded hover to back out to, and the shift it is commanded under, when
        the robot is at a contact's retract point (its start or its orientation's hover)
        commanded under another shift than the current one (a new stage, a step of the
        coarse search, or a resume with --swapped): the last contact this process probed
        (`_left`), or a start or hover of the unshifted plan (a journal's last pose); None
        if neither."""
        q_from = np.asarray(q_from, float)
        if self._left is not None and np.max(np.abs(q_from - self._left[0])) < 1e-9:
            return self._left[1], self._left[2]
        unshifted = self._located(q_from)
        if unshifted is None:
            return None
        return unshifted[0].q_hover, np.zeros_like(q_from)

    def _between_shifts(self, hover: np.ndarray, then: np.ndarray,
                        orientation: PlannedOrientation) -> list[np.ndarray]:
        """The commanded moves from `hover` (commanded under the shift `then`) toward
        `orientation`'s hover under the current shift, each checked on the nominal model
        under the shift its near-sphere end is commanded under: the robot is where `then`
        puts it, the target where the current shift does. A direct move clear under the
        current shift goes straight ([]); else through the clear pose (`_clear`), the leg
        out under `then`, the leg in under the current shift ([the clear pose]). A J2 step
        of the search moves the stylus several cm at the hover: the direct move, seen
        under the new shift, starts next to the sphere although the robot is 60 mm off
        under the one it was commanded with."""
        shift = self._joint_estimate
        try:
            self._check_transfer(hover + shift, orientation)
            return []
        except InputError:
            if self._clear is None:
                raise  # nowhere clear known
        self._check_transfer(hover + then, orientation, q_to=self._clear + then,
                             target="the pose the run found the robot at")
        self._check_transfer(self._clear + shift, orientation)
        return [self._clear]

    def _free_moves(self, orientation: PlannedOrientation, contact: PlannedContact,
                    here: Location | None) -> list[np.ndarray]:
        return free_moves(orientation, contact, here, self.chain, self.setup, self.config)

    def robot_path(self, q: np.ndarray) -> Waypoints:
        """The moves that probe the contacts q (N, n) in order (``probe_contact``): per
        contact the free moves to its start (``free_moves``: the hover only where the
        orientation changes or a direct move would pass near the sphere), the guarded
        approach to the contact, the retract (`retract`: to the start, after an
        orientation's last contact on to its hover); the free moves at the plan's move
        speed, the approach at the contact's. The robot settles once per contact, at its
        start, before the guarded approach (a measurement); the free moves before it and
        the retract end at rest and measure nothing, so no settling follows them. The Modbus
        stepping probe (``probe_io`` modbus) steps instead (``step_fractions``, each step at
        ``STEP_SPEED``, all of them the measurement) and settles nowhere: its readings
        are digital reads at rest after a short slow step, which the simulator does not
        settle either (docs/sphere-probe.md)."""
        rows, speeds, settles, measuring = [], [], [], []
        here: Location | None = None
        stepping = self.modbus is not None
        for row in np.asarray(q, float):
            orientation, contact = self._lookup(row)
            via = self._free_moves(orientation, contact, here)
            q_back, there = retract(orientation, contact)
            if stepping:
                approach = [contact.q_start + s * (contact.q_target - contact.q_start)
                            for s in step_fractions(contact_fraction(self.config))]
                approach_speeds = [STEP_SPEED] * len(approach)
            else:
                approach, approach_speeds = [row], [contact.speed]
            rows += [*via, *approach, q_back]
            speeds += ([self.config.move_speed] * len(via) + approach_speeds
                       + [self.config.move_speed])
            settles += ([False] * (len(via) - 1) + [not stepping] + [False] * len(approach)
                        + [False])
            measuring += [False] * len(via) + [True] * len(approach) + [False]
            here = there
        n = np.size(q, 1) if np.ndim(q) == 2 else 0
        return Waypoints(np.asarray(rows, float).reshape(-1, n), np.asarray(speeds, float),
                         np.asarray(settles, bool), np.asarray(measuring, bool), 0)

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Contacts at q (N, n) on the nominal sphere, sigma = repeatability, with the
        nominal approach speeds along the normal (``design_speeds``; 0 for the Modbus
        stepping probe, which reads at rest) and the guarded moves' approach signs."""
        contacts = [self._lookup(row)[1] for row in q]
        groups = np.array([c.group for c in contacts], dtype=int)
        speed = (design_speeds(self.chain, contacts, np.asarray(q, float), self.setup.tip)
                 if self.probe_io == "guarded" else np.zeros(q.shape[0]))
        approach = travel_signs(np.array([c.q_start for c in contacts]),
                                np.array([c.q_target for c in contacts]))
        samples = Samples(q=q, sigma=self.setup.contact_sigma(speed), group=groups,
                          speed=speed, approach=approach)
        return Dataset(method=METHOD, robot=RobotDescription(name=self.cell.robot),
                       frames={"tool": FramePose(xyz=self.setup.tip, rpy=np.zeros(3)),
                               "sphere": SphereFrame(self.setup.sphere_centre,
                                                     self.setup.sphere_radius)},
                       samples=samples, known=self.setup.known,
                       blocks=probe_blocks(self.setup.stylus_radius))

    @property
    def _transfer_margin(self) -> float:
        """The least tip-to-centre distance (m) of a free move from elsewhere."""
        return self.setup.contact_distance + self.config.standoff

    def _clearance(self, q_from: np.ndarray, q_to: np.ndarray) -> float:
        """Smallest tip-to-centre distance (m) of the joint move q_from -> q_to (plan frame,
        nominal model)."""
        return path_clearance(self.chain, q_from, q_to, self.setup.tip,
                              self.setup.sphere_centre)

    def _check_transfer(self, q_from: np.ndarray | None, orientation: PlannedOrientation,
                        q_to: np.ndarray | None = None, target: str | None = None) -> None:
        """The free move from where the robot is to this orientation's hover (or `q_to`,
        named `target`) keeps the tip off the sphere (nominal model); the planner checked
        moves between consecutive planned orientations only, and the runner may skip
        some."""
        q_to = orientation.q_hover if q_to is None else q_to
        if q_from is None or np.max(np.abs(np.asarray(q_from, float) - q_to)) < 1e-9:
            return
        clear = self._clearance(np.asarray(q_from, float), q_to)
        if clear < self._transfer_margin:
            raise InputError(
                f"the move to {target or f'probe orientation {orientation.group}'} would "
                f"pass {(clear - self.setup.contact_distance) * 1e3:.1f} mm from the sphere "
                "(nominal model); move the robot away from the sphere first")

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        """One contact (free moves to its start, guarded move, retract: `retract`); a
        missed one is skipped. The robot ends where the retract went (`q_end`)."""
        shift = self._joint_estimate
        orientation, contact = self._lookup(np.asarray(q, float) + shift)
        q_here = None if q_from is None else np.asarray(q_from, float) + shift
        here = self._located(q_here)
        back: list[np.ndarray] = []
        retreat = None if here is not None or q_from is None else self._retreat(q_from)
        if retreat is not None:  # first back out to its hover, as commanded then
            hover, then = retreat
            back = [hover, *self._between_shifts(hover, then, orientation)]
        elif here is None:  # from elsewhere: the move to the hover must keep off the sphere
            self._check_transfer(q_here, orientation)
        elif here[0].group != orientation.group:
            self._check_transfer(here[0].q_hover, orientation)
        via = self._free_moves(orientation, contact, here)
        # commanded where the robot reaches the planned poses
        via = back + [v - shift for v in via]
        q_back = retract(orientation, contact)[0] - shift
        self._left = (q_back, orientation.q_hover - shift, shift.copy())
        if np.any(shift != 0.0):
            contact = replace(contact, q_start=contact.q_start - shift,
                              q_target=contact.q_target - shift)
        t = time.monotonic() - self._t0
        if self.modbus is None:
            record = await probe_contact(robot, via, contact, self.setup, self.config, t,
                                         chain=self.chain, q_back=q_back)
        else:
            from hostpc.kinds.sphere_probe.probe_modbus import ModbusProbe, SteppedGuardedMove

            host, port = self.modbus
            async with ModbusProbe(host, port, self.setup.io_line) as probe:
                record = await probe_contact(robot, via, contact, self.setup, self.config, t,
                                             SteppedGuardedMove(robot, probe), q_back=q_back)
        q_end = q_back.tolist()
        if not record.contact or record.q_latched is None:
            return SampleRecord(phase, index, False, q_end=q_end,
                                reason=f"no probe contact before the end of travel "
                                       f"({record.reason})")
        sample = ProbeSample(
            q=floats(record.q_latched), group=record.group,
            sigma=float(self.setup.contact_sigma(record.speed or 0.0)),
            approach=floats(record.approach), t=record.t,
            contact=record.group * CONTACTS_PER_ORIENTATION + record.index,
            speed=record.speed)
        return SampleRecord.measured(phase, index, sample, q_end=q_end)

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """The samples as a dataset document (`dataset`, written)."""
        from hostpc.dataset.writing import dataset_to_dict

        return dataset_to_dict(self.dataset(samples))

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled samples as a Dataset built from the typed samples, with the
        initial estimate as nominal frames and approach speeds along the contact normal
        (falls back to the nominal frames and tip speeds when the samples cannot support
        the estimate, e.g. a few verify ones)."""
        from hostpc.kinds.sphere_probe.planning.geometry import SphereFitError

        contacts = {(c.group, c.index): c for c in (self.plan.contacts if self.plan else [])}
        typed = [ProbeSample.from_json(s) for s in samples]
        records = []
        for sample in typed:
            key = sample.contact
            planned = contacts.get((key // CONTACTS_PER_ORIENTATION,
                                    key % CONTACTS_PER_ORIENTATION))
            direction = None
            if planned is not None:
                travel = planned.q_target - planned.q_start
                direction = travel / np.linalg.norm(travel)
            records.append(ContactRecord(
                group=sample.group, index=key % CONTACTS_PER_ORIENTATION, contact=True,
                q_latched=np.asarray(sample.q, float), speed=sample.speed,
                approach=np.asarray(sample.approach, float), t=sample.t,
                direction=direction))
        import hashlib
        import json

        digest = hashlib.sha256(
            json.dumps([list(sample.q) for sample in typed]).encode()).hexdigest()
        saved = (json.loads(self.frames_path.read_text()) if self.frames_path.is_file()
                 else None)
        if saved is not None and saved["samples"] != digest:
            # another sample set (verification): the fit's nominal frames, so that the
            # fitted deltas apply to the same nominals
            return build_dataset(self.cell.robot, self.setup, records,
                                 start_frames={k: np.asarray(saved[k], float)
                                               for k in ("tool", "sphere")})
        try:
            dataset = self._estimated_dataset(records)
        except (SphereFitError, np.linalg.LinAlgError):
            dataset = build_dataset(self.cell.robot, self.setup,
                                    [replace(r, direction=None) for r in records],
                                    estimate=False)
        write_json_atomic(self.frames_path, {
            "samples": digest, "tool": dataset.pose("tool").xyz.tolist(),
            "sphere": reference_sphere(dataset).center.tolist()})
        return dataset

    def _estimated_dataset(self, records: Sequence[ContactRecord]) -> Dataset:
        """The dataset with the closed-form frames and the contacts' normal speeds. A staged
        run's contacts are latched about the joints' estimate off (the robot is where
        latched + estimate reads): the closed form and the normals are computed there, so
        the frames are the ones the fit, started at the estimate, sets out from."""
        shift = self._joint_estimate
        if not np.any(shift != 0.0):
            return build_dataset(self.cell.robot, self.setup, records)
        dataset = build_dataset(self.cell.robot, self.setup, [
            r if r.q_latched is None else replace(r, q_latched=r.q_latched + shift)
            for r in records])
        return dataset.with_samples(replace(dataset.samples,
                                            q=np.asarray(dataset.samples.q) - shift))

    def describe(self) -> dict[str, Any]:
        """The probe set-up for the result document (SI)."""
        return {"probe": {"sphere_centre": self.setup.sphere_centre.tolist(),
                          "sphere_radius": self.setup.sphere_radius,
                          "stylus_radius": self.setup.stylus_radius,
                          "tip": self.setup.tip.tolist(), "io_line": self.setup.io_line,
                          "repeatability": self.setup.repeatability,
                          "known": list(self.setup.known),
                          "candidate_orientations": self.config.n_orientations,
                          "probe_io": self.probe_io,
                          "modbus": (None if self.modbus is None
                                     else f"{self.modbus[0]}:{self.modbus[1]}")}}


def get_robot_chain(name: str) -> Chain:
    """The nominal chain of a built-in robot."""
    from hostpc.kinematics import get_robot

    return get_robot(name)
