"""Geometry effect: deltas of the DH/MDH table (d, a, alpha, and Hayati beta where the
axis is near-parallel to the next). theta deltas are the joint offsets and are left out."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.kinematics import kin_index
from hostpc.model.effect import Effect, Hook, ModelContext


class Geometry(Effect):
    """delta_kin = basis @ p with a constant selection basis (5n, P)."""

    name = "geometry"
    hook: ClassVar[Hook] = "geometry"
    is_linear: ClassVar[bool] = True
    description = "link lengths, offsets and twists differ from the nominal table"
    advice = "Residuals follow the link geometry ({parameter} differs from the nominal table)"
    traded_freely = True

    def _kinds(self, ctx: ModelContext) -> list[tuple[str, int]]:
        """(kind, joint from 1) of each parameter, in order."""
        chain = ctx.chain
        kinds = [(kind, joint) for kind in ("d", "a", "alpha")
                 for joint in range(1, chain.n + 1)]
        return kinds + [("beta", joint) for joint in range(1, chain.n + 1)
                        if chain.hayati[joint - 1]]

    def _slots(self, ctx: ModelContext) -> list[tuple[str, int]]:
        n = ctx.chain.n
        return [(f"{kind}{joint}", kin_index(kind, joint, n)) for kind, joint in self._kinds(ctx)]

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return [name for name, _ in self._slots(ctx)]

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        """m for a and d, rad for alpha and beta; a prismatic joint's d slot is the delta of
        its fixed rotation about its axis (docs/conventions.md), an angle: rad."""
        prismatic = ctx.chain.joint_is_prismatic
        return ["rad" if kind in ("alpha", "beta") or (kind == "d" and prismatic[joint - 1])
                else "m" for kind, joint in self._kinds(ctx)]

    def basis(self, ctx: ModelContext) -> np.ndarray:
        slots = self._slots(ctx)
        selection = np.zeros((5 * ctx.n_joints, len(slots)))
        for column, (_, row) in enumerate(slots):
            selection[row, column] = 1.0
        return np.broadcast_to(selection, (ctx.n_samples,) + selection.shape)

    def kinematic_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("nkp,p->nk", self.basis(ctx), p)
