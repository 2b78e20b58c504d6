"""Joint coupling: a joint's angle error proportional to a neighbouring joint's angle.

Coupled wrists (a differential drive, a cable routed through the previous joint) make joint
j read off by ``k * q_{j-1}`` or ``k * q_{j+1}``. The effect has one parameter per ordered
pair of neighbouring wrist joints (the last three of each chain; ``pairs="all"``: every
neighbouring pair): ``k6_5`` is joint 6's angle error per radian of joint 5 (on a
kinematic tree ``left.k6_5``). Linear in its parameters.

Only the wrist by default: on a shoulder and elbow, a neighbour's angle is close to what the
gravity torque and the link geometry already depend on, so a coupling there would compete
with compliance and geometry for the same residuals (a coupling elsewhere is found by the
effect-agnostic search, and ``diagnose --ladder`` builds it: diagnostics.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.model import joint_offsets
from hostpc.model.effect import Effect, Hook, ModelContext

WRIST_JOINTS = 3


def coupled_pairs(ctx: ModelContext, wrist_only: bool = True) -> list[tuple[str, int, int]]:
    """(name, affected column, driving column) for every neighbouring pair of one chain
    (only among its last WRIST_JOINTS joints when ``wrist_only``)."""
    pairs = []
    labels = ctx.joint_labels
    prefixes = [label.rpartition(".")[0] for label in labels]
    for column in range(len(labels) - 1):
        prefix, _, first = labels[column].rpartition(".")
        next_prefix, _, second = labels[column + 1].rpartition(".")
        if prefix != next_prefix:
            continue
        from_end = sum(1 for p in prefixes[column:] if p == prefix)  # joints left in chain
        if wrist_only and from_end > WRIST_JOINTS:
            continue
        head = f"{prefix}." if prefix else ""
        i, j = first[1:], second[1:]
        pairs.append((f"{head}k{j}_{i}", column + 1, column))
        pairs.append((f"{head}k{i}_{j}", column, column + 1))
    return pairs


class JointCoupling(Effect):
    """dq_a = k_ab * q_cmd_b for each neighbouring wrist pair (a, b) of one chain (rad per
    rad; a prismatic joint's m in its place: ``parameter_units``); ``JointCoupling("all")``:
    every neighbouring pair."""

    name = "joint_coupling"
    hook: ClassVar[Hook] = "joint"
    is_linear: ClassVar[bool] = True
    description = "a joint's angle error proportional to its neighbour's angle (coupled wrists)"
    advice = ("Residuals follow a neighbouring joint's angle (joint {j}'s angle error is "
              "proportional to it)")

    def __init__(self, pairs: str = "wrist") -> None:
        if pairs not in ("wrist", "all"):
            raise ValueError(f"pairs {pairs!r}: expected 'wrist' or 'all'")
        self.wrist_only = pairs == "wrist"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return [name for name, _, _ in coupled_pairs(ctx, self.wrist_only)]

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        units = joint_offsets.units(ctx.chain)
        return [f"{units[affected]}/{units[driving]}"
                for _, affected, driving in coupled_pairs(ctx, self.wrist_only)]

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """A joint's zero moving with a neighbouring joint's angle, for the pairs the
        effect has on ctx's robot (any neighbour when ctx is None)."""
        offset = joint_offsets.match(parameter)
        if offset is None:
            return False
        b, j = offset.branch, offset.joint
        return any(variable == f"{b}q{i}" and (ctx is None or f"{b}k{j}_{i}" in
                                               cls().parameter_names(ctx))
                   for i in (j - 1, j + 1))

    def basis(self, ctx: ModelContext) -> np.ndarray:
        pairs = coupled_pairs(ctx, self.wrist_only)
        basis = np.zeros((ctx.n_samples, ctx.n_joints, len(pairs)))
        for k, (_, affected, driving) in enumerate(pairs):
            basis[:, affected, k] = ctx.q_cmd[:, driving]
        return basis

    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("njp,p->nj", self.basis(ctx), p)
