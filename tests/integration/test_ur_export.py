"""UR / ROS exports of fitted joint offsets load with standard parsers and carry the values.

The corrected origins must reproduce the chain's own forward kinematics at the true angles
(q_reported + offset) when ROS evaluates them at the reported angles.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from hostpc.errors import InputError
from hostpc.kinematics import forward
from hostpc.kinematics.robots import get_robot
from hostpc.kinematics.rotations import rot_z
from hostpc.robots.ur_export import (
    UR_KINEMATICS_KEYS,
    JointOrigin,
    joint_origins,
    kinematics_yaml,
    urdf_snippet,
    write_exports,
)

OFFSETS = np.array([0.0021, -0.0013, 0.0008, -0.0035, 0.0017, 0.0])


def _urdf_flange(origins: list[JointOrigin], flange: JointOrigin, q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for origin, angle in zip(origins, q, strict=True):
        Rz = np.eye(4)
        Rz[:3, :3] = rot_z(angle)
        T = T @ origin.matrix() @ Rz
    return T @ flange.matrix()


@pytest.mark.parametrize("robot", ["ur5e", "ur10e"])
def test_origins_reproduce_the_chain_at_the_true_angles(robot: str) -> None:
    chain = get_robot(robot)
    q = np.random.default_rng(1).uniform(-2.0, 2.0, (5, 6))
    origins, flange = joint_origins(chain, OFFSETS)
    T_true = forward(chain, q + OFFSETS).T_base_link[:, -1]
    for k in range(q.shape[0]):
        np.testing.assert_allclose(_urdf_flange(origins, flange, q[k]), T_true[k], atol=1e-12)


def test_nominal_ur5e_matches_ur_description() -> None:
    document = yaml.safe_load(kinematics_yaml(get_robot("ur5e"), np.zeros(6)))
    kin = document["kinematics"]
    assert list(kin)[:6] == list(UR_KINEMATICS_KEYS)
    assert kin["shoulder"]["z"] == pytest.approx(0.1625)
    assert kin["upper_arm"]["roll"] == pytest.approx(np.pi / 2)
    assert kin["forearm"]["x"] == pytest.approx(-0.425)
    assert kin["wrist_1"]["x"] == pytest.approx(-0.3922)
    assert kin["wrist_1"]["z"] == pytest.approx(0.1333)
    assert kin["wrist_2"]["y"] == pytest.approx(-0.0997)
    assert kin["wrist_3"]["y"] == pytest.approx(0.0996)


def test_exported_files_parse_and_carry_the_offsets(tmp_path: Path) -> None:
    chain = get_robot("ur5e")
    paths = write_exports(tmp_path, chain, OFFSETS)

    kin = yaml.safe_load(paths["yaml"].read_text())["kinematics"]
    assert kin["hash"].startswith("calib_")
    nominal = yaml.safe_load(kinematics_yaml(chain, np.zeros(6)))["kinematics"]
    # joint 1's origin has no rotation: its yaw is the offset itself
    assert kin["shoulder"]["yaw"] == pytest.approx(OFFSETS[0], abs=1e-12)
    for key, offset in zip(UR_KINEMATICS_KEYS, OFFSETS, strict=True):
        R_nominal = JointOrigin(np.zeros(3), np.array(
            [nominal[key]["roll"], nominal[key]["pitch"], nominal[key]["yaw"]])).matrix()[:3, :3]
        R = JointOrigin(np.zeros(3), np.array(
            [kin[key]["roll"], kin[key]["pitch"], kin[key]["yaw"]])).matrix()[:3, :3]
        np.testing.assert_allclose(R, R_nominal @ rot_z(offset), atol=1e-12)
        assert [kin[key][a] for a in "xyz"] == pytest.approx([nominal[key][a] for a in "xyz"])

    root = ET.parse(paths["urdf"]).getroot()
    joints = root.findall("joint")
    assert [j.get("name") for j in joints] == [
        "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
        "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
    ]
    for joint, key in zip(joints, UR_KINEMATICS_KEYS, strict=True):
        origin = joint.find("origin")
        assert origin is not None
        xyz = [float(v) for v in origin.get("xyz", "").split()]
        rpy = [float(v) for v in origin.get("rpy", "").split()]
        assert xyz == pytest.approx([kin[key][a] for a in "xyz"], abs=1e-12)
        assert rpy == pytest.approx([kin[key][a] for a in ("roll", "pitch", "yaw")], abs=1e-12)
    assert "zerocal_offsets = [0.0021, -0.0013" in paths["urscript"].read_text()


def test_prefix_and_bad_input() -> None:
    chain = get_robot("ur5e")
    root = ET.fromstring(urdf_snippet(chain, OFFSETS, prefix="left_"))
    assert root.find("joint").get("name") == "left_shoulder_pan_joint"  # type: ignore[union-attr]
    with pytest.raises(InputError, match="joint_offsets"):
        kinematics_yaml(chain, [0.0] * 5)
    with pytest.raises(InputError):
        kinematics_yaml(chain, [np.nan] * 6)
