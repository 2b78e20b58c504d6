"""Touch probe: exact contact, latched overtravel, IO edges, faults."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.optimize import least_squares

from controller_stub.world.simulation import Simulation

MakeSim = Callable[..., Simulation]
LATENCY = 0.004


def _probe_sim(make_sim: MakeSim, **truth: object) -> Simulation:
    return make_sim(
        seed=3,
        truth={"zero_errors": {"random_deg": 0.3}, "probe_trigger_latency_s": LATENCY, **truth},
        probe={"repeatability_sigma": 0.0},
    )


def _pose_with_tip_at(sim: Simulation, point: np.ndarray) -> np.ndarray:
    """Reported q putting the TRUE tip at `point` with the flange z pointing down."""

    def residual(q: np.ndarray) -> np.ndarray:
        T = sim.physics.flange_pose(sim.physical_angles(q)[None], sim.time)[0]
        tip = T[:3, :3] @ sim.probe.tip_flange + T[:3, 3]
        return np.concatenate([tip - point, 0.1 * (T[:3, 2] - [0, 0, -1.0])])

    lo, hi = sim.joint_limits()
    heading = np.arctan2(-point[1], -point[0])  # UR q = 0 stretches the arm along -x
    start = np.array([heading, -2.0, 1.5, -1.2, -1.57, 0.0])
    sol = least_squares(residual, start, bounds=(lo, hi), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert sol.cost < 1e-20
    return np.asarray(sol.x)


def _descent(sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
    """Start 3 cm above the sphere top, target 1 cm below its top (through the sphere)."""
    top = sim.probe.sphere_centre + [0.0, 0.0, sim.scenario.probe.sphere_radius]
    q_above = _pose_with_tip_at(sim, top + [0.0, 0.0, 0.03])
    q_below = _pose_with_tip_at(sim, top - [0.0, 0.0, 0.01])
    return q_above, q_below


def test_contact_distance_and_overtravel(make_sim: MakeSim) -> None:
    sim = _probe_sim(make_sim)
    q_above, q_below = _descent(sim)
    sim.move_joints(q_above, 1.0)
    edges: list[tuple[int, bool, float, np.ndarray]] = []
    sim.on_io_edge = lambda line, value, t, q: edges.append((line, value, t, q))
    t0 = sim.time + sim.scenario.motion.settle_s  # a guarded move starts settled
    result = sim.guarded_move(q_below, 0.05, io_line=0)
    assert result.contact and result.q_latched is not None
    assert edges and edges[0][0] == 0 and edges[0][1] is True
    assert sim.digital_inputs()[0] is True
    # a slow approach: past its short ramp (4 rad/s^2) at cruise when it touches, where
    # it has lost half the ramp's time against a move at speed from the first instant
    profile = sim.state.move_profile(q_above, q_below, 0.05)
    rate = (q_below - q_above) * profile.cruise  # rad/s per joint at cruise
    t_latch = edges[0][2]
    t_contact = t_latch - LATENCY
    assert t_contact - t0 > profile.ramp_s > 0.0
    q_contact = q_above + (t_contact - t0 - profile.ramp_s / 2) * rate
    # at the exact contact the tip-sphere distance is R + r to 1e-9 m
    T = sim.physics.flange_pose(sim.physical_angles(q_contact)[None], sim.time)[0]
    tip = T[:3, :3] @ sim.probe.tip_flange + T[:3, 3]
    pr = sim.scenario.probe
    assert np.linalg.norm(tip - sim.probe.sphere_centre) == pytest.approx(
        pr.sphere_radius + pr.stylus_radius, abs=1e-9
    )
    # latched overtravel = joint speed x latency
    np.testing.assert_allclose(result.q_latched - q_contact, rate * LATENCY, atol=1e-12)
    np.testing.assert_allclose(edges[0][3], result.q_latched, atol=0)
    # Cartesian overtravel = tip speed x latency (a nearly straight, slow path)
    T_l = sim.physics.flange_pose(sim.physical_angles(result.q_latched)[None], sim.time)[0]
    tip_l = T_l[:3, :3] @ sim.probe.tip_flange + T_l[:3, 3]
    assert result.speed_mps is not None and result.speed_mps > 0
    assert np.linalg.norm(tip_l - tip) == pytest.approx(result.speed_mps * LATENCY, rel=1e-3)
    # the robot stopped shortly after the latch, not at the end of travel
    assert result.duration_s == pytest.approx(
        t_latch - t0 + sim.scenario.probe.stop_time_s, rel=1e-9
    )
    np.testing.assert_allclose(sim.joint_positions(), result.q)
    # leaving the sphere drops the line, with a falling edge
    sim.move_joints(q_above, 0.5)
    assert sim.digital_inputs()[0] is False
    assert edges[-1][1] is False


def test_latency_makes_overtravel_proportional_to_speed(make_sim: MakeSim) -> None:
    overtravel = []
    for speed in (0.02, 0.08):
        sim = _probe_sim(make_sim)
        q_above, q_below = _descent(sim)
        sim.move_joints(q_above, 1.0)
        r = sim.guarded_move(q_below, speed, io_line=0)
        assert r.contact and r.q_latched is not None and r.speed_mps is not None
        overtravel.append(r.speed_mps * LATENCY)
    assert overtravel[1] == pytest.approx(4 * overtravel[0], rel=1e-2)


def test_no_contact_and_lost_edge(make_sim: MakeSim) -> None:
    sim = _probe_sim(make_sim)
    q_above, q_below = _descent(sim)
    sim.move_joints(q_above, 1.0)
    q_side = _pose_with_tip_at(sim, sim.probe.sphere_centre + [0.05, 0.0, 0.05])
    r = sim.guarded_move(q_side, 0.1, io_line=0)
    assert not r.contact and r.q_latched is None
    np.testing.assert_array_equal(r.q, q_side)

    lost = make_sim(
        seed=3,
        truth={"zero_errors": {"random_deg": 0.3}},
        faults={"lose_io_edge_indices": [0]},
    )
    lost.move_joints(q_above, 1.0)
    r = lost.guarded_move(q_below, 0.05, io_line=0)
    assert not r.contact and r.reason == "no_contact"
    np.testing.assert_array_equal(r.q, q_below)  # ran to the end of travel
    r2 = lost.guarded_move(q_above, 0.05, io_line=0)  # moving out: no rising edge
    assert not r2.contact


def test_repeatability_noise_changes_contact(make_sim: MakeSim) -> None:
    latched = []
    for sigma in (0.0, 1e-4):
        sim = make_sim(seed=3, probe={"repeatability_sigma": sigma})
        q_above, q_below = _descent(sim)
        sim.move_joints(q_above, 1.0)
        r = sim.guarded_move(q_below, 0.05, io_line=0)
        assert r.contact and r.q_latched is not None
        latched.append(r.q_latched)
    assert not np.allclose(latched[0], latched[1], atol=1e-9)
