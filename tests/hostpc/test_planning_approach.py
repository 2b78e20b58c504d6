"""hostpc.planning.approach: every joint reached from both sides when the model has an
approach-dependent effect (backlash), and nothing changed when it has none."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hostpc.kinds.sphere_probe.planning.contacts import (
    ProbePlan,
    balance_probe_plan,
    plan_sphere_probe,
    tip_positions,
)
from hostpc.kinds.sphere_probe.planning.setup import PlanConfig, ProbeSetup
from hostpc.kinematics import forward, get_robot
from hostpc.model.measurements.registry import measurement_models
from hostpc.model.problem import build_problem
from hostpc.model.registry import builtin_effects
from hostpc.planning.approach import (
    MAX_TURN,
    ApproachTally,
    approach_after,
    approach_dependent_effects,
    balance_guarded_moves,
    reversed_target,
    travel_signs,
    unbalanced_joints,
    via_point,
)
from tests.support import sphere_dataset

WRIST_DOWN = np.array([0.0, -1.9, 1.9, -1.6, -1.5708, 0.0])


@pytest.fixture(scope="module")
def probe() -> tuple[ProbePlan, ProbeSetup]:
    setup = ProbeSetup(sphere_centre=np.array([0.45, -0.15, 0.05]), sphere_radius=0.0125,
                       stylus_radius=0.0015, tip=np.array([0.0, 0.0, 0.12]))
    plan = plan_sphere_probe(get_robot("ur5e"), setup, PlanConfig(n_orientations=12),
                             WRIST_DOWN)
    return plan, setup


@pytest.mark.parametrize(("spec", "expected"), [
    (None, []), ("+trigger_latency", []), ("+backlash", ["backlash"]),
    ("joint_offsets,backlash", ["backlash"]), ("-backlash", []),
    (["joint_offsets", "+backlash"], ["backlash"]), ("+no_such_effect", []),
])
def test_the_approach_dependent_effects_of_a_model_spec(spec: object,
                                                         expected: list[str]) -> None:
    assert approach_dependent_effects(spec) == expected  # type: ignore[arg-type]


def test_signs_and_balance() -> None:
    signs = travel_signs(np.zeros((4, 3)), np.array([[1, 0, -1], [1, -1, -1], [1, -1, 1],
                                                      [-1, 1, -1]], dtype=float))
    np.testing.assert_array_equal(signs[0], [1, 1, -1])  # not moving counts as +
    np.testing.assert_array_equal(unbalanced_joints(signs), [True, False, True])


def test_a_reversed_guarded_move_ends_at_the_same_tip(probe: tuple[ProbePlan, ProbeSetup]
                                                      ) -> None:
    plan, setup = probe
    chain = get_robot("ur5e")
    contacts = plan.contacts
    q_start = np.array([c.q_start for c in contacts])
    q_target = np.array([c.q_target for c in contacts])
    assert np.all(travel_signs(q_start, q_target)[:, 3] < 0)  # joint 4: one way only
    reversed_q = reversed_target(chain, q_start[0], q_target[0], setup.tip, [3])
    assert reversed_q is not None
    assert travel_signs(q_start[:1], reversed_q[None])[0, 3] > 0
    np.testing.assert_allclose(tip_positions(chain, reversed_q, setup.tip),
                               tip_positions(chain, q_target[0], setup.tip), atol=1e-6)
    R = forward(chain, np.stack([q_target[0], reversed_q])).T_base_flange[:, :3, :3]
    assert np.arccos(np.clip((np.trace(R[0].T @ R[1]) - 1) / 2, -1, 1)) <= MAX_TURN

    balanced = balance_guarded_moves(chain, q_start, q_target, setup.tip)
    share = np.mean(travel_signs(q_start, balanced) > 0, axis=0)
    assert 0.3 < share[3] < 0.7
    np.testing.assert_allclose(tip_positions(chain, balanced, setup.tip),
                               tip_positions(chain, q_target, setup.tip), atol=1e-6)


def test_the_plan_changes_only_with_an_approach_dependent_effect(
        probe: tuple[ProbePlan, ProbeSetup]) -> None:
    plan, setup = probe
    chain = get_robot("ur5e")
    assert balance_probe_plan(plan, chain, setup.tip, "+trigger_latency") is plan
    assert balance_probe_plan(plan, chain, setup.tip, None) is plan
    balanced = balance_probe_plan(plan, chain, setup.tip, "+trigger_latency,+backlash")
    assert len(balanced.contacts) == len(plan.contacts)
    for old, new in zip(plan.contacts, balanced.contacts, strict=True):
        assert (old.group, old.index, old.speed) == (new.group, new.index, new.speed)
        np.testing.assert_array_equal(old.q_start, new.q_start)
    assert sum(not np.array_equal(o.q_target, n.q_target)
               for o, n in zip(plan.contacts, balanced.contacts, strict=True)) > 10


def run_tour(q: np.ndarray, joints: np.ndarray | None = None
             ) -> tuple[np.ndarray, int]:
    """The recorded approach signs (N, n) of free moves through q (N, n) in order, balanced
    online with via-points as the stereo_target method does; and how many via-points."""
    tally = ApproachTally.empty(q.shape[1])
    q_from: np.ndarray | None = None
    signs, vias = [], 0
    for pose in q:
        via = via_point(tally, q_from, pose, joints)
        vias += via is not None
        recorded = approach_after(q_from, via, pose)
        tally = tally.add(recorded)
        signs.append(recorded)
        q_from = pose
    return np.array(signs), vias


def test_via_points_bring_a_one_way_joint_in_from_both_sides() -> None:
    q = np.zeros((40, 3))
    q[:, 0] = np.linspace(0.0, 0.9, 40)  # joint 1 always moves in +
    q[:, 1] = np.tile([0.2, -0.2], 20)   # joints 2 and 3 alternate: balanced already
    q[:, 2] = np.tile([-0.1, 0.1], 20)
    plain = travel_signs(np.vstack([q[:1], q[:-1]]), q)
    assert unbalanced_joints(plain).tolist() == [True, False, False]
    signs, vias = run_tour(q)
    share = np.mean(signs > 0, axis=0)
    assert 0.4 <= share[0] <= 0.6 and 10 <= vias <= 25
    np.testing.assert_allclose(share[1:], np.mean(plain[:, 1:] > 0, axis=0), atol=0.05)
    _, vias = run_tour(q, joints=np.array([False, True, True]))  # joint 1 not asked for
    assert vias == 0


def test_a_via_point_goes_past_the_pose_and_keeps_to_the_limits() -> None:
    tally = ApproachTally.empty(2)
    for _ in range(8):
        tally = tally.add(np.array([1.0, -1.0]))
    assert tally.flagged.tolist() == [True, True]
    q_from, q = np.array([0.0, 0.5]), np.array([0.3, 0.2])  # joint 1 +, joint 2 -
    via = via_point(tally, q_from, q, step=0.05)
    assert via is not None
    np.testing.assert_allclose(via, [0.35, 0.15])
    np.testing.assert_array_equal(approach_after(q_from, via, q), [-1.0, 1.0])
    limited = via_point(tally, q_from, q, step=0.05, q_min=np.array([-1.0, 0.18]),
                        q_max=np.array([0.32, 1.0]))
    assert limited is None  # both would leave the limits: move directly
    assert via_point(ApproachTally.empty(2), q_from, q) is None


def test_a_balanced_random_tour_gets_no_via_point() -> None:
    rng = np.random.default_rng(4)
    q = rng.uniform(-1.0, 1.0, (60, 6))
    _, vias = run_tour(q)
    assert vias == 0


@pytest.mark.parametrize("name", sorted(builtin_effects()))
def test_an_effect_declares_approach_dependent_exactly_when_it_reads_approach(
        name: str, noisy_stereo) -> None:  # type: ignore[no-untyped-def]
    cls = builtin_effects()[name]
    if cls.hook not in ("joint", "geometry", "sensor"):
        return
    methods = [name for name, model in measurement_models().items() if model.accepts(cls)]
    dataset = noisy_stereo.dataset if "stereo_target" in methods else sphere_dataset()
    ctx = build_problem(dataset, ["joint_offsets"]).context
    rng = np.random.default_rng(1)
    signs = np.where(rng.uniform(size=ctx.q_cmd.shape) < 0.5, -1.0, 1.0)
    effect = cls()
    p = rng.uniform(-1e-3, 1e-3, len(effect.parameter_names(ctx)))
    y = rng.uniform(0.1, 0.5, (ctx.n_samples, 3 if ctx.method == "stereo_target" else 1))

    def output(approach: np.ndarray) -> np.ndarray:
        view = replace(ctx, approach=approach)
        if cls.hook == "joint":
            return np.asarray(effect.joint_delta(view, p))
        if cls.hook == "geometry":
            return np.asarray(effect.kinematic_delta(view, p))
        return np.asarray(effect.sensor_apply(view, p, y))

    reads_approach = not np.allclose(output(signs), output(-signs), rtol=0.0, atol=0.0)
    assert cls.approach_dependent == reads_approach
