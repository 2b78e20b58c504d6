"""sphere_probe's default plan against its robot time (issue 28): the fewest whole probe
orientations that reach the target sigma, the hover only where the orientation changes,
and a floor that holds the guarded approaches. Planning only, no robot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hostpc.calibrate.run_plan import plan_run
from hostpc.kinds.sphere_probe.method import SphereProbeMethod
from hostpc.kinds.sphere_probe.planning.contacts import (
    STYLUS_POINTS,
    path_clearance,
    retract,
)
from hostpc.kinds.sphere_probe.planning.setup import (
    CONTACTS_PER_ORIENTATION,
    MIN_TARGET_ORIENTATIONS,
)
from hostpc.methods.base import NullProgress, Plan, RunSettings
from hostpc.methods.cell import Cell
from hostpc.planning.design import (
    PoseGroups,
    design_matrix,
    groups_for_target_sigma,
    joint_offset_sigmas,
    make_design,
    predicted_covariance,
)
from hostpc.planning.robot_time import DEFAULT_SETTLE_S
from hostpc.planning.tour import JointRates, move_times
from hostpc.robots.base import RobotState

UR5E_HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
PROBE = {"sphere_centre": [0.45, -0.15, 0.05], "sphere_radius": 0.0125,
         "stylus_radius": 0.0015, "tip": [0.0, 0.0, 0.12]}  # the simulator's default cell
ACCELERATION = 4.0
"""rad/s^2 the simulator reports by default (scenario motion.max_joint_acceleration)."""


def _planned(tmp_path: Path, **settings: object) -> tuple[SphereProbeMethod, RobotState, Plan]:
    run = RunSettings(method="sphere_probe", **settings)  # type: ignore[arg-type]
    cell = Cell(robot="ur5e", tool=None, target=None, target_normal=np.array([0, 0, 1.0]),
                target_radius=0.0, known=("sphere",), raw={"probe": PROBE})
    method = SphereProbeMethod(run, cell, tmp_path)
    limit = np.array([2, 2, 1, 2, 2, 2]) * np.pi
    state = RobotState(q=UR5E_HOME.copy(), zero_offsets=np.zeros(6), q_min=-limit,
                       q_max=limit, extra={"max_joint_acceleration": [ACCELERATION] * 6})
    return method, state, plan_run(method, state, run, NullProgress())


def test_the_default_plan_takes_the_fewest_orientations_that_reach_the_target(
        tmp_path: Path) -> None:
    method, state, plan = _planned(tmp_path, target_sigma_deg=0.002, n_verify=3)
    q, q_verify = plan.q, plan.q_verify
    assert method.plan is not None
    pool_groups = {c.group for c in method.plan.contacts}
    labels = np.array([method._lookup(row)[1].group for row in q])
    for label in set(labels.tolist()):  # whole orientations, one after the other
        where = np.flatnonzero(labels == label)
        assert where.size == CONTACTS_PER_ORIENTATION and np.all(np.diff(where) == 1)
    n_fit = len(set(labels.tolist()))
    assert MIN_TARGET_ORIENTATIONS <= n_fit < 20  # was 20 (the fixed plan's S6 count)
    # every identifiable offset reaches 0.002 deg; one orientation fewer does not
    A, names, units = design_matrix(method.design_dataset(q), method.default_effects(), ())
    sigmas = joint_offset_sigmas(make_design(A, names, units), 6)
    assert np.nanmax(np.degrees(sigmas)) <= 0.002
    if n_fit > MIN_TARGET_ORIENTATIONS:
        fewer = joint_offset_sigmas(make_design(A[:-CONTACTS_PER_ORIENTATION], names, units),
                                    6)[:5]
        assert not np.all(np.degrees(fewer) <= 0.002)
    # verification: one whole fresh orientation (3 contacts asked), none of the further ones
    verify_labels = {method._lookup(row)[1].group for row in q_verify}
    assert len(verify_labels) == 1 and q_verify.shape[0] == CONTACTS_PER_ORIENTATION
    more_labels = {method._lookup(row)[1].group for row in plan.more}
    assert not verify_labels & (more_labels | set(labels.tolist()))
    assert len(pool_groups) > n_fit


def test_the_path_hovers_only_between_orientations_and_keeps_off_the_sphere(
        tmp_path: Path) -> None:
    method, state, plan = _planned(tmp_path, target_sigma_deg=0.002, n_verify=3)
    q = plan.q
    path = method.robot_path(q)
    assert method.plan is not None
    hovers = {o.group: o.q_hover for o in method.plan.orientations}
    setup, config = method.setup, method.config
    previous = None
    k = 0
    for row in q:
        orientation, contact = method._lookup(row)
        # the waypoints of this contact: free moves ... start, approach, retract
        end = k + int(np.flatnonzero(np.all(path.q[k:] == row, axis=1))[0])
        via = path.q[k:end]
        is_hover = [bool(np.all(v == hovers[orientation.group])) for v in via]
        if previous is not None and previous[0] == orientation.group:
            assert not any(is_hover), "a hover between two contacts of one orientation"
            clear = path_clearance(method.chain, previous[1], contact.q_start, setup.tip,
                                   setup.sphere_centre)
            assert clear >= setup.contact_distance + 0.5 * config.standoff
        elif previous is not None and not any(is_hover):
            # straight from the last orientation's hover to this start: the wrist turns, so
            # the stylus (its half next to the tip) keeps half the standoff off the sphere
            assert np.all(previous[1] == hovers[previous[0]]) and via.shape[0] == 1
            clear = min(path_clearance(method.chain, previous[1], contact.q_start,
                                       f * setup.tip, setup.sphere_centre)
                        for f in STYLUS_POINTS)
            assert clear >= setup.contact_distance + 0.5 * config.standoff
        else:
            assert any(is_hover)  # an orientation change goes through its hover
        # the approach: measures in motion, from its start, where the robot settles (the
        # one settling of the contact: the free moves before it and the retract end at rest)
        assert path.measuring[end] and path.speed[end] == contact.speed
        assert path.settle[end - 1] and not np.any(path.settle[k:end - 1])
        assert not path.settle[end] and not path.settle[end + 1]
        # the retract: to the start; the orientation's last contact (the pole, along its
        # approach line) on to the hover, where the orientation change starts
        q_back, _ = retract(orientation, contact)
        assert np.all(path.q[end + 1] == q_back)
        last = contact.index == CONTACTS_PER_ORIENTATION - 1
        assert np.all(q_back == (hovers[orientation.group] if last else contact.q_start))
        previous = (orientation.group, q_back)
        k = end + 2
    assert np.count_nonzero(path.settle) == np.count_nonzero(path.measuring) == q.shape[0]


def test_the_floor_holds_the_guarded_approaches_of_the_fewest_orientations(
        tmp_path: Path) -> None:
    method, state, plan = _planned(tmp_path, target_sigma_deg=0.002, n_verify=3)
    q, q_verify = plan.q, plan.q_verify
    planned = plan.info["predicted_robot_time_s"]
    approach = 0.0
    for row in np.vstack([q, q_verify]):
        contact = method._lookup(row)[1]
        # at the contact's speed fraction of 180 deg/s, ramped at the simulator's rate
        rates = JointRates(np.full(6, np.pi * contact.speed), np.full(6, ACCELERATION))
        approach += float(move_times(contact.q_start[None, :], row[None, :], rates)[0])
    contacts = q.shape[0] + q_verify.shape[0]
    expected = contacts * DEFAULT_SETTLE_S + approach  # a contact is latched: no capture
    assert math.isclose(planned["floor"], expected, rel_tol=1e-9)
    # issue 28 asks for 2x the floor; with every move ramped (4 rad/s^2) this plan is 1.89x
    # (1.70x while the floor charged each contact a capture it never takes; 2.07x while
    # every free move settled)
    assert planned["total"] < 1.95 * planned["floor"]


def test_fewest_groups_for_a_target_sigma_and_no_sigma_from_too_few_rows() -> None:
    rng = np.random.default_rng(3)
    n_params, size, n_groups = 4, 3, 8
    A = rng.normal(size=(n_groups * size, 1, n_params))
    names = tuple(f"joint_offsets.q{k + 1}" for k in range(n_params))
    design = make_design(A, names, ("rad",) * n_params)
    groups = PoseGroups(labels=np.repeat(np.arange(n_groups), size))
    chosen = groups.members()
    sigma_of = [np.max(joint_offset_sigmas(design.subset(np.concatenate(chosen[:k])),
                                           n_params)) for k in range(2, n_groups + 1)]
    target = float(sigma_of[2]) * 1.0001  # reached with 4 groups, not with 3
    assert not sigma_of[1] <= target
    assert groups_for_target_sigma(design, chosen, target, n_params) == 4
    assert groups_for_target_sigma(design, chosen, target, n_params, min_groups=6) == 6
    assert groups_for_target_sigma(design, chosen, 1e-12, n_params) is None
    # one group (3 rows) cannot determine 4 parameters: no sigma, not a pseudo-inverse's
    assert np.all(np.isnan(predicted_covariance(design.subset(chosen[0]))))


def test_the_stepping_model_brackets_the_contact() -> None:
    """The Modbus stepping probe's modelled steps: the coarse steps up to the first past the
    contact, then halvings of that step until the bracket is below the resolution."""
    from hostpc.kinds.sphere_probe.planning.contacts import step_fractions

    steps = step_fractions(0.69, coarse_steps=40, resolution=2e-5)
    assert steps[:28] == [k / 40 for k in range(1, 29)]  # 28/40 = 0.7 first reads high
    bisection = steps[28:]
    assert len(bisection) == 11  # 0.025 / 2^11 < 2e-5 <= 0.025 / 2^10
    below = max([27 / 40] + [s for s in bisection if s < 0.69])
    above = min([28 / 40] + [s for s in bisection if s >= 0.69])
    assert above - below <= 2e-5
    assert step_fractions(1.5, coarse_steps=40) == [k / 40 for k in range(1, 41)]  # no contact
