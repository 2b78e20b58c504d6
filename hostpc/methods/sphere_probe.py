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

Units SI (m, rad, s); frames per docs/conventions.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar, Final

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples, SphereFrame
from hostpc.errors import InputError
from hostpc.fitting import FitResult, fit
from hostpc.kinematics import Chain, forward, point_jacobian, screws
from hostpc.kinematics.inverse import solve_ik
from hostpc.methods.base import Method, Phase, Progress, RunSettings, SampleRecord
from hostpc.methods.cell import Cell
from hostpc.methods.planning import PoseGroups
from hostpc.methods.sphere_geometry import InitialEstimate, initial_estimate
from hostpc.robots.base import RobotAdapter, RobotState

METHOD: Final = "sphere_probe"
CONTACTS_PER_ORIENTATION = 5
MIN_ORIENTATIONS = 20
POOL_FACTOR = 2
"""The candidate pool holds this many times the fit's orientations (plus the verification
ones), so the planner has orientations to choose from."""
DEFAULT_EFFECTS: Final = "+trigger_latency"
"""The method's default model: joint offsets + the unknown frames + the probe's trigger
latency (a touch-trigger probe always has one; the spread of approach speeds identifies it).
The Modbus stepping probe reads at rest (no latency) and uses the dataset's default."""
PROBE_IO = ("guarded", "modbus")
"""How contacts are taken: the controller's latched guarded move, or stepping while polling
the probe line over Modbus (``hostpc.methods.probe_modbus``)."""
DEFAULT_MODBUS_PORT = 502
DESIGN_JOINT_SPEED = 1.5
"""rad/s at speed fraction 1 assumed for the planner's approach speeds (a UR's base joints;
the controller's true maximum only scales the predicted latency sigma)."""


# --------------------------------------------------------------------------- setup


@dataclass(frozen=True)
class ProbeSetup:
    """What the cell is: nominal frames, sizes, the probe line and its noise.

    sphere_centre: (3,) nominal sphere centre in base (m); sphere_radius: R (m);
    stylus_radius: r (m); tip: (3,) nominal stylus tip centre in the flange frame (m);
    io_line: digital input of the probe; repeatability: one-sigma contact repeatability of
    the probe (m); latency_jitter: one-sigma jitter of the trigger-to-latch delay (s), which
    becomes a distance error of jitter * approach speed; known: frames trusted and held in
    the fit (``"sphere"`` for a sphere surveyed in the base frame, ``"tool"`` for a measured
    stylus).
    """

    sphere_centre: np.ndarray
    sphere_radius: float = 0.0125
    stylus_radius: float = 0.0015
    tip: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.12]))
    io_line: int = 0
    repeatability: float = 1e-6
    latency_jitter: float = 1e-5
    known: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "sphere_centre", np.asarray(self.sphere_centre, float))
        object.__setattr__(self, "tip", np.asarray(self.tip, float))
        object.__setattr__(self, "known", tuple(self.known))
        if self.sphere_radius <= 0 or self.stylus_radius < 0:
            raise InputError("sphere radius must be > 0 and stylus radius >= 0")
        if np.linalg.norm(self.tip) < 1e-6:
            raise InputError("the stylus tip must be away from the flange origin")
        for name in self.known:
            if name not in ("sphere", "tool"):
                raise InputError(f"known frame {name!r}: sphere_probe knows 'sphere', 'tool'")

    @property
    def contact_distance(self) -> float:
        """R + r (m): tip-centre to sphere-centre distance at contact."""
        return float(self.sphere_radius + self.stylus_radius)

    def contact_sigma(self, speed: np.ndarray | float) -> np.ndarray:
        """(N,) one-sigma contact distance error (m) at approach speeds (N,) m/s."""
        speed = np.nan_to_num(np.asarray(speed, float), nan=0.0)
        return np.sqrt(self.repeatability**2 + (self.latency_jitter * speed) ** 2)

    @classmethod
    def from_description(cls, description: dict[str, Any], **overrides: Any) -> ProbeSetup:
        """From a dict with keys sphere_centre, sphere_radius, stylus_radius, tip, io_line,
        repeatability, latency_jitter, known (SI); ``overrides`` win."""
        values = {k: v for k, v in description.items() if k in cls.__dataclass_fields__}
        values.update({k: v for k, v in overrides.items() if v is not None})
        if "sphere_centre" not in values:
            raise InputError("sphere_probe needs the nominal sphere centre (sphere_centre)")
        return cls(**values)


@dataclass(frozen=True)
class PlanConfig:
    """How to probe.

    n_orientations: probe orientations (>= 20, S6); max_tilt_deg: largest tilt of the stylus
    axis from straight down; ring_deg: angle of the 4 outer contacts from the pole contact
    (the 5th); max_normal_deg: contact normals stay within this of base +z (the sphere's
    post is below it); standoff: start pose distance from the surface (m); overtravel:
    target depth past the surface (m) (must exceed the nominal frames' error); hover: tip
    distance from the sphere centre between orientations (m); guarded_speeds: guarded-move
    speed fractions, cycled over contacts (a spread of approach speeds separates the
    trigger latency); move_speed: speed fraction of free moves; seed: candidate draw.
    """

    n_orientations: int = 24
    max_tilt_deg: float = 30.0
    ring_deg: float = 40.0
    max_normal_deg: float = 75.0
    standoff: float = 0.010
    overtravel: float = 0.012
    hover: float = 0.06
    guarded_speeds: tuple[float, ...] = (0.01, 0.02, 0.04)
    move_speed: float = 0.3
    seed: int = 0


# --------------------------------------------------------------------------- planning


@dataclass(frozen=True)
class PlannedContact:
    """One approach: group (orientation), index in the group, normal (3,) unit contact
    normal (base, from the sphere centre), q_start / q_target (n,) rad, speed fraction."""

    group: int
    index: int
    normal: np.ndarray
    q_start: np.ndarray
    q_target: np.ndarray
    speed: float


@dataclass(frozen=True)
class PlannedOrientation:
    """A probe orientation: group, flange rotation R_base_flange (3, 3), stylus direction
    (3,) (flange to tip, base), q_hover (n,) and its 5 contacts."""

    group: int
    rotation: np.ndarray
    stylus_direction: np.ndarray
    q_hover: np.ndarray
    contacts: tuple[PlannedContact, ...]


@dataclass(frozen=True)
class ProbePlan:
    """The orientations in execution order, and how many candidates were dropped."""

    orientations: tuple[PlannedOrientation, ...]
    rejected: int

    @property
    def contacts(self) -> list[PlannedContact]:
        return [c for o in self.orientations for c in o.contacts]


def _frame_with_z(z: np.ndarray, roll: float) -> np.ndarray:
    """(3, 3) rotation whose third column is the unit vector z, rolled by `roll` about it."""
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    x_r = c * x + s * y
    return np.column_stack([x_r, np.cross(z, x_r), z])


def flange_rotation(stylus_direction: np.ndarray, roll: float, tip: np.ndarray) -> np.ndarray:
    """R_base_flange (3, 3) that points the stylus (flange origin -> tip (3,), flange frame)
    along stylus_direction (3,) in base, rolled by `roll` (rad) about that direction."""
    A = _frame_with_z(stylus_direction, roll)
    B = _frame_with_z(tip, 0.0)
    R: np.ndarray = A @ B.T
    return R


def contact_normals(stylus_direction: np.ndarray, ring_deg: float, phase: float) -> np.ndarray:
    """(5, 3) unit contact normals: the pole (facing the stylus, -direction) and 4 on a ring
    ring_deg from it. Pole + ring are not coplanar, so each group fixes a sphere."""
    pole = -stylus_direction / np.linalg.norm(stylus_direction)
    frame = _frame_with_z(pole, phase)
    a = math.radians(ring_deg)
    normals = [pole]
    for j in range(4):
        b = j * math.pi / 2
        normals.append(math.cos(a) * pole + math.sin(a) * (math.cos(b) * frame[:, 0]
                                                           + math.sin(b) * frame[:, 1]))
    return np.array(normals)


def tip_positions(chain: Chain, q: np.ndarray, tip: np.ndarray) -> np.ndarray:
    """(N, 3) nominal stylus tip centres in base for q (N, n) and tip (3,) in the flange."""
    T = forward(chain, np.atleast_2d(q)).T_base_flange
    tips: np.ndarray = np.einsum("nij,j->ni", T[:, :3, :3], tip) + T[:, :3, 3]
    return tips


def path_clearance(chain: Chain, q_from: np.ndarray, q_to: np.ndarray, tip: np.ndarray,
                   centre: np.ndarray, samples: int = 24) -> float:
    """Smallest tip-to-centre distance (m) along the joint-space line q_from -> q_to (n,)."""
    s = np.linspace(0.0, 1.0, samples)[:, None]
    q = q_from[None, :] + s * (q_to - q_from)[None, :]
    return float(np.min(np.linalg.norm(tip_positions(chain, q, tip) - centre, axis=1)))


def _ik(chain: Chain, R: np.ndarray, tips: np.ndarray, tip: np.ndarray, seed: np.ndarray,
        q_min: np.ndarray, q_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IK for tip positions (K, 3) with flange rotation R; (K, n) q and (K,) ok."""
    goals = np.tile(np.eye(4), (tips.shape[0], 1, 1))
    goals[:, :3, :3] = R
    goals[:, :3, 3] = tips - R @ tip
    q, ok = solve_ik(chain, goals, np.tile(seed, (tips.shape[0], 1)), iterations=100)
    ok &= np.all((q >= q_min) & (q <= q_max), axis=1)
    return q, ok


def plan_sphere_probe(chain: Chain, setup: ProbeSetup, config: PlanConfig, q_seed: np.ndarray,
                      q_min: np.ndarray | None = None, q_max: np.ndarray | None = None
                      ) -> ProbePlan:
    """Plan the probing run on the nominal model (pure; no robot).

    chain: nominal robot; q_seed: (n,) IK seed (the robot's current pose); q_min / q_max: (n,)
    controller joint limits (default: the chain's). Candidate orientations (stylus tilt and
    azimuth on a golden-angle spiral, roll spread) are kept when all 11 poses (hover, 5
    starts, 5 targets) solve within limits on one IK branch and no free move comes near the
    sphere; they are then ordered greedily by joint travel. Raises InputError if fewer than
    ``config.n_orientations`` survive.
    """
    q_min = chain.q_min if q_min is None else np.asarray(q_min, float)
    q_max = chain.q_max if q_max is None else np.asarray(q_max, float)
    rho = setup.contact_distance
    centre = setup.sphere_centre
    rng = np.random.default_rng(config.seed)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    max_tilt = math.radians(config.max_tilt_deg)
    cos_normal = math.cos(math.radians(config.max_normal_deg))
    accepted: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                         np.ndarray]] = []
    rejected = 0
    n_candidates = 6 * config.n_orientations
    seed = np.asarray(q_seed, float)
    for k in range(n_candidates):
        if len(accepted) >= config.n_orientations:
            break
        tilt = max_tilt * math.sqrt((k + 0.5) / config.n_orientations % 1.0)
        azimuth = k * golden
        roll = rng.uniform(-math.pi / 2, math.pi / 2)
        direction = np.array([math.sin(tilt) * math.cos(azimuth),
                              math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)])
        R = flange_rotation(direction, roll, setup.tip)
        normals = contact_normals(direction, config.ring_deg, rng.uniform(0, math.pi / 2))
        if np.any(normals[:, 2] < cos_normal):
            rejected += 1
            continue
        hover = centre - config.hover * direction
        q_hover, ok_hover = _ik(chain, R, hover[None, :], setup.tip, seed, q_min, q_max)
        if not ok_hover[0]:
            rejected += 1
            continue
        starts = centre + (rho + config.standoff) * normals
        targets = centre + (rho - config.overtravel) * normals
        q_pts, ok = _ik(chain, R, np.vstack([starts, targets]), setup.tip, q_hover[0],
                        q_min, q_max)
        same_branch = np.max(np.abs(q_pts - q_hover[0]), axis=1) < 0.5
        if not np.all(ok & same_branch):
            rejected += 1
            continue
        q_starts, q_targets = q_pts[:5], q_pts[5:]
        clear = min(path_clearance(chain, q_hover[0], qs, setup.tip, centre) for qs in q_starts)
        if clear < rho + 0.5 * config.standoff:
            rejected += 1
            continue
        accepted.append((direction, R, q_hover[0], normals, q_starts, q_targets))
        seed = q_hover[0]
    if len(accepted) < config.n_orientations:
        raise InputError(
            f"only {len(accepted)} of {config.n_orientations} probe orientations are reachable "
            f"around the sphere at {np.round(centre, 4).tolist()} m; move the sphere or lower "
            "max_tilt_deg / n_orientations")
    order = _greedy_order([a[2] for a in accepted], np.asarray(q_seed, float))
    orientations = []
    for group, i in enumerate(order):
        direction, R, q_hover, normals, q_starts, q_targets = accepted[i]
        contacts = tuple(
            PlannedContact(group=group, index=j, normal=normals[j], q_start=q_starts[j],
                           q_target=q_targets[j],
                           speed=config.guarded_speeds[(group + j) % len(config.guarded_speeds)])
            for j in range(CONTACTS_PER_ORIENTATION))
        orientations.append(PlannedOrientation(group, R, direction, q_hover, contacts))
    _check_transfers(chain, orientations, setup, config)
    return ProbePlan(tuple(orientations), rejected)


def _greedy_order(q_hovers: Sequence[np.ndarray], q_start: np.ndarray) -> list[int]:
    """Nearest-neighbour order of the orientations by joint travel (max |dq|)."""
    left = list(range(len(q_hovers)))
    order: list[int] = []
    current = q_start
    while left:
        best = min(left, key=lambda i: float(np.max(np.abs(q_hovers[i] - current))))
        order.append(best)
        left.remove(best)
        current = q_hovers[best]
    return order


def _check_transfers(chain: Chain, orientations: Sequence[PlannedOrientation],
                     setup: ProbeSetup, config: PlanConfig) -> None:
    """Moves between hover poses must keep the tip off the sphere (nominal model)."""
    for a, b in zip(orientations[:-1], orientations[1:], strict=True):
        clear = path_clearance(chain, a.q_hover, b.q_hover, setup.tip, setup.sphere_centre)
        if clear < setup.contact_distance + config.standoff:
            raise InputError(
                f"the move between probe orientations {a.group} and {b.group} passes "
                f"{(clear - setup.contact_distance) * 1e3:.1f} mm from the sphere; "
                "increase hover")


# --------------------------------------------------------------------------- acquisition


@dataclass(frozen=True)
class ContactRecord:
    """One guarded move's outcome.

    group, index: as planned; contact: an IO edge came before the end of travel;
    q_latched: (n,) rad at the edge (None if missed); speed: approach speed at contact
    (m/s; the controller's, else estimated on the nominal model); approach: (n,) sign of each
    joint's motion into the contact; t: host time since the start of the run (s);
    reason: why there is no contact ("no_contact", "aborted", ...); direction: (n,) unit
    joint-space direction of the guarded move (the tip's direction of travel at contact
    follows from it, see ``normal_speeds``); q_end: (n,) where the move stopped (at the
    travel limit for a missed contact).
    """

    group: int
    index: int
    contact: bool
    q_latched: np.ndarray | None
    speed: float | None
    approach: np.ndarray
    t: float
    reason: str | None = None
    direction: np.ndarray | None = None
    q_end: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON form (journal lines)."""
        return {
            "group": self.group, "index": self.index, "contact": self.contact,
            "q_latched": None if self.q_latched is None else self.q_latched.tolist(),
            "speed": self.speed, "approach": self.approach.tolist(), "t": self.t,
            "reason": self.reason,
            "direction": None if self.direction is None else self.direction.tolist(),
            "q_end": None if self.q_end is None else np.asarray(self.q_end).tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ContactRecord:
        q = d.get("q_latched")
        return cls(group=int(d["group"]), index=int(d["index"]), contact=bool(d["contact"]),
                   q_latched=None if q is None else np.asarray(q, float),
                   speed=None if d.get("speed") is None else float(d["speed"]),
                   approach=np.asarray(d["approach"], float), t=float(d["t"]),
                   reason=d.get("reason"),
                   direction=None if d.get("direction") is None
                   else np.asarray(d["direction"], float),
                   q_end=None if d.get("q_end") is None else np.asarray(d["q_end"], float))


def nominal_tip_speed(chain: Chain, contact: PlannedContact, tip: np.ndarray,
                      joint_speed: np.ndarray) -> float:
    """Tip speed (m/s) at the start of a guarded move on the nominal model, for joint
    velocities joint_speed (n,) rad/s along the planned line (used when the controller does
    not report the approach speed)."""
    poses = forward(chain, contact.q_start[None, :])
    T = poses.T_base_flange[0]
    x = (T[:3, :3] @ tip + T[:3, 3])[None, :]
    J = point_jacobian(screws(chain, poses), x)[0, :, : chain.n]
    return float(np.linalg.norm(J @ joint_speed))


ContactCallback = Callable[[ContactRecord], Awaitable[None] | None]
GuardedMove = Callable[[np.ndarray, float], Awaitable[Any]]


async def acquire(robot: RobotAdapter, plan: ProbePlan, setup: ProbeSetup, config: PlanConfig,
                  *, done: Iterable[tuple[int, int]] = (),
                  on_contact: ContactCallback | None = None,
                  guarded: GuardedMove | None = None,
                  clock: Callable[[], float] = time.monotonic) -> list[ContactRecord]:
    """Drive the plan: per contact, hover -> start -> guarded move -> start -> hover
    (``probe_contact``); every free move was checked on the nominal model at planning.

    done: (group, index) pairs already recorded (a resumed run skips them); on_contact:
    called after every guarded move (the journal); guarded: replaces the robot's guarded
    move, ``await guarded(q_target, speed) -> ContactOutcome`` (the Modbus path). A missed
    contact is recorded with contact=False and the run goes on. Returns the new records.
    """
    skip = set(done)
    records: list[ContactRecord] = []
    t0 = clock()
    for orientation in plan.orientations:
        for contact in orientation.contacts:
            if (contact.group, contact.index) in skip:
                continue
            record = await probe_contact(robot, orientation, contact, setup, config,
                                         clock() - t0, guarded)
            records.append(record)
            if on_contact is not None:
                result = on_contact(record)
                if result is not None:
                    await result
    return records


async def _move(robot: RobotAdapter, q: np.ndarray, speed: float) -> None:
    outcome = await robot.move_joints(q, speed)
    if not outcome.completed:
        from hostpc.errors import ControllerError

        raise ControllerError(f"move to {np.round(q, 4).tolist()} did not complete: "
                              f"{outcome.reason}")


# --------------------------------------------------------------------------- dataset


def build_dataset(robot_name: str, setup: ProbeSetup, records: Sequence[ContactRecord],
                  *, estimate: bool = True, extra: dict[str, Any] | None = None,
                  start_frames: Mapping[str, np.ndarray] | None = None) -> Dataset:
    """The sphere_probe dataset of the contacts that touched (missed ones are listed in
    ``extra_fields["sphere_probe"]["missed"]``).

    estimate: replace the unknown nominal frames by the closed-form initial estimate (S4,
    S7, S8-S9), so the joint solve starts from it; the CAD nominals are kept in
    ``extra_fields["sphere_probe"]["nominal_frames"]``. Each sample's ``speed`` is the
    approach speed along the contact normal (``normal_speeds``), the controller's tip speed
    is kept as ``extra.tip_speed``, and ``sigma`` follows from both (``contact_sigma``).
    start_frames: ``{"tool": P_t, "sphere": P_b}`` to use as the nominal frames instead of
    an estimate from these records (a verification set must share the fit's nominals);
    the contact normals then come from these frames without a preliminary fit.
    """
    touched = [r for r in records if r.contact and r.q_latched is not None]
    missed = [{"group": r.group, "index": r.index, "reason": r.reason}
              for r in records if not r.contact]
    if not touched:
        raise InputError("no contact was recorded: nothing to calibrate")
    q = np.array([r.q_latched for r in touched])
    tip_speed = np.array([np.nan if r.speed is None else r.speed for r in touched])
    samples = Samples(
        q=q, sigma=setup.contact_sigma(tip_speed), group=np.array([r.group for r in touched]),
        speed=tip_speed, approach=np.array([r.approach for r in touched]),
        t=np.array([r.t for r in touched]), extra={"tip_speed": tip_speed})
    tip = setup.tip if start_frames is None else np.asarray(start_frames["tool"], float)
    centre = (setup.sphere_centre if start_frames is None
              else np.asarray(start_frames["sphere"], float))
    frames: dict[str, Any] = {
        "tool": FramePose(xyz=tip, rpy=np.zeros(3)),
        "sphere": SphereFrame(centre, setup.sphere_radius),
    }
    info: dict[str, Any] = {
        "missed": missed,
        "nominal_frames": {"tip": setup.tip.tolist(),
                           "sphere_centre": setup.sphere_centre.tolist()},
        "repeatability": setup.repeatability, "latency_jitter": setup.latency_jitter,
        "io_line": setup.io_line,
    }
    dataset = Dataset(method=METHOD, robot=RobotDescription(name=robot_name), frames=frames,
                      samples=samples, known=setup.known,
                      probe_stylus_radius=setup.stylus_radius,
                      extra_fields={"sphere_probe": info, **(extra or {})})
    if estimate and start_frames is None:
        dataset, guess = with_initial_estimate(dataset)
        info["initial_estimate"] = {
            "tip": guess.tip.tolist(), "sphere_centre": guess.sphere_centre.tolist(),
            "patent_tip": guess.patent_tip.tolist(),
            "patent_sphere_centre": guess.patent_sphere_centre.tolist(), "rms": guess.rms,
        }
    directions = [r.direction for r in touched]
    if all(d is not None for d in directions) and np.all(np.isfinite(tip_speed)):
        speed = normal_speeds(dataset, np.array(directions), tip_speed,
                              preliminary_fit=start_frames is None)
        samples = replace(dataset.samples, speed=speed, sigma=setup.contact_sigma(speed))
        dataset = dataset.with_samples(samples)
    return replace(dataset, extra_fields={**dataset.extra_fields, "sphere_probe": info})


def normal_speeds(dataset: Dataset, directions: np.ndarray, tip_speed: np.ndarray, *,
                  preliminary_fit: bool = True) -> np.ndarray:
    """(N,) approach speed along the contact normal (m/s, > 0 toward the centre).

    A late latch moves the tip ``latency * v`` along its direction of travel, which changes
    the tip-to-centre distance by ``latency * v . (-u)`` (u: unit normal from the sphere
    centre to the tip): that normal component, not the tip speed, is what the
    ``trigger_latency`` effect multiplies. directions: (N, n) unit joint-space directions
    of the guarded moves; tip_speed: (N,) the controller's tip speed (m/s). The geometry
    comes from a preliminary fit (joint offsets and frames, no cross-validation) of the
    dataset, so the contact normals are accurate to the fit's residuals (preliminary_fit
    False: the dataset's nominal frames and the joints as latched).
    """
    chain = robot_chain_of(dataset)
    q = np.asarray(dataset.samples.q, float).copy()
    if preliminary_fit:
        preliminary = fit(dataset, cv_folds=0)
        frames = frames_from_result(preliminary)
        if "joint_offsets" in preliminary.problem.layout.effect_slices:
            q = q + preliminary.effect_values("joint_offsets")[None, :]
    else:
        frames = {"tool": np.asarray(dataset.pose("tool").xyz, float),
                  "sphere": np.asarray(dataset.sphere().center, float)}
    poses = forward(chain, q)
    T = poses.T_base_flange
    tip = np.einsum("nij,j->ni", T[:, :3, :3], frames["tool"]) + T[:, :3, 3]
    J = point_jacobian(screws(chain, poses), tip)[:, :, : chain.n]
    velocity = np.einsum("nij,nj->ni", J, directions)
    velocity /= np.maximum(np.linalg.norm(velocity, axis=1, keepdims=True), 1e-300)
    normal = tip - frames["sphere"][None, :]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    cosine = -np.sum(velocity * normal, axis=1)
    speed: np.ndarray = np.asarray(tip_speed, float) * cosine
    return speed


def robot_chain_of(dataset: Dataset) -> Chain:
    """The nominal chain of a dataset's robot."""
    from hostpc.model.problem import robot_chain

    return robot_chain(dataset)


def with_initial_estimate(dataset: Dataset) -> tuple[Dataset, InitialEstimate]:
    """The dataset with its unknown frames (tool, sphere) replaced by the closed-form
    initial estimate from its contacts (joints as latched, nominal model)."""
    if dataset.method != METHOD:
        raise InputError(f"expected a {METHOD} dataset, got {dataset.method!r}")
    chain = robot_chain_of(dataset)
    T = forward(chain, np.asarray(dataset.samples.q, float)).T_base_flange
    sphere = dataset.sphere()
    tool = dataset.pose("tool")
    rho = float(sphere.radius) + float(dataset.probe_stylus_radius or 0.0)
    guess = initial_estimate(
        T, np.asarray(dataset.samples.group), rho,
        known_sphere_centre=np.asarray(sphere.center) if "sphere" in dataset.known else None,
        known_tip=np.asarray(tool.xyz) if "tool" in dataset.known else None)
    frames = dict(dataset.frames)
    if "tool" not in dataset.known:
        frames["tool"] = FramePose(xyz=guess.tip, rpy=np.asarray(tool.rpy))
    if "sphere" not in dataset.known:
        frames["sphere"] = SphereFrame(guess.sphere_centre, sphere.radius)
    return replace(dataset, frames=frames), guess


def solve(dataset: Dataset, effects: str | Iterable[str] | None = None, *,
          estimate: bool = True, **options: Any) -> FitResult:
    """The joint solve (S11-S13): start from the initial estimate (if ``estimate``), then
    ``hostpc.fit`` with the given effects (default joint_offsets + unknown frames)."""
    if estimate:
        dataset, _ = with_initial_estimate(dataset)
    return fit(dataset, effects, **options)


def frames_from_result(result: FitResult) -> dict[str, np.ndarray]:
    """Fitted P_b (``sphere``, base, m) and P_t (``tool``, flange, m)."""
    dataset = result.problem.dataset
    out = {"sphere": np.asarray(dataset.sphere().center, float).copy(),
           "tool": np.asarray(dataset.pose("tool").xyz, float).copy()}
    for name in ("sphere", "tool"):
        if name in result.problem.layout.effect_slices:
            out[name] = out[name] + result.effect_values(name)
    return out



# --------------------------------------------------------------------------- the method


PLAN_FILE = "probe_plan.json"
FRAMES_FILE = "probe_frames.json"


async def probe_contact(robot: RobotAdapter, orientation: PlannedOrientation,
                        contact: PlannedContact, setup: ProbeSetup, config: PlanConfig,
                        t: float, guarded: GuardedMove | None = None) -> ContactRecord:
    """One contact: hover -> start -> guarded move -> start -> hover (see ``acquire``)."""
    await _move(robot, orientation.q_hover, config.move_speed)
    await _move(robot, contact.q_start, config.move_speed)
    if guarded is None:
        outcome = await robot.guarded_move(contact.q_target, contact.speed, setup.io_line)
    else:
        outcome = await guarded(contact.q_target, contact.speed)
    travel = contact.q_target - contact.q_start
    approach = np.sign(travel)
    approach[approach == 0] = 1.0
    latched = outcome.q_latched if outcome.contact else None
    await _move(robot, contact.q_start, config.move_speed)
    await _move(robot, orientation.q_hover, config.move_speed)
    return ContactRecord(
        group=contact.group, index=contact.index,
        contact=bool(outcome.contact and latched is not None),
        q_latched=None if latched is None else np.asarray(latched, float),
        speed=None if outcome.speed is None else float(outcome.speed),
        approach=approach, t=t,
        reason=None if outcome.contact else (outcome.reason or "no_contact"),
        direction=travel / max(float(np.linalg.norm(travel)), 1e-300),
        q_end=np.asarray(outcome.q, float))


def _plan_to_dict(plan: ProbePlan) -> dict[str, Any]:
    return {"rejected": plan.rejected, "orientations": [
        {"group": o.group, "rotation": o.rotation.tolist(),
         "stylus_direction": o.stylus_direction.tolist(), "q_hover": o.q_hover.tolist(),
         "contacts": [{"index": c.index, "normal": c.normal.tolist(),
                       "q_start": c.q_start.tolist(), "q_target": c.q_target.tolist(),
                       "speed": c.speed} for c in o.contacts]}
        for o in plan.orientations]}


def _plan_from_dict(data: dict[str, Any]) -> ProbePlan:
    orientations = []
    for o in data["orientations"]:
        contacts = tuple(PlannedContact(int(o["group"]), int(c["index"]),
                                        np.asarray(c["normal"], float),
                                        np.asarray(c["q_start"], float),
                                        np.asarray(c["q_target"], float), float(c["speed"]))
                         for c in o["contacts"])
        orientations.append(PlannedOrientation(
            int(o["group"]), np.asarray(o["rotation"], float),
            np.asarray(o["stylus_direction"], float), np.asarray(o["q_hover"], float),
            contacts))
    return ProbePlan(tuple(orientations), int(data.get("rejected", 0)))


def contact_pose(contact: PlannedContact, config: PlanConfig) -> np.ndarray:
    """(n,) nominal pose of the contact on the guarded line (tip on the nominal surface):
    the pose the shared planner and the design dataset see for this contact."""
    s = config.standoff / (config.standoff + config.overtravel)
    q: np.ndarray = contact.q_start + s * (contact.q_target - contact.q_start)
    return q


def _setup_from_cell(cell: Any, options: dict[str, Any]) -> ProbeSetup:
    """The probe set-up from the cell's raw description (controller + --cell file) key
    ``probe`` (or top-level keys) and the method options."""
    raw = dict(getattr(cell, "raw", {}) or {})
    probe = dict(raw.get("probe") or {})
    aliases = {"sphere_centre_nominal": "sphere_centre", "tip_nominal": "tip",
               "sphere_center": "sphere_centre"}
    for old, new in aliases.items():
        if old in probe and new not in probe:
            probe[new] = probe.pop(old)
    known = tuple(k for k in getattr(cell, "known", ()) if k in ("sphere", "tool"))
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


def design_speeds(chain: Chain, contacts: Sequence[PlannedContact], q: np.ndarray,
                  tip: np.ndarray, joint_speed: float = DESIGN_JOINT_SPEED) -> np.ndarray:
    """(N,) nominal approach speed along the contact normal (m/s, > 0 toward the centre) of
    each planned contact at its nominal contact pose q (N, n): the guarded move's joint
    velocity (speed fraction x ``joint_speed`` on the fastest-moving joint, as a controller
    scales a joint move) through the nominal tip Jacobian. For the planner only."""
    if not contacts:
        return np.zeros(0)
    travel = np.array([c.q_target - c.q_start for c in contacts])
    scale = np.array([c.speed for c in contacts]) * joint_speed
    velocity = travel * (scale / np.maximum(np.max(np.abs(travel), axis=1), 1e-300))[:, None]
    poses = forward(chain, q)
    T = poses.T_base_flange
    x = np.einsum("nij,j->ni", T[:, :3, :3], tip) + T[:, :3, 3]
    J = point_jacobian(screws(chain, poses), x)[:, :, : chain.n]
    tip_velocity = np.einsum("nij,nj->ni", J, velocity)
    normals = np.array([c.normal for c in contacts])
    speed: np.ndarray = -np.sum(tip_velocity * normals, axis=1)
    return speed


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
        """Reload this run's probe plan on resume; with ``probe_io`` modbus, check that the
        probe line can be read (before anything moves)."""
        import json

        if self.plan_path.is_file():
            self.plan = _plan_from_dict(json.loads(self.plan_path.read_text()))
            progress.message(f"probe plan: {self.plan_path} (from this run)")
        if self.modbus is not None:
            from hostpc.methods.probe_modbus import ModbusProbe

            host, port = self.modbus
            async with ModbusProbe(host, port, self.setup.io_line) as probe:
                level = await probe.triggered()
            progress.message(f"probe line: Modbus {host}:{port} discrete input "
                             f"{self.setup.io_line} ({'high' if level else 'low'})")

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """(N_c, n) nominal contact poses of a freshly planned run (persisted)."""
        from hostpc.methods.journal import write_json_atomic

        if self.plan is None:
            self.plan = plan_sphere_probe(self.chain, self.setup, self.config, state.q,
                                          state.q_min, state.q_max)
            write_json_atomic(self.plan_path, _plan_to_dict(self.plan))
        return self._poses()

    def pose_groups(self, pool: np.ndarray) -> PoseGroups:
        """The orientation of each contact of the pool: the planner takes whole
        orientations (5 contacts, S1-S3), at least MIN_ORIENTATIONS of them (S6)."""
        return PoseGroups(labels=np.array([self._lookup(q)[1].group for q in pool]),
                          min_groups=MIN_ORIENTATIONS)

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

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Contacts at q (N, n) on the nominal sphere, sigma = repeatability, with the
        nominal approach speeds along the normal (``design_speeds``; 0 for the Modbus
        stepping probe, which reads at rest)."""
        contacts = [self._lookup(row)[1] for row in q]
        groups = np.array([c.group for c in contacts], dtype=int)
        speed = (design_speeds(self.chain, contacts, np.asarray(q, float), self.setup.tip)
                 if self.probe_io == "guarded" else np.zeros(q.shape[0]))
        samples = Samples(q=q, sigma=self.setup.contact_sigma(speed), group=groups,
                          speed=speed)
        return Dataset(method=METHOD, robot=RobotDescription(name=self.cell.robot),
                       frames={"tool": FramePose(xyz=self.setup.tip, rpy=np.zeros(3)),
                               "sphere": SphereFrame(self.setup.sphere_centre,
                                                     self.setup.sphere_radius)},
                       samples=samples, known=self.setup.known,
                       probe_stylus_radius=self.setup.stylus_radius)

    def _check_transfer(self, q_from: np.ndarray | None,
                        orientation: PlannedOrientation) -> None:
        """The free move from where the robot is to this orientation's hover keeps the tip
        off the sphere (nominal model); the planner checked moves between consecutive
        planned orientations only, and the runner may skip some."""
        if q_from is None:
            return
        q_from = np.asarray(q_from, float)
        if np.max(np.abs(q_from - orientation.q_hover)) < 1e-9:
            return
        clear = path_clearance(self.chain, q_from, orientation.q_hover, self.setup.tip,
                               self.setup.sphere_centre)
        if clear < self.setup.contact_distance + self.config.standoff:
            raise InputError(
                f"the move to probe orientation {orientation.group} would pass "
                f"{(clear - self.setup.contact_distance) * 1e3:.1f} mm from the sphere "
                "(nominal model); move the robot away from the sphere first")

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        """One contact (hover, start, guarded move, back); a missed one is skipped."""
        orientation, contact = self._lookup(np.asarray(q, float))
        self._check_transfer(q_from, orientation)
        t = time.monotonic() - self._t0
        if self.modbus is None:
            record = await probe_contact(robot, orientation, contact, self.setup,
                                         self.config, t)
        else:
            from hostpc.methods.probe_modbus import ModbusProbe, SteppedGuardedMove

            host, port = self.modbus
            async with ModbusProbe(host, port, self.setup.io_line) as probe:
                record = await probe_contact(robot, orientation, contact, self.setup,
                                             self.config, t, SteppedGuardedMove(robot, probe))
        q_end = orientation.q_hover.tolist()
        if not record.contact or record.q_latched is None:
            return SampleRecord(phase, index, False, q_end=q_end,
                                reason=f"no probe contact before the end of travel "
                                       f"({record.reason})")
        sample: dict[str, Any] = {
            "q": record.q_latched.tolist(), "group": record.group,
            "sigma": float(self.setup.contact_sigma(record.speed or 0.0)),
            "approach": record.approach.tolist(), "t": record.t,
            "extra": {"contact": float(record.group * CONTACTS_PER_ORIENTATION
                                       + record.index)},
        }
        if record.speed is not None:
            sample["speed"] = record.speed
            sample["extra"]["tip_speed"] = record.speed
        return SampleRecord(phase, index, True, sample=sample, q_end=q_end)

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """The samples as a dataset document, with the initial estimate as nominal frames
        and approach speeds along the contact normal (falls back to the nominal frames and
        tip speeds when the samples cannot support the estimate, e.g. a few verify ones)."""
        from hostpc.dataset.io import dataset_to_dict
        from hostpc.methods.sphere_geometry import SphereFitError

        contacts = {(c.group, c.index): c for c in (self.plan.contacts if self.plan else [])}
        records = []
        for s in samples:
            key = int(round(float(s.get("extra", {}).get("contact", -1))))
            planned = contacts.get((key // CONTACTS_PER_ORIENTATION,
                                    key % CONTACTS_PER_ORIENTATION))
            direction = None
            if planned is not None:
                travel = planned.q_target - planned.q_start
                direction = travel / np.linalg.norm(travel)
            records.append(ContactRecord(
                group=int(s["group"]), index=key % CONTACTS_PER_ORIENTATION, contact=True,
                q_latched=np.asarray(s["q"], float),
                speed=None if s.get("speed") is None else float(s["speed"]),
                approach=np.asarray(s["approach"], float), t=float(s.get("t", 0.0)),
                direction=direction))
        import hashlib
        import json

        from hostpc.methods.journal import write_json_atomic

        digest = hashlib.sha256(
            json.dumps([list(s["q"]) for s in samples]).encode()).hexdigest()
        saved = (json.loads(self.frames_path.read_text()) if self.frames_path.is_file()
                 else None)
        if saved is not None and saved["samples"] != digest:
            # another sample set (verification): the fit's nominal frames, so that the
            # fitted deltas apply to the same nominals
            dataset = build_dataset(self.cell.robot, self.setup, records,
                                    start_frames={k: np.asarray(saved[k], float)
                                                  for k in ("tool", "sphere")})
            return dataset_to_dict(dataset)
        try:
            dataset = build_dataset(self.cell.robot, self.setup, records)
        except (SphereFitError, np.linalg.LinAlgError):
            dataset = build_dataset(self.cell.robot, self.setup,
                                    [replace(r, direction=None) for r in records],
                                    estimate=False)
        write_json_atomic(self.frames_path, {
            "samples": digest, "tool": dataset.pose("tool").xyz.tolist(),
            "sphere": dataset.sphere().center.tolist()})
        return dataset_to_dict(dataset)

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
