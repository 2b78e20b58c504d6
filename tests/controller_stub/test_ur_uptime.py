"""The UR personality's uptime (its RTDE timestamp, `controller_stub/ur/uptime.py`) on a real
simulation, cycle by cycle: every simulated second counts once (a move at time_scale 0, the
settle and the capture the simulation charges; a move paced in wall time is not counted
again when it ends), the wall time of idle cycles counts, and toward the arm's settling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.ur.paced_motion import CYCLE_S
from controller_stub.ur.uptime import ControllerUptime
from controller_stub.world.simulation import Simulation

SETTLE_S = 0.3


def _idle(uptime: ControllerUptime, cycles: int) -> None:
    for _ in range(cycles):
        uptime.tick(False)


def test_every_simulated_second_counts_once_with_the_wall_time() -> None:
    sim = Simulation(scenario_from_dict({"robot": "ur5e", "motion": {"settle_s": SETTLE_S}}))
    uptime = ControllerUptime(sim.state)
    _idle(uptime, 10)
    assert uptime.seconds == pytest.approx(10 * CYCLE_S)

    # a move that took no wall time (time_scale 0): its simulated time shows at once
    q0 = np.asarray(sim.joint_positions(), float)
    t0, before = sim.state.time, uptime.seconds
    assert sim.move_joints(q0 + [0.5, 0, 0, 0, 0, 0], 1.0).completed
    moved = sim.state.time - t0
    assert moved > 0.4
    # in the same step as the arm's new position, not at the next cycle (the old uptime
    # showed it one cycle late: a host reading the end first took the move's time as none)
    assert uptime.seconds - before == pytest.approx(moved, abs=1e-12)
    uptime.tick(False)
    assert uptime.seconds - before == pytest.approx(moved + CYCLE_S, abs=1e-12)

    # 0.1 s standing still (the host computes): it counts, and toward the settle
    _idle(uptime, 50)
    before = uptime.seconds
    assert sim.settle_for_measurement() == pytest.approx(SETTLE_S - 50 * CYCLE_S, abs=1e-9)
    sim.hold_for_capture()
    uptime.tick(False)
    assert uptime.seconds - before == pytest.approx(
        SETTLE_S - 50 * CYCLE_S + sim.scenario.motion.capture_s + CYCLE_S, abs=1e-9)

    # a move paced in wall time (one cycle per CYCLE_S of it): counted once, as it is shown
    for wall_per_sim in (1.0, 2.0):
        plan = sim.begin_move(q0, 1.0)
        before = uptime.seconds
        cycles = math.ceil(plan.duration_s * wall_per_sim / CYCLE_S)
        for _ in range(cycles):
            uptime.tick(True)
        sim.finish_move(plan)
        uptime.tick(False)
        assert uptime.seconds - before == pytest.approx((cycles + 1) * CYCLE_S, abs=1e-9)
        assert sim.move_joints(q0 + [0.5, 0, 0, 0, 0, 0], 1.0).completed  # back, unpaced
        uptime.tick(False)

    # the uptime never runs backwards
    before = uptime.seconds
    sim.state.advance_clock(-1.0)
    uptime.tick(False)
    assert uptime.seconds == pytest.approx(before + CYCLE_S)
