"""The serial chain: a DH or MDH table with Hayati twists, joint limits and link masses.

The equations and the layout of the kinematic parameter vector are in
``docs/conventions.md`` ("DH and MDH"): per pose, ``5n`` entries grouped by kind,
``theta (n), d (n), a (n), alpha (n), beta (n)``, each group joint 1..n.

A joint is revolute (``q`` adds to ``theta``) or prismatic (``q`` adds to ``d``). The first
``n`` entries of the kinematic vector are always the *joint-variable* slots (what a joint
offset moves): for a prismatic joint the ``theta`` slot holds the length delta of its joint
variable and the ``d`` slot holds the delta of its fixed rotation about the joint axis
(conventions.md, "Prismatic joints"). A chain may also carry fixed mounts before the first
and after the last table row (``T_base_link0``, ``T_link_flange``), as a robot read from a
URDF file does; both are the identity for a plain table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from hostpc.errors import InputError

__all__ = ["KIN_KINDS", "Chain", "kin_index"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

KIN_KINDS: tuple[str, ...] = ("theta", "d", "a", "alpha", "beta")
"""Kinds of kinematic parameters, in the order of the kinematic parameter vector."""


def kin_index(kind: str, joint: int, n: int) -> int:
    """Index of one parameter in the ``5n`` kinematic vector (kind-major, joint-minor).

    Args:
        kind: one of :data:`KIN_KINDS`.
        joint: joint number, 1-based (``1..n``).
        n: number of joints of the chain.

    Returns:
        ``KIN_KINDS.index(kind) * n + joint - 1``.
    """
    if kind not in KIN_KINDS:
        raise InputError(f"kind: unknown kinematic parameter {kind!r}; expected one of {KIN_KINDS}")
    if not 1 <= joint <= n:
        raise InputError(f"joint: {joint} out of range 1..{n}")
    return KIN_KINDS.index(kind) * n + joint - 1


def _frozen_array(
    value: object, name: str, shape: tuple[int, ...], dtype: type
) -> NDArray[Any]:
    """A read-only copy of ``value`` with the given shape; InputError naming ``name`` else."""
    try:
        arr: NDArray[Any] = np.array(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot convert to a {dtype.__name__} array ({exc})") from exc
    if arr.shape != shape:
        raise InputError(f"{name}: expected shape {shape}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: contains non-finite values")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Chain:
    """A serial chain (revolute and prismatic joints) in standard (``"dh"``) or modified
    (``"mdh"``) DH form.

    All arrays are converted to read-only numpy arrays on construction; shapes are checked
    and a wrong one raises :class:`hostpc.errors.InputError` naming the field.

    Attributes:
        name: robot name.
        convention: ``"dh"`` (distal) or ``"mdh"`` (proximal, Craig); see conventions.md.
        a: link lengths (m), shape ``(n,)``. For MDH row ``i`` holds ``a_{i-1}``.
        alpha: link twists (rad), shape ``(n,)``. For MDH row ``i`` holds ``alpha_{i-1}``.
        d: link offsets (m), shape ``(n,)``.
        theta: joint angle offsets (rad) at ``q = 0``, shape ``(n,)``.
        beta: Hayati twists about y (rad), shape ``(n,)``, nominally 0.
        hayati: shape ``(n,)`` bool; True where row ``i``'s ``beta_i`` is a meaningful
            (fittable) parameter because two consecutive joint axes are near-parallel
            (DH: row ``i < n`` with ``alpha_i`` near 0 or pi; MDH: row ``i > 1`` with
            ``alpha`` near 0 or pi, i.e. axes ``i-1`` and ``i``).
        q_min, q_max: joint limits (rad), shape ``(n,)``.
        mass: link masses (kg), shape ``(n,)``, or None when unknown.
        com: centre of mass of each link ``j`` in link frame ``j`` (m), shape ``(n, 3)``,
            or None when unknown.
        prismatic: shape ``(n,)`` bool; True for a prismatic joint (``q`` in m adds to
            ``d``). None on construction means all revolute; stored as an array.
        T_base_link0: fixed pose of table frame 0 in the robot's base frame, ``(4, 4)``;
            None on construction means the identity.
        T_link_flange: fixed pose of the flange in table frame ``n``, ``(4, 4)``; None on
            construction means the identity.
        coupled: the joints that follow another (a URDF ``<mimic>``), each ``(follower,
            leader, multiplier, offset)`` with 0-based joint indices: ``q_follower =
            multiplier * q_leader + offset``. The joint vector still holds every joint (the
            follower's value as the robot reports it); a joint-space correction of the
            leader (its zero offset, compliance, ...) moves the follower by ``multiplier``
            times as much (conventions.md, "Coupled joints").
    """

    name: str
    convention: Literal["dh", "mdh"]
    a: FloatArray
    alpha: FloatArray
    d: FloatArray
    theta: FloatArray
    beta: FloatArray
    hayati: BoolArray
    q_min: FloatArray
    q_max: FloatArray
    mass: FloatArray | None = None
    com: FloatArray | None = None
    prismatic: BoolArray | None = None
    T_base_link0: FloatArray | None = None
    T_link_flange: FloatArray | None = None
    coupled: tuple[tuple[int, int, float, float], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"name: expected a non-empty string, got {self.name!r}")
        if self.convention not in ("dh", "mdh"):
            raise InputError(f"convention: expected 'dh' or 'mdh', got {self.convention!r}")
        a = np.asarray(self.a)
        if a.ndim != 1 or a.shape[0] < 1:
            raise InputError(f"a: expected shape (n,) with n >= 1, got {a.shape}")
        n = a.shape[0]
        for field in ("a", "alpha", "d", "theta", "beta", "q_min", "q_max"):
            object.__setattr__(
                self, field, _frozen_array(getattr(self, field), field, (n,), float)
            )
        object.__setattr__(self, "hayati", _frozen_array(self.hayati, "hayati", (n,), bool))
        if np.any(self.q_min > self.q_max):
            bad = int(np.argmax(self.q_min > self.q_max)) + 1
            raise InputError(f"q_min: joint {bad} has q_min > q_max")
        if self.mass is not None:
            mass = _frozen_array(self.mass, "mass", (n,), float)
            if np.any(mass < 0.0):
                raise InputError("mass: link masses must be >= 0")
            object.__setattr__(self, "mass", mass)
        if self.com is not None:
            object.__setattr__(self, "com", _frozen_array(self.com, "com", (n, 3), float))
        prismatic = np.zeros(n, dtype=bool) if self.prismatic is None else self.prismatic
        object.__setattr__(self, "prismatic", _frozen_array(prismatic, "prismatic", (n,), bool))
        for field in ("T_base_link0", "T_link_flange"):
            value = getattr(self, field)
            T = _frozen_array(np.eye(4) if value is None else value, field, (4, 4), float)
            if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]) or not np.allclose(
                T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9
            ):
                raise InputError(f"{field}: not a rigid transform")
            object.__setattr__(self, field, T)
        couplings = tuple((int(f), int(leader), float(m), float(c))
                          for f, leader, m, c in self.coupled)
        followers = [f for f, _, _, _ in couplings]
        for f, leader, m, c in couplings:
            if not (0 <= f < n and 0 <= leader < n) or f == leader or leader in followers:
                raise InputError(f"coupled: joint {f + 1} cannot follow joint {leader + 1} "
                                 f"(joints 1..{n}; a leader is not itself a follower)")
            if not (np.isfinite(m) and np.isfinite(c)):
                raise InputError(f"coupled: joint {f + 1}: multiplier and offset must be finite")
        if len(set(followers)) != len(followers):
            raise InputError("coupled: a joint follows two leaders")
        object.__setattr__(self, "coupled", couplings)

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.a.shape[0])

    @property
    def joint_is_prismatic(self) -> BoolArray:
        """``(n,)`` bool: True for prismatic joints (never None after construction)."""
        assert self.prismatic is not None
        return self.prismatic

    @property
    def has_mounts(self) -> bool:
        """True when the base or flange mount is not the identity."""
        assert self.T_base_link0 is not None and self.T_link_flange is not None
        return not (
            np.array_equal(self.T_base_link0, np.eye(4))
            and np.array_equal(self.T_link_flange, np.eye(4))
        )

    def kin_vector(self) -> FloatArray:
        """Nominal kinematic parameters ``[theta, d, a, alpha, beta]``, shape ``(5n,)``.

        The first two groups are the joint-variable slot and the other one of (theta, d),
        as in the module docstring: for a prismatic joint ``d`` comes first."""
        slot1 = np.where(self.joint_is_prismatic, self.d, self.theta)
        slot2 = np.where(self.joint_is_prismatic, self.theta, self.d)
        return np.concatenate([slot1, slot2, self.a, self.alpha, self.beta])
