"""Built-in robots (a :class:`Chain` from a DH/MDH table is built in `tables.py`).

Every built-in robot cites the source of its numbers in its docstring. Units are SI
(m, rad, kg); centres of mass are in the link's own DH/MDH frame.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.humanoid import tree_names
from hostpc.kinematics.tables import chain_from_table

__all__ = ["get_robot", "names"]

_HALF_PI = np.pi / 2.0


def _ur5e() -> Chain:
    """Universal Robots UR5e, standard DH.

    Source: Universal Robots, "DH Parameters for calculations of kinematics and dynamics"
    (support article, https://www.universal-robots.com/articles/ur/application-installation/
    dh-parameters-for-calculations-of-kinematics-and-dynamics/), UR5e table: kinematics
    (theta, a, d, alpha) and dynamics (link mass, centre of mass in the link's DH frame).
    Joint limits: +-360 deg on every joint (UR's published working range).
    """
    return chain_from_table(
        "ur5e",
        "dh",
        a=[0.0, -0.425, -0.3922, 0.0, 0.0, 0.0],
        alpha=[_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0],
        d=[0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996],
        theta=[0.0] * 6,
        mass=[3.761, 8.058, 2.846, 1.37, 1.3, 0.365],
        com=[
            [0.0, -0.02561, 0.00193],
            [0.2125, 0.0, 0.11336],
            [0.15, 0.0, 0.0265],
            [0.0, -0.0018, 0.01634],
            [0.0, 0.0018, 0.01634],
            [0.0, 0.0, -0.001159],
        ],
    )


def _ur10e() -> Chain:
    """Universal Robots UR10e, standard DH.

    Source: Universal Robots, "DH Parameters for calculations of kinematics and dynamics"
    (support article, https://www.universal-robots.com/articles/ur/application-installation/
    dh-parameters-for-calculations-of-kinematics-and-dynamics/), UR10e table: kinematics
    (theta, a, d, alpha) and dynamics (link mass, centre of mass in the link's DH frame).
    Joint limits: +-360 deg on every joint (UR's published working range).
    """
    return chain_from_table(
        "ur10e",
        "dh",
        a=[0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0],
        alpha=[_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0],
        d=[0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655],
        theta=[0.0] * 6,
        mass=[7.369, 13.051, 3.989, 2.1, 1.98, 0.615],
        com=[
            [0.021, 0.0, 0.027],
            [0.38, 0.0, 0.158],
            [0.24, 0.0, 0.068],
            [0.0, 0.007, 0.018],
            [0.0, 0.007, 0.018],
            [0.0, 0.0, -0.026],
        ],
    )


def _industrial6() -> Chain:
    """A generic 6R industrial arm with a spherical wrist: the PUMA 560, modified DH.

    Source: the Armstrong, Khatib & Burdick PUMA 560 model ("The explicit dynamic model and
    inertial parameters of the PUMA 560 arm", ICRA 1986) in Craig's modified DH
    convention, as listed in P. Corke's Robotics Toolbox (``mdl_puma560akb``):
    alpha_{i-1} = [0, -90, 0, 90, -90, 90] deg, a_{i-1} = [0, 0, 0.4318, -0.0203, 0, 0] m,
    d_i = [0, 0.2435, -0.0934, 0.4331, 0, 0] m; link masses [0, 17.4, 4.8, 0.82, 0.34,
    0.09] kg and centres of mass in the MDH link frames. The flange is the wrist centre
    (no tool plate offset), as in the source.

    Joint limits: the PUMA 560 ranges of Corke's toolbox model (``Puma560``: -160..160,
    -45..225, -225..45, -110..170, -100..100, -266..266 deg in Paul's DH), mapped to this
    table: all its twists have the opposite sign to Paul's, which reverses the axes of
    joints 2, 3 and 5 (at q = 0 both models have the upper arm along +x and the forearm
    up), so those ranges are mirrored.
    """
    deg = np.pi / 180.0
    return chain_from_table(
        "industrial6",
        "mdh",
        a=[0.0, 0.0, 0.4318, -0.0203, 0.0, 0.0],
        alpha=[0.0, -_HALF_PI, 0.0, _HALF_PI, -_HALF_PI, _HALF_PI],
        d=[0.0, 0.2435, -0.0934, 0.4331, 0.0, 0.0],
        theta=[0.0] * 6,
        q_min=np.array([-160.0, -225.0, -45.0, -110.0, -100.0, -266.0]) * deg,
        q_max=np.array([160.0, 45.0, 225.0, 170.0, 100.0, 266.0]) * deg,
        mass=[0.0, 17.4, 4.8, 0.82, 0.34, 0.09],
        com=[
            [0.0, 0.0, 0.0],
            [0.068, 0.006, -0.016],
            [0.0, -0.070, 0.014],
            [0.0, 0.0, -0.019],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.032],
        ],
    )


_ROBOTS: dict[str, Callable[[], Chain]] = {
    "ur5e": _ur5e,
    "ur10e": _ur10e,
    "industrial6": _industrial6,
}


def names() -> list[str]:
    """Names of the built-in robots, sorted."""
    return sorted(_ROBOTS)


def canonical_name(name: str) -> str:
    """The built-in robot's own spelling of ``name``, matched ignoring case (a PLC writes
    "UR5e", the CLI "ur5e": one robot model, one name in the archive); any other name (a
    URDF robot's, a customer's) only stripped."""
    wanted = name.strip()
    return next((known for known in _ROBOTS if known.lower() == wanted.lower()), wanted)


def get_robot(name: str) -> Chain:
    """The built-in robot ``name`` (see :func:`names`).

    Raises:
        InputError: unknown name; the message lists the built-in robots.
    """
    factory = _ROBOTS.get(name)
    if factory is None:
        if name in tree_names():
            raise InputError(f"robot {name!r} is a kinematic tree (several chains), not a "
                             "serial chain; use hostpc.kinematics.humanoid.get_tree")
        raise InputError(f"unknown robot {name!r}; built-in robots: {', '.join(names())}")
    return factory()
