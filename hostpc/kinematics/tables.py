"""Building a :class:`Chain` from a DH or MDH table (conventions.md, "DH and MDH").

The lowest layer of the robot descriptions: the built-in robots (`robots.py`), the
humanoid's chains (`humanoid.py`) and URDF import (`urdf.py`) all build their chains here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain

__all__ = ["JOINT_TYPES", "PARALLEL_TOL", "chain_from_table"]

JOINT_TYPES: tuple[str, ...] = ("revolute", "prismatic")
"""Joint types of an explicit table row."""

PARALLEL_TOL = 0.01
"""Two consecutive joint axes count as near-parallel when ``|sin(alpha)|`` is below this
(about 0.57 degrees); their row then gets a Hayati ``beta``."""


def _hayati_flags(convention: str, alpha: ArrayLike) -> NDArray[np.bool_]:
    """Rows whose ``beta`` is meaningful: twist between consecutive joint axes near 0 or pi.

    DH row ``i`` holds the twist between axes ``i`` and ``i+1`` (rows ``1..n-1``); MDH row
    ``i`` holds the twist between axes ``i-1`` and ``i`` (rows ``2..n``; row 1's twist is to
    the base z axis).
    """
    alpha = np.asarray(alpha, dtype=np.float64)
    flags: NDArray[np.bool_] = np.abs(np.sin(alpha)) < PARALLEL_TOL
    if flags.size:
        if convention == "dh":
            flags[-1] = False
        else:
            flags[0] = False
    return flags


def chain_from_table(
    name: str,
    convention: Literal["dh", "mdh"],
    a: ArrayLike,
    alpha: ArrayLike,
    d: ArrayLike,
    theta: ArrayLike,
    q_min: ArrayLike | None = None,
    q_max: ArrayLike | None = None,
    mass: ArrayLike | None = None,
    com: ArrayLike | None = None,
    joint_types: Sequence[str] | None = None,
    T_base_link0: ArrayLike | None = None,
    T_link_flange: ArrayLike | None = None,
    coupled: Sequence[tuple[int, int, float, float]] = (),
) -> Chain:
    """Build a :class:`Chain` from a DH or MDH table (conventions.md, "DH and MDH").

    The Hayati flags follow from ``alpha`` (see :data:`PARALLEL_TOL`); nominal ``beta``
    is 0.

    Args:
        name: robot name.
        convention: ``"dh"`` or ``"mdh"``.
        a, alpha, d, theta: table columns, shape ``(n,)`` each (m, rad, m, rad); for MDH
            row ``i`` holds ``a_{i-1}, alpha_{i-1}``.
        q_min, q_max: joint limits (rad), shape ``(n,)``; default ``-2 pi`` and ``2 pi``.
        mass: link masses (kg), shape ``(n,)``, or None.
        com: centre of mass of link ``j`` in link frame ``j`` (m), shape ``(n, 3)``, or None.
        joint_types: ``"revolute"`` (default) or ``"prismatic"`` per joint, or None (all
            revolute). A prismatic joint's ``q`` (m) adds to ``d``; ``theta`` stays fixed.
        T_base_link0, T_link_flange: fixed mounts before the first and after the last row,
            ``(4, 4)`` each, or None (identity).
        coupled: joints that follow another, ``(follower, leader, multiplier, offset)``
            (0-based; see :class:`Chain`).

    Returns:
        The chain; wrong shapes raise :class:`hostpc.errors.InputError` naming the field.
    """
    if convention not in ("dh", "mdh"):
        raise InputError(f"convention: expected 'dh' or 'mdh', got {convention!r}")
    a_arr = np.asarray(a, dtype=np.float64)
    if a_arr.ndim != 1:
        raise InputError(f"a: expected shape (n,), got {a_arr.shape}")
    n = a_arr.shape[0]
    alpha_arr = np.asarray(alpha, dtype=np.float64)
    if alpha_arr.shape != (n,):
        raise InputError(f"alpha: expected shape ({n},), got {alpha_arr.shape}")
    prismatic = None
    if joint_types is not None:
        types = list(joint_types)
        if len(types) != n:
            raise InputError(f"joint_types: expected {n} entries, got {len(types)}")
        for i, kind in enumerate(types):
            if kind not in JOINT_TYPES:
                raise InputError(
                    f"joint_types: joint {i + 1} has type {kind!r}; expected one of {JOINT_TYPES}"
                )
        prismatic = np.array([kind == "prismatic" for kind in types])
    return Chain(
        name=name,
        convention=convention,
        a=a_arr,
        alpha=alpha_arr,
        d=np.asarray(d, dtype=np.float64),
        theta=np.asarray(theta, dtype=np.float64),
        beta=np.zeros(n),
        hayati=_hayati_flags(convention, alpha_arr),
        q_min=np.full(n, -2.0 * np.pi) if q_min is None else np.asarray(q_min, dtype=float),
        q_max=np.full(n, 2.0 * np.pi) if q_max is None else np.asarray(q_max, dtype=float),
        mass=None if mass is None else np.asarray(mass, dtype=np.float64),
        com=None if com is None else np.asarray(com, dtype=np.float64),
        prismatic=prismatic,
        T_base_link0=None if T_base_link0 is None else np.asarray(T_base_link0, float),
        T_link_flange=None if T_link_flange is None else np.asarray(T_link_flange, float),
        coupled=tuple((int(f), int(lead), float(m), float(c)) for f, lead, m, c in coupled),
    )
