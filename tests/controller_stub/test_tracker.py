"""The simulated laser tracker: its noise matches the covariance it reports, the mean is the
true reflector position, and the beam is lost past the acceptance cone."""

from __future__ import annotations

import numpy as np

from controller_stub.geometry import make_transform
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.scenario.tracker import TrackerSpec
from controller_stub.sensors.world_point import Tracker, spherical_noise
from controller_stub.world.simulation import Simulation


def _flange_poses(sim: Simulation, count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = sim.joint_limits()
    q = rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0), size=(count, sim.n_joints))
    return sim.physics.flange_pose(q, 0.0)


def test_noise_spread_matches_the_reported_covariance() -> None:
    spec = TrackerSpec()
    T_base_flange = make_transform([0.4, 0.1, 0.5], [0.0, 0.0, 0.0])
    # point the reflector's axis (flange z) at the tracker
    tracker = Tracker(spec, np.random.default_rng(1))
    p = (tracker.T_world_base @ T_base_flange)[:3, 3]
    z = -p / np.linalg.norm(p)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R_world_flange = np.column_stack([x, np.cross(z, x), z])
    T_base_flange[:3, :3] = tracker.T_world_base[:3, :3].T @ R_world_flange
    truth = (tracker.T_world_base @ T_base_flange @ np.r_[tracker.reflector_true("smr1"), 1])[:3]
    samples = np.array([tracker.measure(T_base_flange)[0]["smr1"]["p"] for _ in range(4000)])
    np.testing.assert_allclose(samples.mean(axis=0), truth, atol=2e-6)
    expected = spherical_noise(truth, spec.sigma_distance, spec.sigma_angle)
    u = truth / np.linalg.norm(truth)
    radial = np.std(samples @ u)
    assert abs(radial / np.sqrt(u @ expected @ u) - 1.0) < 0.1
    across = np.cross(u, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    lateral = np.std(samples @ across)
    assert abs(lateral / np.sqrt(across @ expected @ across) - 1.0) < 0.1
    # an angle noise of 4 urad at ~2.5 m is ~10 um across, the distance noise 8 um along
    assert 5e-6 < lateral < 2e-5


def test_beam_is_lost_outside_the_acceptance_cone() -> None:
    sim = Simulation(scenario_from_dict({}))
    tracker = sim.tracker
    seen_any = lost_any = False
    for T in _flange_poses(sim, 200):
        T_world_flange = tracker.T_world_base @ T
        p = T_world_flange[:3, :3] @ tracker.reflector_true("smr1") + T_world_flange[:3, 3]
        axis = T_world_flange[:3, 2]
        inside = float(axis @ (-p / np.linalg.norm(p))) >= np.cos(np.radians(55.0))
        seen, lost = tracker.measure(T)
        assert ("smr1" in seen) == inside and ("smr1" in lost) == (not inside)
        seen_any |= inside
        lost_any |= not inside
    assert seen_any and lost_any


def test_scenario_errors_move_the_truth_not_the_description() -> None:
    sim = Simulation(scenario_from_dict({"tracker": {
        "world_base_error": {"xyz": [0.001, 0.0, 0.0], "rpy": [0.0, 0.0, 0.001]},
        "reflectors": {"a": {"position": [0.0, 0.0, 0.05], "error": [0.0002, 0.0, 0.0]},
                       "b": {"position": [0.05, 0.0, 0.03], "axis": [1.0, 0.0, 0.0]}}}}))
    description = sim.tracker.measure_tracker()["description"]
    assert description["reflectors"] == {"a": [0.0, 0.0, 0.05], "b": [0.05, 0.0, 0.03]}
    truth = sim.truth()["tracker"]
    np.testing.assert_allclose(truth["reflectors"]["a"], [0.0002, 0.0, 0.05])
    assert truth["T_world_base"]["xyz"] != description["world_base"]["xyz"]


def test_a_reading_takes_robot_time_as_a_capture_does() -> None:
    """The robot stands still for a tracker reading: the clock advances by
    `motion.capture_s` after the reading, which is stamped at its start (the host's plan
    charges each pose a capture: hostpc.planning.robot_time)."""
    sim = Simulation(scenario_from_dict({"motion": {"capture_s": 0.25}}))
    start = sim.time
    first = sim.tracker.measure_tracker()
    second = sim.tracker.measure_tracker()
    assert first["time"] == start and second["time"] == start + 0.25
    assert sim.time == start + 0.5
