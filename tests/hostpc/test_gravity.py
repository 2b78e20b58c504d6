"""Gravity torque: against -dV/dq of the potential energy, and hand-checked cases."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.errors import InputError
from hostpc.kinematics import chain_from_table, forward, get_robot, gravity_torque

G = 9.81


def potential_energy(chain, q: np.ndarray, kin_delta=None) -> np.ndarray:  # type: ignore[no-untyped-def]
    """V = sum_j m_j g h_j (h_j: height of link j's centre of mass in base), shape (N,)."""
    T = forward(chain, q, kin_delta).T_base_link[:, 1:]
    com = np.concatenate([chain.com, np.ones((chain.n, 1))], axis=1)
    height = np.einsum("nkj,kj->nk", T[:, :, 2, :], com)
    return (chain.mass * G * height).sum(axis=1)


@pytest.mark.parametrize("name", ["ur5e", "ur10e", "industrial6"])
def test_gravity_torque_is_minus_potential_gradient(name: str) -> None:
    chain = get_robot(name)
    rng = np.random.default_rng(21)
    q = rng.uniform(chain.q_min, chain.q_max, size=(8, chain.n))
    h = 1e-6
    for kin_delta in (None, rng.normal(scale=0.02, size=5 * chain.n)):
        tau = gravity_torque(chain, q, kin_delta)
        assert tau.shape == (8, chain.n)
        for i in range(chain.n):
            step = np.zeros(chain.n)
            step[i] = h
            dV = (potential_energy(chain, q + step, kin_delta)
                  - potential_energy(chain, q - step, kin_delta)) / (2 * h)
            np.testing.assert_allclose(tau[:, i], -dV, atol=1e-6)


def _planar(convention: str):  # type: ignore[no-untyped-def]
    """Vertical joint 1, then two horizontal joints (axes along -y at q = 0), links along x.

    Link 2: 2 kg, 0.5 m; link 3: 1 kg, 0.4 m; each centre of mass mid-link. DH frames sit
    at the distal end of each link (com at -L/2), MDH frames at its proximal joint (+L/2).
    """
    if convention == "dh":
        return chain_from_table(
            "planar", "dh", a=[0, 0.5, 0.4], alpha=[np.pi / 2, 0, 0], d=[0, 0, 0],
            theta=[0, 0, 0], mass=[0, 2.0, 1.0], com=[[0, 0, 0], [-0.25, 0, 0], [-0.2, 0, 0]],
        )
    return chain_from_table(
        "planar", "mdh", a=[0, 0, 0.5], alpha=[0, np.pi / 2, 0], d=[0, 0, 0],
        theta=[0, 0, 0], mass=[0, 2.0, 1.0], com=[[0, 0, 0], [0.25, 0, 0], [0.2, 0, 0]],
    )


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_gravity_torque_hand_checked(convention: str) -> None:
    chain = _planar(convention)
    # Arm horizontal along +x, joint axes along -y: for a mass m at x, (c - o) x (m g) =
    # (x, 0, 0) x (0, 0, -m g) = (0, m g x, 0); on z = -y0 this is -m g x.
    #   tau_2 = -g (2 * 0.25 + 1 * (0.5 + 0.2)) = -1.2 g,   tau_3 = -g (1 * 0.2) = -0.2 g
    # Joint 1 is vertical: no gravity torque.
    tau = gravity_torque(chain, np.zeros((1, 3)))
    np.testing.assert_allclose(tau, [[0.0, -1.2 * G, -0.2 * G]], atol=1e-12)
    # Upper arm straight up (rotate about -y by +90 deg), forearm horizontal again
    # (q3 = -90 deg): only the forearm's lever counts, at x = 0.2 for both joints.
    tau = gravity_torque(chain, np.array([[0.7, np.pi / 2, -np.pi / 2]]))
    np.testing.assert_allclose(tau, [[0.0, -0.2 * G, -0.2 * G]], atol=1e-12)
    # Everything straight up: no torque.
    tau = gravity_torque(chain, np.array([[0.0, np.pi / 2, 0.0]]))
    np.testing.assert_allclose(tau, 0.0, atol=1e-12)


def test_ur5e_shoulder_torque_at_zero_by_hand() -> None:
    # UR5e stretched out along -x at q = 0; joint 2 turns about -y0 through (0, 0, d1).
    # tau_2 = -g sum_{j>=2} m_j x_j, with link j's com x from the DH frames:
    # link 2 frame at x = -0.425 (com +0.2125), link 3 at -0.8172 (com +0.15),
    # links 4..6 at x = -0.8172 (com x-offsets 0 in their frames, which are rotated so
    # that their com x stays -0.8172).
    masses = np.array([8.058, 2.846, 1.37, 1.3, 0.365])
    x = np.array([-0.425 + 0.2125, -0.8172 + 0.15, -0.8172, -0.8172, -0.8172])
    tau = gravity_torque(get_robot("ur5e"), np.zeros((1, 6)))
    assert tau[0, 1] == pytest.approx(-G * (masses * x).sum(), abs=1e-9)
    assert tau[0, 0] == pytest.approx(0.0, abs=1e-12)


def test_gravity_torque_needs_mass_data() -> None:
    chain = chain_from_table("bare", "dh", a=[1.0], alpha=[0.0], d=[0.0], theta=[0.0])
    with pytest.raises(InputError, match="mass"):
        gravity_torque(chain, np.zeros((1, 1)))
    with pytest.raises(InputError, match="^q:"):
        gravity_torque(get_robot("ur5e"), np.zeros(6))
