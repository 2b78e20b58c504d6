"""Joint coupling: a joint's angle error proportional to a neighbouring joint's angle.

Coupled wrists (a differential drive, a cable routed through the previous joint) make joint
j read off by ``k * q_{j-1}`` or ``k * q_{j+1}``. The effect has one parameter per ordered
pair of neighbouring joints of one chain: ``k4_3`` is joint 4's angle error per radian of
joint 3 (on a kinematic tree ``left.k4_3``). Linear in its parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.model.effect import Effect, Hook, ModelContext


def coupled_pairs(ctx: ModelContext) -> list[tuple[str, int, int]]:
    """(name, affected column, driving column) for every neighbouring pair of one chain."""
    pairs = []
    labels = ctx.joint_labels
    for column in range(len(labels) - 1):
        prefix, _, first = labels[column].rpartition(".")
        next_prefix, _, second = labels[column + 1].rpartition(".")
        if prefix != next_prefix:
            continue
        head = f"{prefix}." if prefix else ""
        i, j = first[1:], second[1:]
        pairs.append((f"{head}k{j}_{i}", column + 1, column))
        pairs.append((f"{head}k{i}_{j}", column, column + 1))
    return pairs


class JointCoupling(Effect):
    """dq_a = k_ab * q_cmd_b for each neighbouring pair (a, b) of one chain (rad per rad)."""

    name = "joint_coupling"
    hook: ClassVar[Hook] = "joint"
    is_linear: ClassVar[bool] = True
    unit = "rad/rad"
    description = "a joint's angle error proportional to its neighbour's angle (coupled wrists)"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return [name for name, _, _ in coupled_pairs(ctx)]

    def basis(self, ctx: ModelContext) -> np.ndarray:
        pairs = coupled_pairs(ctx)
        basis = np.zeros((ctx.n_samples, ctx.n_joints, len(pairs)))
        for k, (_, affected, driving) in enumerate(pairs):
            basis[:, affected, k] = ctx.q_cmd[:, driving]
        return basis

    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("njp,p->nj", self.basis(ctx), p)
