"""The joint offset's one owner (hostpc.model.joint_offsets): names <-> controller joints."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.errors import InputError
from hostpc.kinematics import get_robot
from hostpc.model import joint_offsets
from hostpc.model.joint_offsets import JointOffsetName, PushTable


def test_serial_names_round_trip_through_the_push_table() -> None:
    table = PushTable.for_controller(6)
    assert table.names == tuple(f"joint_offsets.q{j}" for j in range(1, 7))
    assert table.labels == ("q1", "q2", "q3", "q4", "q5", "q6")
    for j, name in enumerate(table.names):
        assert table.index(name) == j
        parsed = joint_offsets.parse(name)
        assert parsed == JointOffsetName("", j + 1)
        assert parsed.name == name and parsed.label == table.labels[j]
        assert joint_offsets.offset_name(joint_offsets.label(name)) == name
    assert table.values({"joint_offsets.q2": 0.01, "tool.x": 1.0}) == [0, 0.01, 0, 0, 0, 0]


def test_labelled_joints_of_a_kinematic_tree() -> None:
    labels = ("head.q1", "head.q2", "left.q1", "left.q2", "right.q1")
    table = PushTable.for_controller(5, labels)
    assert table.names[3] == "joint_offsets.left.q2"
    assert table.labels == labels
    assert table.index("joint_offsets.right.q1") == 4
    parsed = joint_offsets.parse("joint_offsets.left.q2")
    assert (parsed.chain, parsed.joint, parsed.branch) == ("left", 2, "left.")
    assert joint_offsets.chain_prefix("left") == "joint_offsets.left."
    assert all(name.startswith(joint_offsets.chain_prefix("head")) for name in table.names[:2])
    # labels that do not match the controller's joint count fall back to q1..qn
    assert PushTable.for_controller(2, labels).labels == ("q1", "q2")


def test_offsets_among_other_parameters() -> None:
    names = ["tool.x", "joint_offsets.q1", "geometry.a2", "joint_offsets.q2", "target.z"]
    assert [joint_offsets.is_offset(n) for n in names] == [False, True, False, True, False]
    assert joint_offsets.labels(names) == ["q1", "q2"]
    assert joint_offsets.match("geometry.a2") is None
    assert joint_offsets.match("joint_compliance.c2") is None


@pytest.mark.parametrize("bad", ["tool.x", "joint_offsets", "joint_offsets.x1",
                                 "joint_offsets.left.", "joint_compliance.q1"])
def test_a_bad_name_gives_one_clear_error(bad: str) -> None:
    with pytest.raises(InputError, match="is not a joint offset parameter") as error:
        joint_offsets.parse(bad)
    assert repr(bad) in str(error.value)


def test_a_name_the_controller_has_not() -> None:
    table = PushTable.for_controller(6)
    with pytest.raises(InputError, match=r"'joint_offsets.q7' is not an offset of this "):
        table.index("joint_offsets.q7")
    with pytest.raises(InputError, match="is not a joint offset parameter"):
        table.index("tool.x")
    with pytest.raises(InputError, match="is not a joint offset parameter"):
        joint_offsets.label("tool.x")


def test_an_offset_has_its_joints_unit() -> None:
    # radians for a revolute joint, metres for a prismatic one (shown as deg / mm)
    assert joint_offsets.unit(False) == joint_offsets.ANGLE_UNIT == "rad"
    assert joint_offsets.unit(True) == joint_offsets.LENGTH_UNIT == "m"
    assert joint_offsets.units(get_robot("ur5e")) == ("rad",) * 6


def test_the_effect_names_its_parameters_as_the_owner_does() -> None:
    from hostpc.model import build_problem
    from hostpc.synthesize import random_truth, synthesize_stereo_target

    truth = random_truth(np.random.default_rng(1))
    dataset = synthesize_stereo_target(truth, n_samples=8, seed=1).dataset
    problem = build_problem(dataset, joint_offsets.EFFECT)
    assert list(problem.layout.names) == list(PushTable.for_controller(6).names)
