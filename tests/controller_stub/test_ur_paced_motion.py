"""The UR personality's cycle-by-cycle view of a motion plan (controller_stub/ur/paced_motion)."""

from __future__ import annotations

import numpy as np
import pytest

from controller_stub.ur.paced_motion import CYCLE_S, PacedMotion
from controller_stub.world.motion import GuardedContact, MotionPlan, PathEdge, PathProfile

Q0 = np.zeros(6)
Q1 = np.array([0.2, -0.1, 0.0, 0.05, 0.0, 0.0])


def _plan(duration: float = 0.1, contact: GuardedContact | None = None,
          edges: tuple[PathEdge, ...] = (), s_end: float = 1.0) -> MotionPlan:
    """A plan at constant path speed (no ramp: infinite acceleration) over `duration` s."""
    profile = PathProfile.of_move(Q1 - Q0, np.abs(Q1 - Q0).max() / duration, np.inf)
    return MotionPlan(Q0, Q1, 0.0, profile, s_end, 0 if contact else None, edges, contact)


def test_the_path_advances_one_cycle_at_a_time_in_controller_time() -> None:
    motion = PacedMotion(_plan(0.1), start_cycle=100, wall_per_sim=1.0, probe_line=0)
    assert motion.s_at(100) == 0.0 and motion.s_at(90) == 0.0
    assert motion.s_at(105) == pytest.approx(5 * CYCLE_S / 0.1)
    np.testing.assert_allclose(motion.q_at(110), 0.2 * Q1)
    np.testing.assert_allclose(motion.qd_at(110), Q1 / 0.1)
    assert not motion.finished(149) and motion.finished(150)
    np.testing.assert_allclose(motion.q_at(500), Q1)
    np.testing.assert_allclose(motion.qd_at(500), 0.0)
    # a slower clock (time_scale 2): half the path per cycle
    slow = PacedMotion(_plan(0.1), start_cycle=0, wall_per_sim=2.0, probe_line=0)
    assert slow.s_at(10) == pytest.approx(0.5 * motion.s_at(110))
    # time_scale 0: at the end at once
    instant = PacedMotion(_plan(0.1), start_cycle=0, wall_per_sim=0.0, probe_line=0)
    assert instant.finished(0) and instant.fraction_at(0) == 1.0


def test_the_probe_input_rises_at_the_latch_point_and_follows_path_edges() -> None:
    contact = GuardedContact(s_contact=0.30, s_latch=0.35, s_stop=0.45,
                             q_latched=0.35 * Q1, time_latch=0.035, speed_mps=0.01)
    motion = PacedMotion(_plan(0.1, contact, s_end=0.45), start_cycle=0, wall_per_sim=1.0,
                         probe_line=0)
    # cycle k shows s = 0.02 k: low through 0.34 (touching, not yet latched), high from 0.36
    assert not motion.probe_level(17, False)
    assert motion.probe_level(18, False)
    assert motion.fraction_at(18) == pytest.approx(0.36 / 0.45)
    assert not motion.finished(22) and motion.finished(23)  # s_end 0.45 = 22.5 cycles
    falling = PathEdge(0.09, False, 0.009, 0.09 * Q1)
    leaving = PacedMotion(_plan(0.1, edges=(falling,)), start_cycle=0, wall_per_sim=1.0,
                          probe_line=0)
    assert leaving.probe_level(4, True) and not leaving.probe_level(5, True)


def test_a_stop_decelerates_at_its_rate_from_the_cycle_it_arrives_at() -> None:
    """stopj(a) mid-cruise: the leading joint (0.2 rad) slows at a rad/s^2, so the path at
    D = a / 0.2; it rests at s0 + v0^2 / 2D after v0 / D, and the plan's fraction there is
    where the plan itself reaches that s (the ramp took longer: sim_time_at)."""
    motion = PacedMotion(_plan(0.1), start_cycle=0, wall_per_sim=1.0, probe_line=0)
    stopping = motion.stopped(10, deceleration=40.0)  # s0 = 0.2, v0 = 10 / s, D = 200 / s^2
    assert stopping.stopped(12, 1.0) is stopping  # a second stop keeps the first
    v0, path_d = 10.0, 40.0 / 0.2
    s_final = 0.2 + v0**2 / (2 * path_d)  # 0.45
    t_end = 0.02 + v0 / path_d  # 0.07 s: cycle 35
    tau = 5 * CYCLE_S
    assert stopping.s_at(15) == pytest.approx(0.2 + v0 * tau - 0.5 * path_d * tau**2)
    np.testing.assert_allclose(stopping.qd_at(15), Q1 * (v0 - path_d * tau))
    assert not stopping.finished(34) and stopping.finished(35)
    assert stopping.s_at(35) == pytest.approx(s_final) == stopping.s_at(500)
    np.testing.assert_allclose(stopping.q_at(500), s_final * Q1)
    np.testing.assert_allclose(stopping.qd_at(35), 0.0)
    assert stopping.fraction_at(500) == pytest.approx(s_final)  # constant plan speed
    assert stopping.sim_time_at(500) == pytest.approx(t_end)


def test_a_stop_never_runs_ahead_of_the_plan() -> None:
    """A gentle stop late in a ramped plan: the plan's own deceleration ends first, so the
    motion ends where and when the plan does (completed: fraction 1)."""
    profile = PathProfile.of_move(Q1 - Q0, np.full(6, 1.0), np.full(6, 4.0))
    plan = MotionPlan(Q0, Q1, 0.0, profile, 1.0, None, ())
    motion = PacedMotion(plan, start_cycle=0, wall_per_sim=1.0, probe_line=0)
    end_cycle = int(np.ceil(profile.duration_s / CYCLE_S))
    stopping = motion.stopped(end_cycle - 20, deceleration=0.1)
    for cycle in range(end_cycle - 20, end_cycle + 5):
        assert stopping.s_at(cycle) == pytest.approx(motion.s_at(cycle))
    assert stopping.finished(end_cycle) and stopping.fraction_at(end_cycle) == 1.0
