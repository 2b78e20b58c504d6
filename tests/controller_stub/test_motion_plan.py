"""Deferred motions: begin_move plans, finish_move executes to the end or stops part-way."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from controller_stub.errors import SimulationRefused
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.motion import GuardedMoveResult, MoveResult
from controller_stub.world.simulation import Simulation

STEP = np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])


def probe_world(seed: int = 5) -> dict[str, Any]:
    """A scenario whose reference sphere sits half-way along home -> home + STEP."""
    finder = Simulation(scenario_from_dict({"seed": seed, "probe": {"repeatability_sigma": 0.0}}))
    finder.move_joints(finder.joint_positions() + STEP / 2, 1.0)
    return {
        "seed": seed,
        "probe": {
            "repeatability_sigma": 0.0,
            "sphere_centre": finder.tip_position().tolist(),
            "sphere_centre_error": [0.0, 0.0, 0.0],
        },
    }


def recording_sim(overrides: dict[str, Any]) -> tuple[Simulation, list[tuple[Any, ...]]]:
    sim = Simulation(scenario_from_dict(overrides))
    edges: list[tuple[Any, ...]] = []
    sim.on_io_edge = lambda line, value, t, q: edges.append((line, value, t, q))
    return sim, edges


def test_finish_to_the_end_equals_the_immediate_move() -> None:
    world = probe_world()
    immediate, immediate_edges = recording_sim(world)
    deferred, deferred_edges = recording_sim(world)
    target = immediate.joint_positions() + STEP
    expected = immediate.move_joints(target, 0.5)
    plan = deferred.begin_move(target, 0.5)
    np.testing.assert_array_equal(deferred.joint_positions(), plan.q_start)  # not moved yet
    assert deferred.time == 0.0 and deferred_edges == []
    result = deferred.finish_move(plan)
    assert isinstance(result, MoveResult) and result.completed and result.reason is None
    np.testing.assert_array_equal(result.q, expected.q)
    assert result.duration_s == expected.duration_s == plan.duration_s
    assert deferred.time == immediate.time
    assert [e[:3] for e in deferred_edges] == [e[:3] for e in immediate_edges]
    assert [e[1] for e in immediate_edges] == [True, False]  # entered and left the sphere


def test_stopped_move_ends_part_way_with_only_the_edges_before_the_stop() -> None:
    sim, edges = recording_sim(probe_world())
    q_start = sim.joint_positions()
    plan = sim.begin_move(q_start + STEP, 0.5)
    first_edge = plan.edges[0]
    assert 0.1 < first_edge.s < 0.9
    # stopped half-way (in time) to the first edge: still ramping up at the default 4 rad/s^2
    t_stop = first_edge.time / 2
    acceleration = float(sim.max_joint_acceleration()[0])
    assert acceleration == 4.0 and t_stop < plan.profile.ramp_s
    result = sim.finish_move(plan, t_stop / plan.duration_s)
    assert isinstance(result, MoveResult)
    assert not result.completed and result.reason == "aborted"
    np.testing.assert_allclose(result.q - q_start, [0.5 * acceleration * t_stop**2, 0, 0, 0, 0, 0],
                               atol=1e-14)
    np.testing.assert_allclose(sim.joint_positions(), result.q)
    assert result.duration_s == pytest.approx(t_stop)
    assert sim.time == pytest.approx(result.duration_s)
    assert edges == [] and sim.digital_inputs()[0] is False


def test_stopped_guarded_move_reports_no_contact_that_came_after_the_stop() -> None:
    world = probe_world()
    complete, complete_edges = recording_sim(world)
    stopped, stopped_edges = recording_sim(world)
    target = complete.joint_positions() + STEP
    full = complete.guarded_move(target, 0.5, 0)
    assert full.contact and [e[1] for e in complete_edges] == [True]

    plan = stopped.begin_move(target, 0.5, io_line=0)
    assert plan.contact is not None and plan.s_end == plan.contact.s_stop
    before_touch = 0.5 * plan.contact.s_contact / plan.s_end
    result = stopped.finish_move(plan, before_touch)
    assert isinstance(result, GuardedMoveResult)
    assert not result.contact and result.q_latched is None and result.reason == "aborted"
    np.testing.assert_allclose(result.q, plan.q_at(before_touch))
    assert stopped_edges == [] and stopped.digital_inputs()[0] is False


def test_guarded_move_stopped_after_the_latch_keeps_its_contact() -> None:
    sim, edges = recording_sim(probe_world())
    plan = sim.begin_move(sim.joint_positions() + STEP, 0.5, io_line=0)
    assert plan.contact is not None
    after_latch = (plan.contact.s_latch + plan.contact.s_stop) / 2 / plan.s_end
    result = sim.finish_move(plan, after_latch)
    assert isinstance(result, GuardedMoveResult)
    assert result.contact and result.reason == "aborted"
    np.testing.assert_allclose(result.q_latched, plan.contact.q_latched)
    np.testing.assert_allclose(result.q, plan.q_at(after_latch))
    assert [e[1] for e in edges] == [True]


def test_one_plan_at_a_time_and_no_offset_writes_while_moving() -> None:
    sim = Simulation(scenario_from_dict({}))
    q0 = sim.joint_positions()
    plan = sim.begin_move(q0 + 0.1, 1.0)
    with pytest.raises(SimulationRefused) as busy:
        sim.move_joints(q0, 1.0)
    assert busy.value.code == "busy"
    with pytest.raises(SimulationRefused) as offsets:
        sim.set_zero_offsets(sim.zero_offsets())
    assert offsets.value.code == "busy"
    sim.finish_move(plan, 0.0)
    np.testing.assert_array_equal(sim.joint_positions(), q0)
    with pytest.raises(SimulationRefused, match="not the motion in progress"):
        sim.finish_move(plan)
    assert sim.move_joints(q0 + 0.1, 1.0).completed  # free again
