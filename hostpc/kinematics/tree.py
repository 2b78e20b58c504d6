"""Kinematic trees: named serial chains that hang from each other's frames.

A tree is an ordered tuple of :class:`Branch` es. Each branch is one serial
:class:`~hostpc.kinematics.chain.Chain` (its own DH/MDH table, joints ``1..n_c``) whose base
frame is fixed to a frame of its parent branch (the parent's ``base`` or ``end`` frame, the
end being the parent chain's flange) by a nominal mount ``T_parent_base``. The root branch
(``parent`` None) defines the tree's root frame: its base *is* the root.

The combined joint vector of the tree concatenates the branches' joints in branch order, so
a tree with chains ``head`` (2), ``left`` (7) and ``right`` (7) has 16 joints labelled
``head.q1, head.q2, left.q1, ..., right.q7`` (:attr:`KinematicTree.joint_labels`); the
same labels name joint-space effect parameters (``joint_offsets.left.q3``).

For the fit, :meth:`KinematicTree.stacked_chain` concatenates the branch tables into one
*bookkeeping* :class:`Chain` of ``n = sum n_c`` rows. It is never used for forward
kinematics as a serial chain; it gives the effects (``ModelContext.chain``) a table of the
right size, and its ``5n`` kinematic vector maps onto the branches'
(:meth:`KinematicTree.kin_indices`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.gravity import GRAVITY
from hostpc.kinematics.jacobians import joint_axes
from hostpc.kinematics.poses import forward

__all__ = ["Branch", "KinematicTree", "tree_gravity_torque"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class Branch:
    """One serial chain of a tree.

    Attributes:
        name: branch name (``"head"``, ``"left"``, ...); prefixes its joint labels.
        chain: the chain's DH/MDH table.
        parent: name of the branch it hangs from, or None for the root branch.
        attach: which frame of the parent carries this branch's base: ``"base"`` (the
            parent chain's base frame) or ``"end"`` (the parent chain's flange).
        T_parent_base: nominal mount, shape ``(4, 4)``: this branch's base frame in the
            ``attach`` frame of the parent (identity for the root).
    """

    name: str
    chain: Chain
    parent: str | None = None
    attach: Literal["base", "end"] = "base"
    T_parent_base: FloatArray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        T = np.array(self.T_parent_base, dtype=np.float64)
        if T.shape != (4, 4):
            raise InputError(f"{self.name}.T_parent_base: expected shape (4, 4), got {T.shape}")
        if self.attach not in ("base", "end"):
            raise InputError(f"{self.name}.attach: expected 'base' or 'end', got {self.attach!r}")
        T.flags.writeable = False
        object.__setattr__(self, "T_parent_base", T)


@dataclass(frozen=True, eq=False)
class KinematicTree:
    """Named serial chains sharing frames (see the module docstring).

    Attributes:
        name: robot name (``"humanoid_upper"``).
        branches: the branches in joint-vector order; the first is the root, and every
            parent precedes its children.
        frames: nominal values of the tree's named frames for a method (e.g. the dual_loop
            ``camera``, ``left_base``, ...): name -> ``(4, 4)`` pose or ``(3,)`` point.
    """

    name: str
    branches: tuple[Branch, ...]
    frames: Mapping[str, FloatArray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.branches:
            raise InputError(f"tree {self.name!r}: needs at least one branch")
        seen: set[str] = set()
        for k, branch in enumerate(self.branches):
            if branch.name in seen:
                raise InputError(f"tree {self.name!r}: branch {branch.name!r} listed twice")
            if (branch.parent is None) != (k == 0):
                raise InputError(
                    f"tree {self.name!r}: only the first branch is the root "
                    f"(branch {branch.name!r} has parent {branch.parent!r})"
                )
            if branch.parent is not None and branch.parent not in seen:
                raise InputError(
                    f"tree {self.name!r}: branch {branch.name!r} hangs from "
                    f"{branch.parent!r}, which must come before it"
                )
            seen.add(branch.name)
        conventions = {b.chain.convention for b in self.branches}
        if len(conventions) != 1:
            raise InputError(f"tree {self.name!r}: all chains must share one convention")
        object.__setattr__(self, "branches", tuple(self.branches))
        object.__setattr__(self, "frames", dict(self.frames))

    # ------------------------------------------------------------------ bookkeeping

    @property
    def names(self) -> tuple[str, ...]:
        """Branch names in joint-vector order."""
        return tuple(b.name for b in self.branches)

    @property
    def n(self) -> int:
        """Total number of joints (length of the combined joint vector)."""
        return sum(b.chain.n for b in self.branches)

    def branch(self, name: str) -> Branch:
        """The branch ``name``; InputError naming the branches otherwise."""
        for b in self.branches:
            if b.name == name:
                return b
        raise InputError(f"tree {self.name!r} has no chain {name!r} (has: {', '.join(self.names)})")

    def joint_slice(self, name: str) -> slice:
        """Columns of branch ``name`` in the combined joint vector."""
        start = 0
        for b in self.branches:
            if b.name == name:
                return slice(start, start + b.chain.n)
            start += b.chain.n
        self.branch(name)  # raises
        raise AssertionError("unreachable")

    @property
    def joint_labels(self) -> tuple[str, ...]:
        """``("head.q1", ..., "right.q7")``: one label per combined joint."""
        return tuple(f"{b.name}.q{j + 1}" for b in self.branches for j in range(b.chain.n))

    def kin_indices(self, name: str) -> IntArray:
        """Indices, shape ``(5 n_c,)``, of branch ``name``'s kinematic vector
        (``theta, d, a, alpha, beta``, each joint 1..n_c) in the stacked ``5n`` vector."""
        span = self.joint_slice(name)
        joints = np.arange(span.start, span.stop)
        return np.concatenate([kind * self.n + joints for kind in range(5)]).astype(np.int64)

    def stacked_chain(self) -> Chain:
        """All branch tables concatenated (rows in combined joint order); no mass data.

        A bookkeeping chain for effects (sizes, Hayati flags), not a serial mechanism."""
        chains = [b.chain for b in self.branches]

        def cat(attr: str) -> FloatArray:
            return np.concatenate([np.asarray(getattr(c, attr)) for c in chains])

        return Chain(
            name=self.name,
            convention=chains[0].convention,
            a=cat("a"),
            alpha=cat("alpha"),
            d=cat("d"),
            theta=cat("theta"),
            beta=cat("beta"),
            hayati=cat("hayati").astype(bool),
            q_min=cat("q_min"),
            q_max=cat("q_max"),
            prismatic=cat("prismatic").astype(bool),
        )

    # ------------------------------------------------------------------ kinematics

    def root_transforms(
        self, q: ArrayLike, kin_delta: ArrayLike | None = None
    ) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Base and end frame of every branch in the root frame, with the nominal mounts.

        Args:
            q: combined joint angles (rad), shape ``(N, n)``.
            kin_delta: stacked kinematic deltas, shape ``(N, 5n)``, or None.

        Returns:
            name -> ``(T_root_base (N, 4, 4), T_root_end (N, 4, 4))``.
        """
        q_arr = np.asarray(q, dtype=np.float64)
        if q_arr.ndim != 2 or q_arr.shape[1] != self.n:
            raise InputError(f"q: expected shape (N, {self.n}), got {q_arr.shape}")
        N = q_arr.shape[0]
        delta = None if kin_delta is None else np.asarray(kin_delta, dtype=np.float64)
        out: dict[str, tuple[FloatArray, FloatArray]] = {}
        for b in self.branches:
            if b.parent is None:
                T_base = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
            else:
                parent_base, parent_end = out[b.parent]
                T_base = (parent_base if b.attach == "base" else parent_end) @ b.T_parent_base
            d_b = None if delta is None else delta[:, self.kin_indices(b.name)]
            poses = forward(b.chain, q_arr[:, self.joint_slice(b.name)], d_b)
            out[b.name] = (T_base, T_base @ poses.T_base_flange)
        return out


def tree_gravity_torque(
    tree: KinematicTree, q: ArrayLike, gravity_root: ArrayLike = GRAVITY
) -> FloatArray:
    """Gravity load torque on every joint of the tree, each branch on its own.

    ``tau_i = z_i . sum_{j >= i} (c_j - o_i) x (m_j g)`` (conventions.md) over the links of
    joint ``i``'s own chain, with ``g`` expressed in that chain's base frame. The load of a
    child chain on its parent is not included (the trees here hang children from the
    parent's fixed base).

    Args:
        tree: every chain must carry mass data.
        q: combined joint angles (rad), shape ``(N, n)``.
        gravity_root: gravity in the root frame (m/s^2), shape ``(3,)``.

    Returns:
        ``tau`` (N m), shape ``(N, n)``.
    """
    q_arr = np.asarray(q, dtype=np.float64)
    frames = tree.root_transforms(q_arr)
    g_root = np.asarray(gravity_root, dtype=np.float64)
    tau = np.empty_like(q_arr)
    for b in tree.branches:
        chain = b.chain
        if chain.mass is None or chain.com is None:
            raise InputError(f"chain {b.name!r} of {tree.name!r} has no mass data")
        T_root_base = frames[b.name][0]
        g = np.einsum("nji,j->ni", T_root_base[:, :3, :3], g_root)  # R^T g, (N, 3)
        poses = forward(chain, q_arr[:, tree.joint_slice(b.name)])
        T = poses.T_base_link[:, 1:]
        c = np.einsum("nkij,kj->nki", T[..., :3, :3], chain.com) + T[..., :3, 3]
        S = np.cumsum((chain.mass[:, None] * c)[:, ::-1], axis=1)[:, ::-1]
        M = np.cumsum(chain.mass[::-1])[::-1]
        z, o = joint_axes(poses)
        lever = S - M[:, None] * o
        tau[:, tree.joint_slice(b.name)] = np.einsum(
            "nki,nki->nk", z, np.cross(lever, g[:, None, :])
        )
    return tau
