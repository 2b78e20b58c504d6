"""Simulation: motion, limits, estop, faults, zero offsets, hidden effects, truth."""

from __future__ import annotations

import json
import math
from collections.abc import Callable

import numpy as np
import pytest

from controller_stub.errors import SimulationRefused
from controller_stub.world.motion import PathProfile
from controller_stub.world.robot_model import gravity_torque
from controller_stub.world.simulation import Simulation

MakeSim = Callable[..., Simulation]

Q_A = np.array([0.2, -1.3, 1.2, -1.4, -1.5, 0.3])


def test_motion_duration_and_clock(make_sim: MakeSim) -> None:
    sim = make_sim(truth={"zero_errors": [0.0] * 6})
    q0 = sim.joint_positions()
    target = q0 + np.array([0.5, -0.2, 0.0, 0.1, 0.0, -1.0])
    result = sim.move_joints(target, 0.5)
    # joint 6 leads (1 rad; all joints pi rad/s, 4 rad/s^2): it reaches 0.5 pi rad/s,
    # cruises, and brakes: d / v + v / a (the others scaled to finish with it)
    v, a = 0.5 * np.pi, 4.0
    np.testing.assert_array_equal(sim.max_joint_speed(), np.pi)
    np.testing.assert_array_equal(sim.max_joint_acceleration(), a)
    expected = 1.0 / v + v / a
    assert result.completed
    assert result.duration_s == pytest.approx(expected, rel=1e-12)
    # robot time: the motion only (the settling comes before the next measurement)
    assert sim.time == pytest.approx(expected, rel=1e-12)
    np.testing.assert_array_equal(sim.joint_positions(), target)


def test_profile_is_a_continuous_trapezoid_or_triangle_of_the_stated_duration() -> None:
    """PathProfile against the closed form: duration, s(t) and its slope continuous (finite
    differences), ramps at A, cruise at V, triangular when the move is short."""
    speed, accel = np.full(6, 0.5 * np.pi), np.full(6, 1.4)
    for d, triangular in ((np.radians(30.0), True), (3.0, False)):
        dq = np.array([0.0, d, -0.3 * d, 0.0, 0.1 * d, 0.0])
        profile = PathProfile.of_move(dq, speed, accel)
        v, a = 0.5 * np.pi, 1.4
        expected = 2 * np.sqrt(d / a) if triangular else d / v + v / a
        assert (d <= v * v / a) == triangular
        assert profile.duration_s == pytest.approx(expected, rel=1e-14)
        t = np.linspace(0.0, profile.duration_s, 20001)
        s = profile.s_at(t)
        assert s[0] == 0.0 and s[-1] == pytest.approx(1.0, abs=1e-14)
        rate = np.diff(s) / np.diff(t)  # ds/dt: continuous, never above V
        assert np.max(np.abs(np.diff(rate))) < 1e-3 * np.max(rate)
        assert np.max(rate) * d <= v * (1 + 1e-9)
        assert (np.max(rate) * d < 0.999 * v) == triangular
        accel_fd = np.diff(rate) / np.diff(t)[1:]
        assert np.max(np.abs(accel_fd)) * d <= a * (1 + 1e-6)
        np.testing.assert_allclose(profile.time_at(s), t, atol=1e-9)  # the inverse
        mid = profile.duration_s / 2
        assert profile.rate_at(mid) == pytest.approx(np.max(rate), rel=1e-3)
        # the leading joint's own profile: 0.5 a t^2 in the ramp
        assert profile.s_at(0.01) * d == pytest.approx(0.5 * a * 0.01**2, rel=1e-12)
    # a joint that ramps slower than the leader binds the path's acceleration
    slow = PathProfile.of_move(np.array([1.0, 0.5]), np.array([1.0, 1.0]), np.array([4.0, 0.5]))
    assert slow.acceleration == pytest.approx(1.0) and slow.cruise == pytest.approx(1.0)
    assert PathProfile.of_move(np.zeros(6), speed, accel).duration_s == 0.0


def test_settle_and_capture_time_charged_to_the_clock(make_sim: MakeSim) -> None:
    """Settling is charged before a measurement that follows motion, not after every move:
    a move that another move follows (a via point) pays none, a second capture at the same
    pose none; the frame is stamped after the settling, at the exposure's start."""
    sim = make_sim(truth={"zero_errors": [0.0] * 6},
                   motion={"settle_s": 0.5, "capture_s": 0.25})
    q0 = sim.joint_positions()
    via = q0 + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.4])
    target = q0 + np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.2])
    motion = sim.motion.motion_duration(q0, via, 1.0) + sim.motion.motion_duration(
        via, target, 1.0)
    sim.move_joints(via, 1.0)
    sim.move_joints(target, 1.0)  # the via move ended at rest: no settling between
    assert sim.time == pytest.approx(motion, rel=1e-12)
    still = sim.move_joints(target, 1.0)  # already there: no motion, nothing to settle
    assert still.duration_s == 0.0 and sim.time == pytest.approx(motion, rel=1e-12)
    frame = sim.capture_stereo("target")
    assert frame.time == pytest.approx(motion + 0.5, rel=1e-12)  # settled, then exposed
    assert sim.time == pytest.approx(motion + 0.75, rel=1e-12)
    sim.capture_stereo("chessboard", 0)  # the robot waits for rig captures too; settled
    assert sim.time == pytest.approx(motion + 1.0, rel=1e-12)
    assert sim.settle_for_measurement() == 0.0  # standing still longer than settle_s


def test_settling_before_a_tracker_reading_and_a_guarded_move(make_sim: MakeSim) -> None:
    """A tracker reading and the start of a guarded move are measurements: each waits out
    what is left of settle_s since the last motion ended (0 after a capture there)."""
    sim = make_sim(truth={"zero_errors": [0.0] * 6}, motion={"capture_s": 0.1})
    q0 = sim.joint_positions()
    up = q0 + np.array([0.0, -0.05, 0.0, 0.0, 0.0, 0.0])
    moved = sim.move_joints(up, 1.0)
    reading = sim.tracker.measure_tracker()
    assert reading["time"] == pytest.approx(moved.duration_s + 0.3, rel=1e-12)
    t = sim.time
    guarded = sim.guarded_move(q0, 0.1, sim.scenario.probe.io_line)
    assert sim.time == pytest.approx(t + guarded.duration_s, rel=1e-12)  # settled already
    back = sim.move_joints(up, 1.0)
    t = sim.time
    again = sim.guarded_move(q0, 0.1, sim.scenario.probe.io_line)
    assert sim.time == pytest.approx(t + 0.3 + again.duration_s, rel=1e-12)
    assert back.duration_s > 0.0


def test_aborted_move_settles_before_the_next_measurement(make_sim: MakeSim) -> None:
    """An abort decelerates the arm: the abort itself charges no settling, but the next
    measurement waits settle_s from where it stopped, as after a completed move."""
    sim = make_sim(truth={"zero_errors": [0.0] * 6})
    plan = sim.begin_move(sim.joint_positions() + 0.3, 1.0)
    result = sim.finish_move(plan, 0.5)
    assert not result.completed and result.duration_s > 0.0
    assert sim.time == pytest.approx(result.duration_s, rel=1e-12)  # no settling charged
    assert sim.settle_for_measurement() == pytest.approx(0.3, rel=1e-12)
    assert sim.time == pytest.approx(result.duration_s + 0.3, rel=1e-12)
    plan = sim.begin_move(sim.joint_positions() + 0.3, 1.0)
    t = sim.time
    cut = sim.finish_move(plan, 0.5)
    frame = sim.capture_stereo("target")  # a capture right after a half-profile abort
    assert frame.time == pytest.approx(t + cut.duration_s + 0.3, rel=1e-12)


def test_joint_limit_and_bad_arguments_refused(make_sim: MakeSim) -> None:
    sim = make_sim()
    lo, hi = sim.joint_limits()
    target = sim.joint_positions()
    target[2] = hi[2] + 0.01
    with pytest.raises(SimulationRefused) as info:
        sim.move_joints(target, 0.5)
    assert info.value.code == "joint_limit" and "joint 3" in str(info.value)
    for bad_speed in (0.0, 1.5, -0.1):
        with pytest.raises(SimulationRefused) as info:
            sim.move_joints(sim.joint_positions(), bad_speed)
        assert info.value.code == "invalid_argument"
    with pytest.raises(SimulationRefused, match="expected 6"):
        sim.move_joints([0.0] * 5, 0.5)
    assert sim.time == 0.0


def test_estop_refuses_until_reset(make_sim: MakeSim) -> None:
    sim = make_sim()
    sim.estop()
    assert sim.estopped
    with pytest.raises(SimulationRefused) as info:
        sim.move_joints(Q_A, 0.5)
    assert info.value.code == "estop"
    sim.reset_estop()
    assert sim.move_joints(Q_A, 0.5).completed


def test_faults_refuse_move_and_estop_after_moves(make_sim: MakeSim) -> None:
    sim = make_sim(faults={"refuse_move_indices": [1], "estop_after_moves": 3})
    sim.move_joints(Q_A, 1.0)  # move 0
    with pytest.raises(SimulationRefused) as info:
        sim.move_joints(Q_A + 0.1, 1.0)  # move 1 refused
    assert info.value.code == "refused_fault"
    sim.move_joints(Q_A + 0.1, 1.0)  # move 2 (2nd completed)
    sim.move_joints(Q_A, 1.0)  # 3rd completed -> estop
    assert sim.estopped
    with pytest.raises(SimulationRefused, match="emergency"):
        sim.move_joints(Q_A + 0.1, 1.0)
    sim.reset_estop()
    sim.move_joints(Q_A + 0.1, 1.0)
    sim.move_joints(Q_A, 1.0)
    assert not sim.estopped  # fires once


def test_offsets_set_limit_history_rollback(make_sim: MakeSim) -> None:
    sim = make_sim(server={"initial_offsets": [0.01, -0.02, 0.0, 0.0, 0.0, 0.03]})
    o0 = sim.zero_offsets()
    q_before = sim.joint_positions()
    delta = np.array([1e-3, -2e-3, 0.0, 5e-4, 0.0, 0.0])
    previous = sim.set_zero_offsets(o0 + delta)
    np.testing.assert_array_equal(previous, o0)
    np.testing.assert_allclose(sim.joint_positions(), q_before + delta, atol=1e-15)
    too_far = o0.copy()
    too_far[4] += math.radians(5.01)
    with pytest.raises(SimulationRefused) as info:
        sim.set_zero_offsets(too_far)
    assert info.value.code == "offset_limit" and "joint 5" in str(info.value)
    # the limit is measured from the ORIGINAL offsets, not the current ones
    ok = o0.copy()
    ok[4] += math.radians(4.9)
    sim.set_zero_offsets(ok)
    history = sim.offset_history()
    assert [i for i, _ in history] == [0, 1, 2]
    np.testing.assert_array_equal(history[1][1], o0 + delta)
    replaced = sim.rollback(0)
    np.testing.assert_array_equal(replaced, ok)
    np.testing.assert_array_equal(sim.zero_offsets(), o0)
    np.testing.assert_allclose(sim.joint_positions(), q_before, atol=1e-15)
    with pytest.raises(SimulationRefused) as info:
        sim.rollback(99)
    assert info.value.code == "unknown_history_id"


def test_pushed_offsets_change_later_physics_exactly(make_sim: MakeSim) -> None:
    sim = make_sim(seed=11)
    sim.move_joints(Q_A, 0.5)
    e = np.asarray(sim.truth()["zero_errors"])
    np.testing.assert_allclose(sim.physical_angles(), Q_A + e, atol=1e-15)
    T_before = sim.flange_pose()
    delta = np.array([1e-3, -2e-3, 3e-3, 0.0, -1e-3, 2e-3])
    sim.set_zero_offsets(sim.zero_offsets() + delta)
    # pushing offsets does not move the robot; only the reported angles shift
    np.testing.assert_allclose(sim.flange_pose(), T_before, atol=1e-15)
    np.testing.assert_allclose(sim.truth()["zero_errors"], e - delta, atol=1e-15)
    sim.move_joints(Q_A, 0.5)  # same command, different physical pose
    np.testing.assert_allclose(sim.physical_angles(), Q_A + e - delta, atol=1e-15)
    # a perfect host compensation o_new = o + e makes reported == physical
    sim.set_zero_offsets(sim.zero_offsets() + (e - delta))
    sim.move_joints(Q_A, 0.5)
    np.testing.assert_allclose(sim.physical_angles(), Q_A, atol=1e-15)
    np.testing.assert_allclose(sim.truth()["zero_errors"], 0.0, atol=1e-15)


def test_backlash_sign_follows_approach_direction(make_sim: MakeSim) -> None:
    b = np.array([1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3])
    sim = make_sim(truth={"zero_errors": [0.0] * 6, "backlash": b.tolist()})
    sim.move_joints(Q_A - 0.1, 1.0)
    sim.move_joints(Q_A, 1.0)  # every joint approached from below (+ direction)
    np.testing.assert_allclose(sim.physical_angles(), Q_A + b, atol=1e-15)
    sim.move_joints(Q_A + 0.1, 1.0)
    sim.move_joints(Q_A, 1.0)  # from above
    np.testing.assert_allclose(sim.physical_angles(), Q_A - b, atol=1e-15)
    mixed = Q_A.copy()
    mixed[0] += 0.2  # only joint 1 moves (down again after); others keep their direction
    sim.move_joints(mixed, 1.0)
    expected = Q_A - b
    expected[0] = mixed[0] + b[0]
    np.testing.assert_allclose(sim.physical_angles(), expected, atol=1e-15)


def test_compliance_equals_c_times_actual_gravity_torque(make_sim: MakeSim) -> None:
    c = np.array([2e-6, 5e-6, 4e-6, 1e-5, 1e-5, 1e-5])
    sim = make_sim(truth={"zero_errors": [0.0] * 6, "joint_compliance": c.tolist()})
    sim.move_joints(Q_A, 1.0)
    q_phys = sim.physical_angles()
    tau = gravity_torque(sim.model, q_phys)[0]
    assert np.max(np.abs(c * tau)) > 1e-5  # the effect is visible
    np.testing.assert_allclose(q_phys, Q_A + c * tau, atol=1e-14)


def test_harmonic_and_encoder_scale_formulas(make_sim: MakeSim) -> None:
    h = np.array([[1e-4, -2e-4, 3e-4, 5e-5]] * 6)
    s = np.array([1e-4, -2e-4, 3e-4, 0.0, 1e-4, -1e-4])
    sim = make_sim(
        truth={
            "zero_errors": [0.0] * 6,
            "transmission_harmonic": h.tolist(),
            "encoder_scale": s.tolist(),
        }
    )
    sim.move_joints(Q_A, 1.0)
    q = Q_A
    expected = (
        q
        + s * q
        + (
            h[:, 0] * np.sin(q)
            + h[:, 1] * np.cos(q)
            + h[:, 2] * np.sin(2 * q)
            + h[:, 3] * np.cos(2 * q)
        )
    )
    np.testing.assert_allclose(sim.physical_angles(), expected, atol=1e-15)


def test_thermal_drift_grows_lengths_with_run_time(make_sim: MakeSim) -> None:
    rate = [0.0, 0.0, 1e-6, 0.0, 0.0, 0.0]  # a3 grows 1 um per simulated second
    sim = make_sim(truth={"zero_errors": [0.0] * 6, "thermal_drift": {"a": rate}})
    sim.move_joints(Q_A, 1.0)
    T0, t0 = sim.flange_pose(), sim.time
    sim.move_joints(Q_A + 1.0, 0.01)
    sim.move_joints(Q_A, 0.01)
    T1, t1 = sim.flange_pose(), sim.time
    assert t1 - t0 > 50
    shift = np.linalg.norm(T1[:3, 3] - T0[:3, 3])
    assert shift == pytest.approx(1e-6 * (t1 - t0), rel=1e-6)  # a3 is a straight offset
    assert sim.truth()["link_length_deltas_now"]["a"][2] == pytest.approx(1e-6 * t1)


def test_link_length_errors_move_the_flange(make_sim: MakeSim) -> None:
    sim = make_sim(truth={"zero_errors": [0.0] * 6})
    sim2 = make_sim(
        truth={"zero_errors": [0.0] * 6, "link_length_errors": {"d": [0, 0, 0, 0, 0, 2e-4]}}
    )
    for s in (sim, sim2):
        s.move_joints(Q_A, 1.0)
    T, T2 = sim.flange_pose(), sim2.flange_pose()
    # d6 is along the flange z axis
    np.testing.assert_allclose(T2[:3, 3] - T[:3, 3], 2e-4 * T[:3, 2], atol=1e-15)


def test_truth_is_json_and_description_hides_it(make_sim: MakeSim) -> None:
    sim = make_sim(seed=5, truth={"zero_errors": {"random_deg": 0.5}, "backlash": [1e-4] * 6})
    truth = json.loads(json.dumps(sim.truth()))
    assert truth["robot"] == "ur5e"
    assert len(truth["zero_errors"]) == 6
    assert max(abs(v) for v in truth["zero_errors"]) <= math.radians(0.5)
    assert truth["effects"]["backlash"] == [1e-4] * 6
    for key in ("fx", "fy", "cx", "cy", "distortion", "baseline", "T_flange_camera"):
        assert key in truth["camera"]
    for key in ("stylus_tip", "sphere_centre", "sphere_radius"):
        assert key in truth["probe"]
    description = json.dumps(sim.camera_description())
    assert "error" not in description
    assert str(truth["camera"]["fx"]) not in description
    assert str(truth["target"]["centre"][0]) not in description


def test_determinism_same_seed_same_world(make_sim: MakeSim) -> None:
    a, b = make_sim(seed=21), make_sim(seed=21)
    c = make_sim(seed=22)
    assert a.truth() == b.truth()
    assert a.truth()["zero_errors"] != c.truth()["zero_errors"]
    fa, fb = a.capture_stereo("chessboard", 3), b.capture_stereo("chessboard", 3)
    np.testing.assert_array_equal(fa.left, fb.left)
    np.testing.assert_array_equal(fa.right, fb.right)
    np.testing.assert_array_equal(a.stereo.chessboard_poses(), b.stereo.chessboard_poses())
    assert not np.array_equal(a.stereo.chessboard_poses(), c.stereo.chessboard_poses())


def test_digital_outputs_and_io_range(make_sim: MakeSim) -> None:
    sim = make_sim()
    sim.set_digital_output(3, True)
    assert sim.digital_outputs()[3] is True
    with pytest.raises(SimulationRefused):
        sim.set_digital_output(99, True)
    assert len(sim.digital_inputs()) == 8


def test_unknown_pattern_and_view_refused(default_sim: Simulation) -> None:
    with pytest.raises(SimulationRefused):
        default_sim.capture_stereo("plaid")
    # n_views planned views, then 3 x n_views extra views (aimed anywhere) for coverage
    max_views = default_sim.camera_description()["chessboard"]["max_views"]
    assert max_views == 4 * default_sim.scenario.chessboard.n_views
    extra = default_sim.capture_stereo("chessboard", view=20)
    assert extra.left.shape == (1024, 1280)
    with pytest.raises(SimulationRefused):
        default_sim.capture_stereo("chessboard", view=max_views)
