"""Prismatic joints and URDF robots: forward kinematics against an independent product of
URDF transforms, screws against finite differences, gravity against the potential energy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hostpc.errors import InputError
from hostpc.kinematics import (
    chain_from_table,
    forward,
    gravity_torque,
    point_jacobian,
    rotation_jacobian,
    screws,
)
from hostpc.kinematics.urdf import chain_from_urdf, load_urdf_chain, parse_urdf
from hostpc.model import joint_offsets

URDF = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"


def _urdf_fk(q: np.ndarray) -> np.ndarray:
    """T_base_tool0 as the plain product of URDF transforms (origin, then joint motion)."""
    robot = parse_urdf(URDF.read_text())
    order = ["base_mount", "lift", "joint1", "joint2", "joint3", "joint4", "joint5", "joint6",
             "flange_joint", "tool0_joint"]
    T = np.eye(4)
    k = 0
    for name in order:
        joint = robot.joints[name]
        motion = np.eye(4)
        if joint.type == "prismatic":
            motion[:3, 3] = joint.axis * q[k]
        elif joint.type in ("revolute", "continuous"):
            motion[:3, :3] = Rotation.from_rotvec(joint.axis * q[k]).as_matrix()
        if joint.type != "fixed":
            k += 1
        T = T @ joint.origin @ motion
    return T


@pytest.fixture(scope="module")
def arm7():
    return load_urdf_chain(URDF, "base_link", "tool0")


def _random_q(chain, rng, count):
    low = np.maximum(chain.q_min, -2.5)
    high = np.minimum(chain.q_max, 2.5)
    return rng.uniform(low, high, size=(count, chain.n))


def test_urdf_chain_matches_the_product_of_urdf_transforms(arm7):
    assert arm7.n == 7
    assert list(arm7.joint_is_prismatic) == [True] + [False] * 6
    assert joint_offsets.units(arm7) == ("m",) + ("rad",) * 6
    rng = np.random.default_rng(3)
    q = _random_q(arm7, rng, 25)
    T = forward(arm7, q).T_base_flange
    for k in range(len(q)):
        np.testing.assert_allclose(T[k], _urdf_fk(q[k]), atol=1e-12)


def test_urdf_mass_model_merges_fixed_links(arm7):
    # wrist3 has no inertial: the flange (0.3 kg) is fixed to it; camera_link (0.5 kg) is
    # fixed to wrist2 off the chain and is carried by joint 5's body
    np.testing.assert_allclose(arm7.mass, [6.0, 4.0, 8.0, 3.5, 1.2, 1.5, 0.3])


def test_urdf_limits_and_parallel_axes(arm7):
    assert arm7.q_min[0] == 0.0 and arm7.q_max[0] == 0.5
    assert arm7.hayati[3]  # joints 2 and 3 are parallel: row 4's Hayati beta (MDH)


def _fd_check(chain, q, rng):
    """Point and rotation Jacobians of every kinematic parameter against central
    differences of forward kinematics."""
    m = 5 * chain.n
    base = rng.normal(scale=1e-3, size=m)
    poses = forward(chain, q, base)
    T = poses.T_base_flange
    tip = T[:, :3, :3] @ np.array([0.03, -0.02, 0.05]) + T[:, :3, 3]
    S = screws(chain, poses)
    J_point = point_jacobian(S, tip)
    J_rot = rotation_jacobian(S)
    h = 1e-6
    for k in range(m):
        step = np.zeros(m)
        step[k] = h
        Tp = forward(chain, q, base + step).T_base_flange
        Tm = forward(chain, q, base - step).T_base_flange
        tp = Tp[:, :3, :3] @ np.array([0.03, -0.02, 0.05]) + Tp[:, :3, 3]
        tm = Tm[:, :3, :3] @ np.array([0.03, -0.02, 0.05]) + Tm[:, :3, 3]
        np.testing.assert_allclose(J_point[:, :, k], (tp - tm) / (2 * h), atol=1e-8)
        dR = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h) @ np.swapaxes(T[:, :3, :3], 1, 2)
        w = np.stack([dR[:, 2, 1], dR[:, 0, 2], dR[:, 1, 0]], axis=1)
        np.testing.assert_allclose(J_rot[:, :, k], w, atol=1e-8)


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_prismatic_table_screws_match_finite_differences(convention):
    chain = chain_from_table(
        "slide3", convention, a=[0.1, 0.3, 0.05, 0.0], alpha=[np.pi / 2, 0.0, 0.3, -1.2],
        d=[0.2, 0.1, 0.0, 0.1], theta=[0.0, 0.4, 0.0, 0.1],
        joint_types=["revolute", "prismatic", "revolute", "prismatic"],
    )
    rng = np.random.default_rng(5)
    _fd_check(chain, rng.uniform(-1, 1, size=(6, 4)), rng)


def test_urdf_screws_match_finite_differences(arm7):
    rng = np.random.default_rng(7)
    _fd_check(arm7, _random_q(arm7, rng, 5), rng)


def test_prismatic_joint_adds_to_d():
    revolute = chain_from_table("r", "dh", a=[0.1, 0.2], alpha=[0.3, 0.0], d=[0.25, 0.0],
                                theta=[0.2, 0.0])
    slide = chain_from_table("p", "dh", a=[0.1, 0.2], alpha=[0.3, 0.0], d=[0.0, 0.0],
                             theta=[0.2, 0.0], joint_types=["prismatic", "revolute"])
    q2 = 0.7
    np.testing.assert_allclose(forward(slide, [[0.25, q2]]).T_base_flange,
                               forward(revolute, [[0.0, q2]]).T_base_flange, atol=1e-14)


def test_gravity_torque_is_minus_the_gradient_of_potential_energy(arm7):
    rng = np.random.default_rng(11)
    q = _random_q(arm7, rng, 4)

    def potential(qq):
        T = forward(arm7, qq).T_base_link[:, 1:]
        c = np.einsum("nkij,kj->nki", T[..., :3, :3], arm7.com) + T[..., :3, 3]
        return 9.81 * np.einsum("k,nk->n", arm7.mass, c[..., 2])

    tau = gravity_torque(arm7, q)
    h = 1e-6
    for j in range(arm7.n):
        step = np.zeros(arm7.n)
        step[j] = h
        np.testing.assert_allclose(tau[:, j], -(potential(q + step) - potential(q - step))
                                   / (2 * h), atol=1e-6)
    # the lift carries every moving mass: its force is -M g along +z
    np.testing.assert_allclose(tau[:, 0], -9.81 * arm7.mass.sum(), rtol=1e-12)


@pytest.mark.parametrize(("text", "message"), [
    ("<robot", "not valid XML"),
    ("<model/>", "expected <robot>"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="planar"><parent link="a"/>'
     '<child link="b"/></joint></robot>', "only revolute"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a"/>'
     '<child link="b"/><origin xyz="0 x 0"/></joint></robot>', "origin xyz"),
    ('<robot><link name="a"/><link name="b"/><link name="c"/><joint name="j" type="revolute">'
     '<parent link="a"/><child link="b"/></joint></robot>', "does not hang from"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a"/>'
     '<child link="b"/><axis xyz="0 0 0"/></joint></robot>', "zero vector"),
    ('<robot><link name="a"/><link name="b"/><link name="c"/>'
     '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/></joint>'
     '<joint name="j2" type="revolute"><parent link="b"/><child link="c"/></joint>'
     '<joint name="j3" type="revolute"><parent link="c"/><child link="b"/></joint></robot>',
     "child of two joints"),
    ('<robot><link name="a"/><link name="b"/><link name="c"/>'
     '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/></joint>'
     '<joint name="j2" type="revolute"><parent link="c"/><child link="c"/></joint></robot>',
     "to itself"),
    ('<robot><link name="a"/><link name="b"/><link name="c"/><link name="d"/>'
     '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/></joint>'
     '<joint name="j2" type="revolute"><parent link="c"/><child link="d"/></joint>'
     '<joint name="j3" type="revolute"><parent link="d"/><child link="c"/></joint></robot>',
     "form a loop"),
    ('<robot><link name="a"/><link name="b"/>'
     '<joint name="j" type="revolute"><parent link="a"/><child link="ghost"/></joint></robot>',
     "not a declared"),
    ('<robot><link name="a"/><link name="b"/><link name="a"/></robot>', "declared twice"),
])
def test_broken_urdf_gets_one_clear_error(text, message):
    with pytest.raises(InputError, match=message):
        tip = "c" if "link name=\"c\"" in text else "b"
        chain_from_urdf(parse_urdf(text, "x.urdf"), "a", tip, "x.urdf")


def test_unknown_link_and_missing_file_are_named(tmp_path):
    with pytest.raises(InputError, match="tip_link 'nope'"):
        load_urdf_chain(URDF, "base_link", "nope")
    with pytest.raises(InputError, match="cannot read URDF"):
        load_urdf_chain(tmp_path / "missing.urdf", "a", "b")
