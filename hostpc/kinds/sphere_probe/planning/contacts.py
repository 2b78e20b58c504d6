"""sphere_probe planning (pure, nominal model): probe orientations and contact poses.

For each of >= 20 probe orientations (flange rotations), 5 approach directions over the
reachable cap of the sphere; start poses at a standoff from the surface, targets past it;
joint angles by ``solve_ik`` on the nominal model, inside the joint limits; every free-space
move checked on the nominal model not to touch the sphere. Also the plan's JSON form (kept
in the run folder), each contact's nominal contact pose and its design approach speed.
Units SI (m, rad, s); frames per docs/conventions.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.kinds.sphere_probe.planning.setup import (
    CONTACTS_PER_ORIENTATION,
    PlanConfig,
    ProbeSetup,
)
from hostpc.kinematics import Chain, forward, point_jacobian, screws
from hostpc.kinematics.inverse import solve_ik
from hostpc.planning.approach import approach_dependent_effects, balance_guarded_moves

DESIGN_JOINT_SPEED = 1.5
"""rad/s at speed fraction 1 assumed for the planner's approach speeds (a UR's base joints;
the controller's true maximum only scales the predicted latency sigma)."""


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
    """(5, 3) unit contact normals: 4 on a ring ring_deg from the pole, then the pole (facing
    the stylus, -direction; last: its approach line runs through the hover, so its retract
    leaves the orientation, `retract`). Pole + ring are not coplanar, so each group
    fixes a sphere."""
    pole = -stylus_direction / np.linalg.norm(stylus_direction)
    frame = _frame_with_z(pole, phase)
    a = math.radians(ring_deg)
    normals = []
    for j in range(4):
        b = j * math.pi / 2
        normals.append(math.cos(a) * pole + math.sin(a) * (math.cos(b) * frame[:, 0]
                                                           + math.sin(b) * frame[:, 1]))
    return np.array([*normals, pole])


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
        # the speeds cycle from the pole (probed last, `contact_normals`) round the ring
        speeds = [config.guarded_speeds[(group + (j + 1) % CONTACTS_PER_ORIENTATION)
                                        % len(config.guarded_speeds)]
                  for j in range(CONTACTS_PER_ORIENTATION)]
        contacts = tuple(
            PlannedContact(group=group, index=j, normal=normals[j], q_start=q_starts[j],
                           q_target=q_targets[j], speed=speeds[j])
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


Location = tuple[PlannedOrientation, PlannedContact | None]
"""Where the stylus is between contacts: at a contact's start pose (its retract point),
or at an orientation's hover (contact None)."""


def retract(orientation: PlannedOrientation, contact: PlannedContact
            ) -> tuple[np.ndarray, Location]:
    """Where the retract after `contact`'s guarded move goes: (n,) joint target and where
    the stylus then is. To its start; the orientation's last contact (the pole,
    `contact_normals`) on along its approach line to the hover, where the next
    orientation's moves start (one settled move instead of the retract and the move to the
    hover)."""
    if contact.index == len(orientation.contacts) - 1:
        return orientation.q_hover, (orientation, None)
    return contact.q_start, (orientation, contact)


def free_moves(orientation: PlannedOrientation, contact: PlannedContact,
               here: Location | None, chain: Chain | None = None,
               setup: ProbeSetup | None = None, config: PlanConfig | None = None
               ) -> list[np.ndarray]:
    """The free moves (joint targets (n,), each at the move speed and settled) that bring
    the stylus from `here` to the start of `contact` (its guarded approach follows).

    Hover only where needed: the hover is the orientation change (the stylus 60 mm off the
    sphere while the wrist turns). Between two contacts of one orientation the stylus
    goes from one start pose (the previous contact's retract point, `standoff` off the
    surface) straight to the next when that joint move keeps the tip at least half the
    standoff off the nominal surface (the planner's rule for hover -> start moves); else
    through the hover. Between orientations from the previous one's hover (where its last
    contact's retract ends, `retract`): straight to the start when the whole move keeps the
    half of the stylus next to the tip at least half the standoff off the nominal surface
    (the wrist turns on the way), else through this orientation's hover; from a start of
    the previous orientation: its hover, this one's, the start. `here` None (robot
    elsewhere): this orientation's hover, the start.
    Without `chain`, `setup` and `config` (no clearance check) every contact starts from
    its hover."""
    if here is None:
        return [orientation.q_hover, contact.q_start]
    at, previous = here
    checked = chain is not None and setup is not None and config is not None
    if at.group != orientation.group:
        if previous is not None:
            return [at.q_hover, orientation.q_hover, contact.q_start]
        if checked and _clear(at.q_hover, contact.q_start, chain, setup, config, stylus=True):
            return [contact.q_start]
        return [orientation.q_hover, contact.q_start]
    if previous is None:
        return [contact.q_start]
    if checked and _clear(previous.q_start, contact.q_start, chain, setup, config):
        return [contact.q_start]
    return [orientation.q_hover, contact.q_start]


STYLUS_POINTS = np.linspace(0.5, 1.0, 6)
"""Points of the stylus a wrist-turning move is checked at (`free_moves`), as fractions of
flange -> tip: its half next to the tip (the other half is 60 mm or more off the tip)."""


def _clear(q_from: np.ndarray, q_to: np.ndarray, chain: Chain | None,
           setup: ProbeSetup | None, config: PlanConfig | None, stylus: bool = False) -> bool:
    """The joint move q_from -> q_to keeps the tip (`stylus`: the half of the stylus next to
    the tip, the wrist turns) at least half the standoff off the nominal surface."""
    assert chain is not None and setup is not None and config is not None
    points = STYLUS_POINTS if stylus else np.ones(1)
    clear = min(path_clearance(chain, q_from, q_to, f * setup.tip, setup.sphere_centre)
                for f in points)
    return clear >= setup.contact_distance + 0.5 * config.standoff


def plan_to_dict(plan: ProbePlan) -> JsonObject:
    return {"rejected": plan.rejected, "orientations": [
        {"group": o.group, "rotation": o.rotation.tolist(),
         "stylus_direction": o.stylus_direction.tolist(), "q_hover": o.q_hover.tolist(),
         "contacts": [{"index": c.index, "normal": c.normal.tolist(),
                       "q_start": c.q_start.tolist(), "q_target": c.q_target.tolist(),
                       "speed": c.speed} for c in o.contacts]}
        for o in plan.orientations]}


def plan_from_dict(data: JsonObject) -> ProbePlan:
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


STEP_COARSE = 40
"""The Modbus stepping probe's equal steps over the whole travel (`SteppedGuardedMove`)."""
STEP_RESOLUTION = 2e-5
"""Its final bracket length (path units s: fraction of the travel)."""
STEP_SPEED = 0.1
"""The speed fraction of its step moves."""


def step_fractions(s_contact: float, coarse_steps: int = STEP_COARSE,
                   resolution: float = STEP_RESOLUTION) -> list[float]:
    """The path fractions s, in order, that a Modbus stepping approach
    (``hostpc.kinds.sphere_probe.probe_modbus.SteppedGuardedMove``) moves to when the probe
    line reads high from s_contact on: the coarse steps up to the first past the contact,
    then the bisection of that step down to `resolution`. The plan's model of the approach
    (``SphereProbeMethod.robot_path``); no contact within the travel: every coarse step."""
    steps: list[float] = []
    s_lo, s_hi = 0.0, None
    for k in range(1, coarse_steps + 1):
        steps.append(k / coarse_steps)
        if steps[-1] >= s_contact:
            s_hi = steps[-1]
            break
        s_lo = steps[-1]
    if s_hi is None:
        return steps
    while s_hi - s_lo > resolution:
        s_mid = 0.5 * (s_lo + s_hi)
        steps.append(s_mid)
        s_lo, s_hi = (s_lo, s_mid) if s_mid >= s_contact else (s_mid, s_hi)
    return steps


def contact_pose(contact: PlannedContact, config: PlanConfig) -> np.ndarray:
    """(n,) nominal pose of the contact on the guarded line (tip on the nominal surface):
    the pose the shared planner and the design dataset see for this contact."""
    s = contact_fraction(config)
    q: np.ndarray = contact.q_start + s * (contact.q_target - contact.q_start)
    return q


def contact_fraction(config: PlanConfig) -> float:
    """Where on its guarded line (path fraction s from the start) a contact touches the
    nominal surface."""
    return config.standoff / (config.standoff + config.overtravel)


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


def balance_probe_plan(plan: ProbePlan, chain: Chain, tip: np.ndarray,
                       effects: str | Iterable[str] | None,
                       plugins: Iterable[str | Path] = (), q_min: np.ndarray | None = None,
                       q_max: np.ndarray | None = None) -> ProbePlan:
    """The sphere_probe plan for a model: unchanged (the same object) when no effect of
    ``effects`` is approach-dependent; else with its guarded moves balanced
    (``balance_guarded_moves`` on every contact: same start poses, same number of moves).
    tip: (3,) stylus tip centre in the flange (m)."""
    if not approach_dependent_effects(effects, plugins) or not plan.contacts:
        return plan
    contacts = plan.contacts
    q_start = np.array([c.q_start for c in contacts])
    targets = balance_guarded_moves(chain, q_start, np.array([c.q_target for c in contacts]),
                                    tip, q_min=q_min, q_max=q_max)
    moved = iter(targets)
    orientations = tuple(
        replace(o, contacts=tuple(replace(c, q_target=next(moved)) for c in o.contacts))
        for o in plan.orientations)
    return replace(plan, orientations=orientations)
