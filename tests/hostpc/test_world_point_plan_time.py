"""world_point's default plan in the bench's cell (no frame known): its tour is shortened
after the selection (hostpc.planning.design.shorten_tour) and keeps the target sigma. No
robot moves: the plan is made from a simulator's state and tracker description on a free
loopback port."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.run_plan import plan_run
from hostpc.kinds.world_point.method import WorldPointMethod
from hostpc.methods.base import NullProgress, RunSettings
from hostpc.methods.cell import build_cell
from hostpc.planning.design import (
    design_matrix,
    greedy_d_optimal,
    joint_offset_sigmas,
    make_design,
    shorten_tour,
)
from hostpc.planning.robot_time import TimeLimits
from hostpc.planning.tour import full_turn_joints, path_time
from hostpc.robots.base import RobotState
from tests.hostpc.test_plan_robot_time import default_simulator

TARGET_DEG = 0.002


async def _method_and_state(tmp_path: Path, seed: int
                            ) -> tuple[WorldPointMethod, RunSettings, RobotState]:
    async with default_simulator("world_point") as robot:
        state = await robot.state()
        # bench/bench_robot_time.py's run: `calibrate --scenario FILE`, no frame known
        settings = RunSettings(method="world_point", seed=seed, n_poses=60, n_verify=4,
                               n_candidates=1500, speed=0.5, target_sigma_deg=TARGET_DEG)
        method = WorldPointMethod(settings, build_cell(state.camera, state.robot, None, ()),
                                  tmp_path)
        await method.prepare(robot, NullProgress())
        return method, settings, state


@pytest.mark.parametrize("seed", range(3))
async def test_default_plan_is_short_and_keeps_its_target_sigma(seed: int,
                                                                tmp_path: Path) -> None:
    """The old plan (the travel-aware selection's tour) predicted 23.6, 23.9 and 21.5 s for
    planning seeds 0-2 (14, 13 and 14 fit poses); shortened 15.5, 15.6 and 17.6 s."""
    method, settings, state = await _method_and_state(tmp_path, seed)
    plan = plan_run(method, state, settings, NullProgress())
    planned = plan.info["predicted_robot_time_s"]
    assert planned["total"] <= 19.0, planned
    sigmas = [s for s in plan.info["predicted_joint_sigma_deg"] if s is not None]
    assert len(sigmas) == 4 and max(sigmas) <= TARGET_DEG * (1 + 1e-9), sigmas
    # the floor never exceeds the plan's own settle and capture
    poses = plan.q.shape[0] + plan.q_verify.shape[0]
    assert planned["floor"] <= planned["settle"] + planned["capture"] + 1e-9
    assert planned["settle"] + planned["capture"] == pytest.approx(0.4 * poses)


async def test_shorten_tour_never_slower_and_keeps_every_sigma(tmp_path: Path) -> None:
    """On a tour of the 20 most informative poses: fewer poses, less motion, every
    identifiable offset still at the target; the poses held fixed stay."""
    method, settings, state = await _method_and_state(tmp_path, 0)
    pool = method.candidates(state, np.random.default_rng(0))
    A, names, units = design_matrix(method.design_dataset(pool), None, (), pool.shape[0])
    design = make_design(A, names, units)
    tour = greedy_d_optimal(design, 20)
    limits = (state.q_min, state.q_max)
    q0 = np.asarray(state.q, float)
    rates = TimeLimits.from_extra(state.extra, 6).rates(0.5)
    periodic = full_turn_joints(*limits)
    target = math.radians(TARGET_DEG)
    assert np.nanmax(joint_offset_sigmas(design.subset(tour), 6)) <= target
    short = shorten_tour(design, pool, tour, q0, target, 6, 0.4, rates, periodic,
                         fixed=tour[:2])
    assert set(tour[:2].tolist()) <= set(short.tolist())
    assert short.size < tour.size
    before = path_time(pool[tour], q0, rates, periodic) + 0.4 * tour.size
    after = path_time(pool[short], q0, rates, periodic) + 0.4 * short.size
    assert after < before - 1.0, (before, after)
    assert np.nanmax(joint_offset_sigmas(design.subset(short), 6)) <= target * (1 + 1e-9)
