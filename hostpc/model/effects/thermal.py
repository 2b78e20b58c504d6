"""Thermal expansion of the links: every nominal link length and offset (DH/MDH ``a`` and
``d``) grows by ``e * (T - T_mean)``.

``T`` is the recorded ``temperature`` (K or deg C: a difference is the same) when the
dataset has it on every sample, else the time since the start ``t`` (s): an arm warming up
during the run expands roughly in proportion to the time it has run. ``T_mean`` is the
mean over the samples, so the constant part stays in the nominal table (or ``geometry``)
and ``e`` is the expansion per kelvin (1/K) or per second (1/s). Linear in ``e``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.errors import EffectError
from hostpc.kinematics import kin_index
from hostpc.model.effect import Effect, Hook, ModelContext

#: a link length or offset of the geometry effect ("geometry.a2", "geometry.d4")
LINK_LENGTH = re.compile(r"geometry\.[ad]\d+")


def thermal_driver(ctx: ModelContext) -> tuple[str, np.ndarray]:
    """("temperature" or "t", its values minus their mean (N,)); EffectError when neither
    is recorded on every sample."""
    for name in ("temperature", "t"):
        values = ctx.variables.get(name)
        if values is not None and np.all(np.isfinite(values)):
            values = np.asarray(values, dtype=float)
            return name, values - values.mean()
    raise EffectError("thermal_expansion needs `temperature` or `t` on every sample")


class ThermalExpansion(Effect):
    """delta a_i = e * a_i * dT, delta d_i = e * d_i * dT (one parameter ``e``)."""

    name = "thermal_expansion"
    hook: ClassVar[Hook] = "geometry"
    is_linear: ClassVar[bool] = True
    description = "link lengths grow with temperature (or with time since the start)"
    advice = "Residuals drift with the temperature (or the time since the start)"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ["e"]

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """A link length or offset moving with the temperature or the time."""
        return LINK_LENGTH.fullmatch(parameter) is not None and variable in ("temperature", "t")

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return ["1/K" if thermal_driver(ctx)[0] == "temperature" else "1/s"]

    def basis(self, ctx: ModelContext) -> np.ndarray:
        _, change = thermal_driver(ctx)
        chain = ctx.chain
        n = chain.n
        lengths = np.zeros(5 * n)
        for joint in range(1, n + 1):
            lengths[kin_index("a", joint, n)] = chain.a[joint - 1]
            lengths[kin_index("d", joint, n)] = chain.d[joint - 1]
        return (change[:, None] * lengths[None, :])[:, :, None]

    def kinematic_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("nkp,p->nk", self.basis(ctx), p)
