"""Built-in robots and chain_from_table."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.errors import InputError
from hostpc.kinematics import Chain, chain_from_table, get_robot, names


def test_names() -> None:
    assert names() == sorted(["ur5e", "ur10e", "industrial6"])


@pytest.mark.parametrize("name", ["ur5e", "ur10e", "industrial6"])
def test_builtin_robot_is_complete(name: str) -> None:
    chain = get_robot(name)
    assert isinstance(chain, Chain)
    assert chain.name == name
    assert chain.n == 6
    assert chain.mass is not None and chain.mass.shape == (6,)
    assert chain.com is not None and chain.com.shape == (6, 3)
    assert np.all(chain.q_min < chain.q_max)
    np.testing.assert_array_equal(chain.beta, 0.0)
    np.testing.assert_array_equal(chain.theta, 0.0)
    assert not chain.a.flags.writeable
    # a fresh, independent object each call
    assert get_robot(name) is not chain


def test_ur5e_table() -> None:
    chain = get_robot("ur5e")
    assert chain.convention == "dh"
    np.testing.assert_allclose(chain.d, [0.1625, 0, 0, 0.1333, 0.0997, 0.0996])
    np.testing.assert_allclose(chain.a, [0, -0.425, -0.3922, 0, 0, 0])
    np.testing.assert_allclose(chain.alpha, np.pi / 2 * np.array([1, 0, 0, 1, -1, 0]))
    np.testing.assert_allclose(chain.mass, [3.761, 8.058, 2.846, 1.37, 1.3, 0.365])
    np.testing.assert_allclose(chain.com[1], [0.2125, 0, 0.11336])
    np.testing.assert_allclose(chain.q_max, 2 * np.pi)
    np.testing.assert_allclose(chain.q_min, -2 * np.pi)


def test_ur10e_table() -> None:
    chain = get_robot("ur10e")
    assert chain.convention == "dh"
    np.testing.assert_allclose(chain.d, [0.1807, 0, 0, 0.17415, 0.11985, 0.11655])
    np.testing.assert_allclose(chain.a, [0, -0.6127, -0.57155, 0, 0, 0])
    np.testing.assert_allclose(chain.mass, [7.369, 13.051, 3.989, 2.1, 1.98, 0.615])
    np.testing.assert_allclose(chain.com[5], [0, 0, -0.026])


def test_industrial6_is_mdh_puma() -> None:
    chain = get_robot("industrial6")
    assert chain.convention == "mdh"
    np.testing.assert_allclose(chain.a, [0, 0, 0.4318, -0.0203, 0, 0])
    np.testing.assert_allclose(chain.d, [0, 0.2435, -0.0934, 0.4331, 0, 0])
    np.testing.assert_allclose(np.rad2deg(chain.q_min), [-160, -225, -45, -110, -100, -266])
    np.testing.assert_allclose(np.rad2deg(chain.q_max), [160, 45, 225, 170, 100, 266])
    assert chain.mass.sum() == pytest.approx(17.4 + 4.8 + 0.82 + 0.34 + 0.09)


def test_unknown_robot() -> None:
    with pytest.raises(InputError, match=r"unknown robot 'ur3'; built-in robots: .*ur5e"):
        get_robot("ur3")


def test_chain_from_table_defaults() -> None:
    chain = chain_from_table("two", "dh", a=[0.5, 0.4], alpha=[0, 0], d=[0, 0], theta=[0, 0])
    np.testing.assert_allclose(chain.q_min, [-2 * np.pi] * 2)
    np.testing.assert_allclose(chain.q_max, [2 * np.pi] * 2)
    np.testing.assert_array_equal(chain.beta, 0.0)
    np.testing.assert_array_equal(chain.hayati, [True, False])
    assert chain.mass is None and chain.com is None


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        (dict(convention="cdh"), "convention"),
        (dict(alpha=[0.0]), "alpha"),
        (dict(d=[0.0, 0.0, 0.0]), "d"),
        (dict(theta=[[0.0, 0.0]]), "theta"),
        (dict(q_min=[0.0]), "q_min"),
        (dict(mass=[1.0]), "mass"),
        (dict(com=[[0.0, 0.0]] * 2), "com"),
        (dict(a=[[0.0, 0.0]]), "a"),
    ],
)
def test_chain_from_table_bad_input(kwargs: dict[str, object], field: str) -> None:
    table: dict[str, object] = dict(
        name="two", convention="dh", a=[0.5, 0.4], alpha=[0, 0], d=[0, 0], theta=[0, 0]
    )
    table.update(kwargs)
    with pytest.raises(InputError, match=rf"^{field}:"):
        chain_from_table(**table)  # type: ignore[arg-type]
