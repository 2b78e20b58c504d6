"""sphere_probe acquisition (I/O, through a ``RobotAdapter``): driving the planned contacts.

Per contact the free moves to its start pose (`planning.contacts.free_moves`: the hover
only where the orientation changes or a direct move would pass near the sphere), a guarded
move toward the target (S1-S3, S6) and the retract (`retract`: to the start, after an
orientation's last contact on to its hover). A missed contact (no IO
edge before the end of travel, or a lost edge) stops that move at the travel limit, is
recorded, and the run goes on. Units SI (m, rad, s).
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from hostpc.kinds.sphere_probe.planning.contacts import (
    Location,
    PlannedContact,
    ProbePlan,
    free_moves,
    retract,
)
from hostpc.kinds.sphere_probe.planning.setup import PlanConfig, ProbeSetup
from hostpc.kinematics import Chain, forward, point_jacobian, screws
from hostpc.robots.base import ContactOutcome, RobotAdapter


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


def tip_speed_at(chain: Chain, q: np.ndarray, tip: np.ndarray, qd: np.ndarray) -> float:
    """Tip speed (m/s) on the nominal model at joint angles q (n,) rad moving at joint
    velocities qd (n,) rad/s (a controller that measures qd but does not know the tip)."""
    poses = forward(chain, np.asarray(q, float)[None, :])
    T = poses.T_base_flange[0]
    x = (T[:3, :3] @ tip + T[:3, 3])[None, :]
    J = point_jacobian(screws(chain, poses), x)[0, :, : chain.n]
    return float(np.linalg.norm(J @ np.asarray(qd, float)))


ContactCallback = Callable[[ContactRecord], Awaitable[None] | None]
GuardedMove = Callable[[np.ndarray, float], Awaitable[ContactOutcome]]


async def acquire(robot: RobotAdapter, plan: ProbePlan, setup: ProbeSetup, config: PlanConfig,
                  *, done: Iterable[tuple[int, int]] = (),
                  on_contact: ContactCallback | None = None,
                  guarded: GuardedMove | None = None,
                  clock: Callable[[], float] = time.monotonic,
                  chain: Chain | None = None) -> list[ContactRecord]:
    """Drive the plan: per contact its free moves to the start (`free_moves`: with
    `chain`, straight from the previous contact's start where that keeps clear of the
    sphere, else through the hover), the guarded move, the retract (``probe_contact``,
    `retract`); every free move was checked on the nominal model at planning.

    done: (group, index) pairs already recorded (a resumed run skips them); on_contact:
    called after every guarded move (the journal); guarded: replaces the robot's guarded
    move, ``await guarded(q_target, speed) -> ContactOutcome`` (the Modbus path). A missed
    contact is recorded with contact=False and the run goes on. Returns the new records.
    """
    skip = set(done)
    records: list[ContactRecord] = []
    t0 = clock()
    here: Location | None = None
    for orientation in plan.orientations:
        for contact in orientation.contacts:
            if (contact.group, contact.index) in skip:
                continue
            via = free_moves(orientation, contact, here, chain, setup, config)
            q_back, there = retract(orientation, contact)
            record = await probe_contact(robot, via, contact, setup, config,
                                         clock() - t0, guarded, chain, q_back)
            here = there
            records.append(record)
            if on_contact is not None:
                result = on_contact(record)
                if result is not None:
                    await result
        if here is not None and here[0] is orientation and here[1] is not None:
            # leave it as planned: its hover
            await _move(robot, orientation.q_hover, config.move_speed)
            here = (orientation, None)
    return records


async def _move(robot: RobotAdapter, q: np.ndarray, speed: float) -> None:
    outcome = await robot.move_joints(q, speed)
    if not outcome.completed:
        from hostpc.errors import ControllerError

        raise ControllerError(f"move to {np.round(q, 4).tolist()} did not complete: "
                              f"{outcome.reason}")


async def probe_contact(robot: RobotAdapter, via: Sequence[np.ndarray],
                        contact: PlannedContact, setup: ProbeSetup, config: PlanConfig,
                        t: float, guarded: GuardedMove | None = None,
                        chain: Chain | None = None, q_back: np.ndarray | None = None
                        ) -> ContactRecord:
    """One contact: the free moves `via` (ending at the contact's start, `free_moves`), the
    guarded move, the retract to `q_back` (`retract`; None: the start), where the robot
    ends (see ``acquire``).

    chain: the nominal model, to turn the joint velocities a controller measured at the
    edge (``ContactOutcome.qd``) into the tip speed when it does not report that itself."""
    for q in via:
        await _move(robot, q, config.move_speed)
    if guarded is None:
        outcome = await robot.guarded_move(contact.q_target, contact.speed, setup.io_line)
    else:
        outcome = await guarded(contact.q_target, contact.speed)
    travel = contact.q_target - contact.q_start
    approach = np.sign(travel)
    approach[approach == 0] = 1.0
    latched = outcome.q_latched if outcome.contact else None
    speed = None if outcome.speed is None else float(outcome.speed)
    if speed is None and latched is not None and outcome.qd is not None and chain is not None:
        speed = tip_speed_at(chain, np.asarray(latched, float), setup.tip, outcome.qd)
    await _move(robot, contact.q_start if q_back is None else q_back, config.move_speed)
    return ContactRecord(
        group=contact.group, index=contact.index,
        contact=bool(outcome.contact and latched is not None),
        q_latched=None if latched is None else np.asarray(latched, float),
        speed=speed, approach=approach, t=t,
        reason=None if outcome.contact else (outcome.reason or "no_contact"),
        direction=travel / max(float(np.linalg.norm(travel)), 1e-300),
        q_end=np.asarray(outcome.q, float))
