"""The state every simulated controller shares (controller_stub/world/controller_state.py): the arm
simulation and the humanoid refuse the same things the same way, and keep one offset history
that rollback ids name."""

from __future__ import annotations

import numpy as np
import pytest

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.controller_state import ControllerState, SimulatedController
from controller_stub.world.humanoid import HumanoidSimulation
from controller_stub.world.simulation import Simulation, create_simulation

ROBOTS = ["ur5e", "humanoid_upper"]


def make(robot: str) -> SimulatedController:
    return create_simulation(scenario_from_dict({"robot": robot, "seed": 5}))


def test_both_simulations_share_the_one_state() -> None:
    assert isinstance(make("ur5e"), Simulation)
    assert isinstance(make("humanoid_upper"), HumanoidSimulation)
    for robot in ROBOTS:
        sim = make(robot)  # the state is a collaborator the simulation holds (issue 26)
        assert isinstance(sim.state, ControllerState)


@pytest.mark.parametrize("robot", ROBOTS)
def test_offset_writes_are_refused_busy_while_moving(robot: str) -> None:
    sim = make(robot)
    q0 = sim.joint_positions()
    written = sim.zero_offsets() + 1e-4
    sim.set_zero_offsets(written)
    plan = sim.begin_move(sim.joint_positions() + 0.05, 1.0)
    assert sim.busy
    for write in (lambda: sim.set_zero_offsets(sim.zero_offsets()),
                  lambda: sim.rollback(0),
                  lambda: sim.undo_write(sim.last_history_id)):
        with pytest.raises(SimulationRefused) as refused:
            write()
        assert refused.value.code == "busy"
    with pytest.raises(SimulationRefused) as second:
        sim.begin_move(q0, 1.0)
    assert second.value.code == "busy"
    np.testing.assert_array_equal(sim.zero_offsets(), written)  # nothing changed
    result = sim.finish_move(plan, 0.5)  # aborted half-way: stops there
    assert not sim.busy and result.reason == "aborted"
    np.testing.assert_allclose(result.q, plan.q_at(0.5))
    np.testing.assert_allclose(sim.joint_positions(), plan.q_at(0.5))
    sim.set_zero_offsets(sim.zero_offsets())  # free again


@pytest.mark.parametrize("robot", ROBOTS)
def test_one_history_undo_restores_the_offsets_before_a_write(robot: str) -> None:
    sim = make(robot)
    original = sim.zero_offsets()
    assert sim.last_history_id == 0
    sim.set_zero_offsets(original + 1e-4)
    first = sim.last_history_id
    sim.set_zero_offsets(original + 2e-4)
    second = sim.last_history_id
    replaced = sim.undo_write(second)
    np.testing.assert_allclose(replaced, original + 2e-4)
    np.testing.assert_allclose(sim.zero_offsets(), original + 1e-4)
    sim.undo_write(first)
    np.testing.assert_allclose(sim.zero_offsets(), original)
    assert [i for i, _ in sim.offset_history()] == [0, first, second, 3, 4]
    for bad in (0, 99):
        with pytest.raises(SimulationRefused) as unknown:
            sim.undo_write(bad)
        assert unknown.value.code == "unknown_history_id"


@pytest.mark.parametrize("robot", ROBOTS)
def test_shared_argument_checks(robot: str) -> None:
    sim = make(robot)
    n = sim.n_joints
    lo, _ = sim.joint_limits()
    cases = [(lambda: sim.set_zero_offsets(np.zeros(n + 1)), "invalid_argument"),
             (lambda: sim.set_zero_offsets([np.nan] * n), "invalid_argument"),
             (lambda: sim.set_zero_offsets(np.ones(n)), "offset_limit"),
             (lambda: sim.move_joints(lo - 0.1, 1.0), "joint_limit"),
             (lambda: sim.set_digital_output(99, True), "invalid_argument")]
    for call, code in cases:
        with pytest.raises(SimulationRefused) as refused:
            call()
        assert refused.value.code == code
    sim.estop()
    with pytest.raises(SimulationRefused) as stopped:
        sim.move_joints(sim.joint_positions(), 1.0)
    assert stopped.value.code == "estop"
