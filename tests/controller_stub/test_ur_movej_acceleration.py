"""The UR personality refuses a movej whose acceleration is not a positive number (0,
negative, NaN) with a protective stop, as it refuses other impossible moves; it never
silently substitutes the scenario's acceleration."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.ur.personality import UrPersonality
from controller_stub.world.simulation import Simulation


def _move(acceleration: float | None) -> tuple[bool, str | None, UrPersonality, np.ndarray]:
    sim = Simulation(scenario_from_dict({"robot": "ur5e", "motion": {"time_scale": 0.0}}))
    robot = UrPersonality(sim, None)
    q0 = np.asarray(sim.joint_positions(), float).copy()
    completed, reason = asyncio.run(robot.move_joints(q0 + [0.3, 0, 0, 0, 0, 0], 1.0,
                                                      acceleration))
    return completed, reason, robot, np.asarray(sim.joint_positions(), float) - q0


@pytest.mark.parametrize("acceleration", [0.0, -1.0, float("nan")])
def test_a_movej_without_a_positive_acceleration_is_refused(acceleration: float) -> None:
    completed, reason, robot, moved = _move(acceleration)
    assert (completed, reason) == (False, "invalid_acceleration")
    assert robot.protective_stopped()
    np.testing.assert_array_equal(moved, 0.0)


def test_a_positive_acceleration_moves() -> None:
    completed, reason, robot, moved = _move(1.4)
    assert (completed, reason) == (True, None) and not robot.protective_stopped()
    np.testing.assert_allclose(moved, [0.3, 0, 0, 0, 0, 0], atol=1e-12)
