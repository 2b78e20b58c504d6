"""Forward kinematics, screws and Jacobians of hostpc.kinematics.

Golden values come from sources independent of the code under test: flange poses derived by
hand from the published DH tables (derivations in the comments), and a product-of-
exponentials model written here from the joint axes read off the robot at q = 0, evaluated
with scipy's matrix exponential. Every Jacobian is checked against central differences of
forward().
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hostpc.errors import InputError
from hostpc.kinematics import (
    KIN_KINDS,
    Chain,
    chain_from_table,
    forward,
    get_robot,
    kin_index,
    point_jacobian,
    rotation_jacobian,
    screws,
)

# UR published DH tables (universal-robots.com, "DH Parameters for calculations of
# kinematics and dynamics"), copied here so the golden values do not come from robots.py.
UR_TABLES = {
    "ur5e": dict(d1=0.1625, a2=-0.425, a3=-0.3922, d4=0.1333, d5=0.0997, d6=0.0996),
    "ur10e": dict(d1=0.1807, a2=-0.6127, a3=-0.57155, d4=0.17415, d5=0.11985, d6=0.11655),
}


def ur_golden(name: str) -> list[tuple[list[float], np.ndarray]]:
    """Hand-derived UR flange poses ``(q, T_base_flange)``.

    q = 0 (DH: alpha = [90, 0, 0, 90, -90, 0] deg): z1 = Rx(90) z = -y0, so joints 2..4
    turn about -y0 and x1 = x2 = x3 = x0: the upper arm and forearm lie along x0 and the
    wrist-1 origin is at (a2 + a3, 0, d1). d4 runs along z3 = -y0. z4 = R3 Rx(90) z = -y3
    = -z0, so d5 runs down; z5 = y4 = -y0, so d6 runs along -y0. The flange frame is
    R5 = Rx(90) Rx(90) Rx(-90) = Rx(90): x = x0, y = z0, z = -y0.
        p = (a2 + a3, -(d4 + d6), d1 - d5)

    q1 = 90 deg turns all of it about z0: (x, y) -> (-y, x), R -> Rz(90) R.

    q2 = -90 deg turns everything outboard of joint 2 by -90 deg about -y0 through
    (0, 0, d1), i.e. +90 deg about +y0 (x -> -z, z -> x): the flange offset from the
    shoulder (a2 + a3, -(d4 + d6), -d5) becomes (-d5, -(d4 + d6), -(a2 + a3)).

    q5 = 90 deg turns the wrist about z4 = -z0 through o4 = (a2 + a3, -d4, d1), i.e.
    -90 deg about +z0 ((x, y) -> (y, -x)): the flange offset (0, -d6, -d5) from o4 becomes
    (-d6, 0, -d5).
    """
    p = UR_TABLES[name]
    d1, a2, a3, d4, d5, d6 = (p[k] for k in ("d1", "a2", "a3", "d4", "d5", "d6"))
    R0 = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    Rz90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    Ry90 = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    cases = [
        ([0, 0, 0, 0, 0, 0], R0, [a2 + a3, -(d4 + d6), d1 - d5]),
        ([np.pi / 2, 0, 0, 0, 0, 0], Rz90 @ R0, [d4 + d6, a2 + a3, d1 - d5]),
        ([0, -np.pi / 2, 0, 0, 0, 0], Ry90 @ R0, [-d5, -(d4 + d6), d1 - (a2 + a3)]),
        ([0, 0, 0, 0, np.pi / 2, 0], Rz90.T @ R0, [a2 + a3 - d6, -d4, d1 - d5]),
    ]
    out = []
    for q, R, t in cases:
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = t
        out.append((q, T))
    return out


@pytest.mark.parametrize("name", ["ur5e", "ur10e"])
def test_ur_flange_matches_hand_derivation(name: str) -> None:
    chain = get_robot(name)
    for q, T_expected in ur_golden(name):
        T = forward(chain, np.array([q], dtype=float)).T_base_flange[0]
        np.testing.assert_allclose(T, T_expected, atol=1e-12, err_msg=f"q = {q}")


def test_industrial6_flange_at_zero_matches_hand_derivation() -> None:
    # Craig MDH, PUMA 560 (AKB): frame 2 = Rx(-90) Tz(0.2435): z2 = +y0, o2 = (0, .2435, 0);
    # frame 3 = Tx(0.4318) Tz(-0.0934) in frame 2: o3 = (0.4318, 0.1501, 0);
    # frame 4 = Rx(90) Tx(-0.0203) Tz(0.4331): z4 = z0, o4 = (0.4115, 0.1501, 0.4331);
    # frames 5, 6 only twist (-90, +90): R6 = Rx(-90) Rx(90) Rx(-90) Rx(90) = I.
    T = forward(get_robot("industrial6"), np.zeros((1, 6))).T_base_flange[0]
    expected = np.eye(4)
    expected[:3, 3] = [0.4318 - 0.0203, 0.2435 - 0.0934, 0.4331]
    np.testing.assert_allclose(T, expected, atol=1e-12)


def _poe_model(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Space-frame joint axes, points on them and the home pose M, read off at q = 0."""
    if name == "industrial6":
        o3 = [0.4318, 0.1501, 0.0]
        o4 = [0.4115, 0.1501, 0.4331]
        axes = [[0, 0, 1], [0, 1, 0], [0, 1, 0], [0, 0, 1], [0, 1, 0], [0, 0, 1]]
        points = [[0, 0, 0], [0, 0.2435, 0], o3, o4, o4, o4]
        M = np.eye(4)
        M[:3, 3] = o4
        return np.array(axes, float), np.array(points, float), M
    p = UR_TABLES[name]
    d1, a2, a3, d4, d5 = p["d1"], p["a2"], p["a3"], p["d4"], p["d5"]
    axes = [[0, 0, 1], [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, 0, -1], [0, -1, 0]]
    points = [
        [0, 0, 0],
        [0, 0, d1],
        [a2, 0, d1],
        [a2 + a3, 0, d1],
        [a2 + a3, -d4, d1],
        [a2 + a3, -d4, d1 - d5],
    ]
    return np.array(axes, float), np.array(points, float), ur_golden(name)[0][1]


def _poe_forward(name: str, q: np.ndarray) -> np.ndarray:
    """T_base_flange = prod_i expm([S_i] q_i) @ M, with S_i = (w_i, -w_i x p_i)."""
    axes, points, M = _poe_model(name)
    T = np.eye(4)
    for w, p, angle in zip(axes, points, q, strict=True):
        twist = np.zeros((4, 4))
        twist[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
        twist[:3, 3] = -np.cross(w, p)
        T = T @ scipy.linalg.expm(twist * angle)
    return T @ M


@pytest.mark.parametrize("name", ["ur5e", "ur10e", "industrial6"])
def test_forward_matches_product_of_exponentials(name: str) -> None:
    rng = np.random.default_rng(7)
    q = rng.uniform(-np.pi, np.pi, size=(20, 6))
    T = forward(get_robot(name), q).T_base_flange
    expected = np.array([_poe_forward(name, qi) for qi in q])
    np.testing.assert_allclose(T, expected, atol=1e-12)


def test_forward_frames_and_shapes() -> None:
    chain = get_robot("ur5e")
    q = np.random.default_rng(0).normal(size=(4, 6))
    poses = forward(chain, q)
    T = poses.T_base_link
    assert T.shape == (4, 7, 4, 4)
    np.testing.assert_allclose(T[:, 0], np.broadcast_to(np.eye(4), (4, 4, 4)))
    np.testing.assert_array_equal(poses.T_base_flange, T[:, 6])
    np.testing.assert_allclose(T[:, :, 3], np.broadcast_to([0, 0, 0, 1.0], (4, 7, 4)))
    R = T[..., :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)


def _row_transform(convention: str, a: float, alpha: float, d: float, theta: float,
                   beta: float) -> np.ndarray:
    """One joint transform from elementary matrices, straight from conventions.md."""
    def rot(axis: int, angle: float) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        T = np.eye(4)
        T[i, i] = T[j, j] = c
        T[i, j], T[j, i] = -s, s
        return T

    def trans(axis: int, length: float) -> np.ndarray:
        T = np.eye(4)
        T[axis, 3] = length
        return T

    if convention == "dh":
        return rot(2, theta) @ trans(2, d) @ trans(0, a) @ rot(0, alpha) @ rot(1, beta)
    return rot(0, alpha) @ rot(1, beta) @ trans(0, a) @ rot(2, theta) @ trans(2, d)


@pytest.mark.parametrize("name", ["ur5e", "industrial6"])
def test_forward_with_kin_delta_matches_elementary_product(name: str) -> None:
    chain = get_robot(name)
    rng = np.random.default_rng(3)
    N, n = 5, chain.n
    q = rng.uniform(-np.pi, np.pi, size=(N, n))
    for kin_delta in (rng.normal(scale=0.05, size=5 * n), rng.normal(scale=0.05, size=(N, 5 * n))):
        T = forward(chain, q, kin_delta).T_base_link
        delta = np.broadcast_to(kin_delta, (N, 5 * n))
        for k in range(N):
            rows = chain.kin_vector() + delta[k]
            theta, d, a, alpha, beta = rows.reshape(5, n)
            expected = np.eye(4)
            for i in range(n):
                expected = expected @ _row_transform(
                    chain.convention, a[i], alpha[i], d[i], theta[i] + q[k, i], beta[i]
                )
                np.testing.assert_allclose(T[k, i + 1], expected, atol=1e-12)


def test_forward_kin_delta_forms_agree() -> None:
    """(5n,), (N, 5n) with only theta varying, and fully per-pose deltas agree."""
    chain = get_robot("ur10e")
    rng = np.random.default_rng(4)
    q = rng.normal(size=(6, 6))
    shared = rng.normal(scale=0.02, size=30)
    tiled = np.tile(shared, (6, 1))
    T_shared = forward(chain, q, shared).T_base_link
    np.testing.assert_allclose(forward(chain, q, tiled).T_base_link, T_shared, atol=1e-15)
    joint = tiled.copy()
    joint[:, :6] += rng.normal(scale=0.02, size=(6, 6))
    T_joint = forward(chain, q, joint).T_base_link
    np.testing.assert_allclose(T_joint, forward(chain, q + joint[:, :6] - shared[:6], shared)
                               .T_base_link, atol=1e-14)
    general = joint.copy()
    general[3, 20] += 1e-3  # one alpha differs in one pose -> general path
    T_general = forward(chain, q, general).T_base_link
    np.testing.assert_allclose(np.delete(T_general, 3, axis=0), np.delete(T_joint, 3, axis=0),
                               atol=1e-14)
    assert not np.allclose(T_general[3, -1], T_joint[3, -1], atol=1e-6)


# --- Jacobians against central differences ------------------------------------------------

joint_vectors = arrays(np.float64, (6,), elements=st.floats(-np.pi, np.pi))
kin_deltas = arrays(np.float64, (30,), elements=st.floats(-0.05, 0.05))
H = 1e-6
TOOL_POINT = np.array([0.03, -0.05, 0.12, 1.0])  # a point fixed to the flange (flange frame)


def _central_differences(chain: Chain, q: np.ndarray, kin_delta: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """d(tool point)/d(kin param) (3, 5n) and angular velocity per param (3, 5n)."""
    m = 5 * chain.n
    steps = np.eye(m) * H
    deltas = np.concatenate([kin_delta + steps, kin_delta - steps])  # (2m, 5n)
    T = forward(chain, np.tile(q, (2 * m, 1)), deltas).T_base_flange
    x = T @ TOOL_POINT
    dx = (x[:m, :3] - x[m:, :3]).T / (2 * H)
    R0 = forward(chain, q[None], kin_delta[None]).T_base_flange[0, :3, :3]
    dR = (T[:m, :3, :3] - T[m:, :3, :3]) / (2 * H)
    W = dR @ R0.T  # skew(w) per parameter
    w = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]]) / 2
    return dx, w


def _check_jacobians(chain: Chain, q: np.ndarray, kin_delta: np.ndarray) -> None:
    poses = forward(chain, q[None], kin_delta[None])
    kin_screws = screws(chain, poses)
    x = (poses.T_base_flange @ TOOL_POINT)[:, :3]
    J_point = point_jacobian(kin_screws, x)
    J_rot = rotation_jacobian(kin_screws)
    assert J_point.shape == J_rot.shape == (1, 3, 5 * chain.n)
    dx, w = _central_differences(chain, q, kin_delta)
    np.testing.assert_allclose(J_point[0], dx, atol=1e-8)
    np.testing.assert_allclose(J_rot[0], w, atol=1e-8)


@settings(max_examples=30, deadline=None)
@given(q=joint_vectors, kin_delta=kin_deltas)
def test_jacobians_dh_match_central_differences(q: np.ndarray, kin_delta: np.ndarray) -> None:
    _check_jacobians(get_robot("ur5e"), q, kin_delta)


@settings(max_examples=30, deadline=None)
@given(q=joint_vectors, kin_delta=kin_deltas)
def test_jacobians_mdh_match_central_differences(q: np.ndarray, kin_delta: np.ndarray) -> None:
    _check_jacobians(get_robot("industrial6"), q, kin_delta)


@pytest.mark.parametrize("name", ["ur5e", "industrial6"])
def test_jacobians_with_nonzero_nominal_beta_and_theta(name: str) -> None:
    base = get_robot(name)
    chain = Chain(
        name="tilted", convention=base.convention, a=base.a, alpha=base.alpha + 0.02,
        d=base.d, theta=base.theta + 0.3, beta=np.full(6, 0.04), hayati=base.hayati,
        q_min=base.q_min, q_max=base.q_max,
    )
    rng = np.random.default_rng(11)
    for _ in range(3):
        _check_jacobians(chain, rng.uniform(-3, 3, 6), rng.uniform(-0.05, 0.05, 30))


def test_jacobians_vectorised_over_poses() -> None:
    """Per-pose deltas (general path) give each pose its own single-pose Jacobian."""
    chain = get_robot("industrial6")
    rng = np.random.default_rng(5)
    q = rng.uniform(-3, 3, (4, 6))
    kin_delta = rng.uniform(-0.05, 0.05, (4, 30))
    poses = forward(chain, q, kin_delta)
    s = screws(chain, poses)
    x = rng.normal(size=(4, 3))
    J = point_jacobian(s, x)
    W = rotation_jacobian(s)
    for k in range(4):
        sk = screws(chain, forward(chain, q[k : k + 1], kin_delta[k]))
        np.testing.assert_allclose(J[k], point_jacobian(sk, x[k : k + 1])[0], atol=1e-14)
        np.testing.assert_allclose(W[k], rotation_jacobian(sk)[0], atol=1e-14)


def test_theta_jacobian_is_joint_jacobian() -> None:
    chain = get_robot("ur10e")
    q = np.array([[0.3, -1.1, 0.7, -0.4, 1.2, 0.2]])
    poses = forward(chain, q)
    x = poses.T_base_flange[:, :3, 3]
    J = point_jacobian(screws(chain, poses), x)[0, :, :6]
    steps = np.eye(6) * H
    xp = forward(chain, q + steps).T_base_flange[:, :3, 3]
    xm = forward(chain, q - steps).T_base_flange[:, :3, 3]
    np.testing.assert_allclose(J, ((xp - xm) / (2 * H)).T, atol=1e-8)


def test_screw_structure() -> None:
    chain = get_robot("ur5e")
    s = screws(chain, forward(chain, np.random.default_rng(2).normal(size=(3, 6))))
    assert s.axis.shape == s.point.shape == (3, 30, 3)
    np.testing.assert_array_equal(s.is_rotation, [True] * 6 + [False] * 12 + [True] * 12)
    np.testing.assert_allclose(np.linalg.norm(s.axis, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(s.point[:, 6:18], 0.0)
    # translations do not rotate the flange
    np.testing.assert_array_equal(rotation_jacobian(s)[:, :, 6:18], 0.0)


# --- chain data and bad input -------------------------------------------------------------

def test_kin_index_and_vector_layout() -> None:
    chain = get_robot("ur5e")
    assert KIN_KINDS == ("theta", "d", "a", "alpha", "beta")
    assert kin_index("theta", 1, 6) == 0
    assert kin_index("d", 1, 6) == 6
    assert kin_index("alpha", 3, 6) == 20
    assert kin_index("beta", 6, 6) == 29
    vec = chain.kin_vector()
    assert vec.shape == (30,)
    assert vec[kin_index("d", 1, 6)] == pytest.approx(0.1625)
    assert vec[kin_index("a", 2, 6)] == pytest.approx(-0.425)
    assert vec[kin_index("alpha", 5, 6)] == pytest.approx(-np.pi / 2)
    with pytest.raises(InputError, match="^kind:"):
        kin_index("gamma", 1, 6)
    with pytest.raises(InputError, match="^joint:"):
        kin_index("d", 7, 6)
    with pytest.raises(InputError, match="^joint:"):
        kin_index("d", 0, 6)


def test_hayati_flags() -> None:
    np.testing.assert_array_equal(get_robot("ur5e").hayati, [0, 1, 1, 0, 0, 0])
    np.testing.assert_array_equal(get_robot("industrial6").hayati, [0, 0, 1, 0, 0, 0])
    # DH: the last row has no next axis; MDH: the first row twists to the base z axis.
    dh = chain_from_table("t", "dh", a=[1, 1, 1], alpha=[0, np.pi, 0], d=[0] * 3, theta=[0] * 3)
    np.testing.assert_array_equal(dh.hayati, [1, 1, 0])
    mdh = chain_from_table("t", "mdh", a=[0, 1, 1], alpha=[0, np.pi, 0.5], d=[0] * 3,
                           theta=[0] * 3)
    np.testing.assert_array_equal(mdh.hayati, [0, 1, 0])


def _valid_fields() -> dict[str, object]:
    return dict(
        name="r", convention="dh", a=np.zeros(3), alpha=np.zeros(3), d=np.zeros(3),
        theta=np.zeros(3), beta=np.zeros(3), hayati=np.zeros(3, bool), q_min=-np.ones(3),
        q_max=np.ones(3), mass=np.ones(3), com=np.zeros((3, 3)),
    )


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("alpha", np.zeros(4)),
        ("d", np.zeros((3, 1))),
        ("theta", [0.0, 0.0]),
        ("beta", np.zeros(2)),
        ("hayati", np.zeros(2, bool)),
        ("q_min", np.zeros(5)),
        ("q_max", np.zeros(2)),
        ("mass", np.ones(4)),
        ("com", np.zeros((3, 2))),
        ("convention", "xyz"),
        ("a", np.zeros((3, 3))),
        ("d", [0.0, np.nan, 0.0]),
        ("mass", [1.0, -1.0, 1.0]),
        ("q_min", [2.0, 0.0, 0.0]),
    ],
)
def test_chain_rejects_bad_fields(field: str, value: object) -> None:
    fields = _valid_fields()
    fields[field] = value
    with pytest.raises(InputError, match=rf"^{field}:"):
        Chain(**fields)  # type: ignore[arg-type]


def test_chain_arrays_are_read_only() -> None:
    chain = Chain(**_valid_fields())  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        chain.a[0] = 1.0


def test_bad_shapes_raise_input_error_naming_the_argument() -> None:
    chain = get_robot("ur5e")
    with pytest.raises(InputError, match="^q:"):
        forward(chain, np.zeros(6))
    with pytest.raises(InputError, match="^q:"):
        forward(chain, np.zeros((2, 5)))
    with pytest.raises(InputError, match="^kin_delta:"):
        forward(chain, np.zeros((2, 6)), np.zeros(29))
    with pytest.raises(InputError, match="^kin_delta:"):
        forward(chain, np.zeros((2, 6)), np.zeros((3, 30)))
    poses = forward(chain, np.zeros((2, 6)))
    s = screws(chain, poses)
    with pytest.raises(InputError, match="^x_base:"):
        point_jacobian(s, np.zeros((3, 3)))
    with pytest.raises(InputError, match="^poses:"):
        screws(get_robot("industrial6"), poses)
