"""A stopj whose ramp runs past the end of the movej's plan (a deceleration too gentle to
stop before the target) ends the motion at the ramp's end: the robot starts settling only
when it is at rest, so a measurement right after waits the whole settle_s (the old
personality ended the motion at the plan's end and added the ramp after, so the settle timer
started a ramp early; and the ramp's rounding left it a hair short, "stopped")."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.ur.personality import UrPersonality
from controller_stub.world.simulation import Simulation

SETTLE_S = 0.4
VELOCITY = 0.5
"""rad/s: a 1 rad move of 2.4 s."""


async def _stopped_late(robot: UrPersonality, q: np.ndarray) -> tuple[bool, str | None]:
    clock = asyncio.create_task(robot._run_clock())  # the cycle clock, without the servers
    try:
        move = asyncio.create_task(robot.move_joints(q, VELOCITY, 1.4))
        while robot.cycle < 500:  # 1 s of controller time (a busy host slows its clock)
            await asyncio.sleep(0.002)
        # cruising at 0.5 rad/s, ~0.6 rad before the target;
        # a ramp too gentle to stop before the target: it gets there later than the plan
        assert robot.stop_motion(0.17)
        return await move
    finally:
        clock.cancel()


def test_a_stop_ramp_past_the_plan_end_settles_from_the_ramp_end() -> None:
    sim = Simulation(scenario_from_dict({"robot": "ur5e", "motion": {
        "time_scale": 1.0, "settle_s": SETTLE_S}}))
    robot = UrPersonality(sim, None)
    q0 = np.asarray(sim.joint_positions(), float).copy()
    target = q0 + [1.0, 0, 0, 0, 0, 0]
    t0 = sim.state.time
    completed, reason = asyncio.run(_stopped_late(robot, target))
    fraction = VELOCITY / float(np.min(sim.max_joint_speed()))
    plan_s = sim.state.move_profile(q0, target, fraction, 1.4).duration_s
    ramp_s = sim.state.time - t0 - plan_s
    assert ramp_s > 0.05, ramp_s  # the ramp did run past the plan's end
    assert (completed, reason) == (True, None)
    assert sim.settle_for_measurement() == pytest.approx(SETTLE_S, abs=1e-9)
