"""Joint-space effects: q_true = q_cmd + delta(q_cmd, context, p). All are linear in p.

A delta has its joint's unit (``joint_offsets.unit``: rad, m for a prismatic joint), so
each per-joint parameter's unit follows its joint's type (``parameter_units``)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.errors import EffectError
from hostpc.model import joint_offsets
from hostpc.model.effect import Effect, Hook, ModelContext

#: a gravity torque or an approach direction as a diagnostic variable ("tau3",
#: "left.approach2"): compliance and backlash show in many parameters at once
TORQUE_VARIABLE = re.compile(r"(\w+\.)?tau\d+")
APPROACH_VARIABLE = re.compile(r"(\w+\.)?approach\d+")


def _diagonal_basis(values: np.ndarray) -> np.ndarray:
    """(N, n) per-joint regressors -> (N, n, n) basis with delta_i = values_i * p_i."""
    n_samples, n_joints = values.shape
    basis = np.zeros((n_samples, n_joints, n_joints))
    index = np.arange(n_joints)
    basis[:, index, index] = values
    return basis


def _joint_units(ctx: ModelContext, per: str = "") -> list[str]:
    """The unit of each joint's delta (its offset's, ``joint_offsets.units``) per unit of
    its regressor: ``per`` "" (none), or "load" (a gravity torque in N m, a force along a
    prismatic joint's axis in N)."""
    units = joint_offsets.units(ctx.chain)
    if per == "load":
        return [f"{unit}/N" if unit == joint_offsets.LENGTH_UNIT else f"{unit}/(N m)"
                for unit in units]
    return list(units)


class _LinearJointEffect(Effect):
    hook: ClassVar[Hook] = "joint"
    is_linear: ClassVar[bool] = True

    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("njp,p->nj", self.basis(ctx), p)


class JointOffsets(_LinearJointEffect):
    """Joint zero offsets: dq_i = p_i (rad; m for a prismatic joint). A coupled joint
    (``Chain.coupled``, a URDF ``<mimic>``) has no offset of its own: it follows its
    leader's (its parameter moves nothing and the fit holds it at 0;
    hostpc.model.measurements.terms.kinematic_deltas)."""

    name = "joint_offsets"
    description = "constant zero offset of every joint"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ctx.per_joint_names("q")

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return _joint_units(ctx)

    def basis(self, ctx: ModelContext) -> np.ndarray:
        return _diagonal_basis(np.ones_like(ctx.q_cmd))


class JointCompliance(_LinearJointEffect):
    """Joint compliance under gravity: dq_i = c_i * tau_i(q_cmd) (rad per N m; m per N for a
    prismatic joint, whose tau_i is the force along its axis)."""

    name = "joint_compliance"
    description = "joints bend under the gravity load torque"
    advice = "Residuals follow the gravity torque on joint {j}"

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """Any parameter moving with a joint's gravity torque."""
        return TORQUE_VARIABLE.fullmatch(variable) is not None

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ctx.per_joint_names("c")

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return _joint_units(ctx, per="load")

    def basis(self, ctx: ModelContext) -> np.ndarray:
        if not np.all(np.isfinite(ctx.tau)):
            raise EffectError(
                f"joint_compliance needs link masses, but robot {ctx.chain.name!r} has none"
            )
        return _diagonal_basis(ctx.tau)


class EncoderScale(_LinearJointEffect):
    """Encoder scale error: dq_i = s_i * q_cmd_i."""

    name = "encoder_scale"
    description = "joint angle reads scaled by (1 + s)"
    advice = "Residuals grow with the angle of joint {j} (a scale error of its encoder)"

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """A joint's zero moving with its own angle."""
        return _own_angle(parameter, variable)

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ctx.per_joint_names("s")

    def basis(self, ctx: ModelContext) -> np.ndarray:
        return _diagonal_basis(ctx.q_cmd)


class Backlash(_LinearJointEffect):
    """Backlash: dq_i = b_i * approach_i (approach = +1/-1 direction of the last motion;
    b_i in rad, m for a prismatic joint)."""

    name = "backlash"
    approach_dependent = True
    description = "joint angle depends on the direction of the last motion"
    advice = "Residuals depend on the direction of the last motion of joint {j}"

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """Any parameter moving with a joint's approach direction."""
        return APPROACH_VARIABLE.fullmatch(variable) is not None

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ctx.per_joint_names("b")

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return _joint_units(ctx)

    def basis(self, ctx: ModelContext) -> np.ndarray:
        return _diagonal_basis(ctx.approach)


class TransmissionHarmonic(_LinearJointEffect):
    """Transmission harmonics per joint: dq = a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q
    (rad; on a prismatic joint m, with q in m as the argument: no revolution to follow, a
    term there fits nothing physical)."""

    name = "transmission_harmonic"
    description = "once- and twice-per-revolution errors of each joint's transmission"
    advice = ("Residuals follow a once- or twice-per-revolution pattern of joint {j}'s "
              "angle")
    _terms = (("sin1", np.sin, 1.0), ("cos1", np.cos, 1.0), ("sin2", np.sin, 2.0),
              ("cos2", np.cos, 2.0))

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """A joint's zero moving with its own angle."""
        return _own_angle(parameter, variable)

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return [f"{term}_{label}" for label in ctx.joint_labels for term, _, _ in self._terms]

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return [unit for unit in _joint_units(ctx) for _ in self._terms]

    def basis(self, ctx: ModelContext) -> np.ndarray:
        n_samples, n_joints = ctx.q_cmd.shape
        n_terms = len(self._terms)
        basis = np.zeros((n_samples, n_joints, n_joints * n_terms))
        for joint in range(n_joints):
            for k, (_, function, order) in enumerate(self._terms):
                basis[:, joint, joint * n_terms + k] = function(order * ctx.q_cmd[:, joint])
        return basis


def _own_angle(parameter: str, variable: str) -> bool:
    """Whether parameter is a joint's zero offset and variable that joint's angle."""
    offset = joint_offsets.match(parameter)
    return offset is not None and variable == f"{offset.branch}q{offset.joint}"
