"""The joint zero offset, the product's output: the one owner of its parameter names.

The ``joint_offsets`` effect (``hostpc.model.effects.joint_space.JointOffsets``) gives every
joint one parameter, ``dq_j = p_j`` (q_true = q_cmd + p; rad, m for a prismatic joint). Its
full parameter name is the effect's name, a dot and the joint's label: ``joint_offsets.q1``
.. ``joint_offsets.qn`` on a serial robot, ``joint_offsets.head.q1``,
``joint_offsets.left.q3``, ... on a kinematic tree (its chain's name before the joint,
docs/dual-loop.md). Fitting, planning, push, verify,
the report, the CLI and the station build and read these names here, never by the prefix.

Units: an offset has its joint's unit (:func:`unit`, :func:`units`): a revolute joint's is an
angle (rad inside: parameters, the push table, the controller's offsets), a prismatic
joint's a length (m inside). The fit's parameter layout carries that unit
(``JointOffsets.parameter_units``), so every edge shows it as the layout says: deg for a
revolute joint, mm for a prismatic one (``hostpc.display_units``), and a prior is parsed
in it (``hostpc.fitting.priors``).

The push table (:class:`PushTable`): the controller's joints in its order, each with the
name of its offset parameter, so a fit's values go to the right joint index and back.
Pure: no numpy state, no I/O; importable from every layer above ``hostpc.model``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hostpc.errors import InputError

if TYPE_CHECKING:
    from hostpc.kinematics import Chain

__all__ = ["ANGLE_UNIT", "EFFECT", "LENGTH_UNIT", "JointOffsetName", "PushTable",
           "chain_prefix", "is_offset", "label", "labels", "match", "offset_name", "parse",
           "unit", "units"]

#: the effect whose parameters are the joint zero offsets
EFFECT = "joint_offsets"
_PREFIX = EFFECT + "."
#: the unit of a revolute joint's offset inside hostpc (and on the wire); deg for people
ANGLE_UNIT = "rad"
#: the unit of a prismatic joint's offset inside hostpc; mm for people
LENGTH_UNIT = "m"
#: a joint label: ``q<j>``, or ``<chain>.q<j>`` on a kinematic tree
_NAME = re.compile(re.escape(_PREFIX) + r"(?P<label>(?:(?P<chain>\w+)\.)?q(?P<joint>\d+))$")


@dataclass(frozen=True)
class JointOffsetName:
    """One parsed offset name: ``joint_offsets.left.q3`` -> chain "left", joint 3, label
    "left.q3"; a serial robot's ``joint_offsets.q3`` has chain "" (joint counts from 1)."""

    chain: str
    joint: int

    @property
    def label(self) -> str:
        return f"{self.chain}.q{self.joint}" if self.chain else f"q{self.joint}"

    @property
    def name(self) -> str:
        return offset_name(self.label)

    @property
    def branch(self) -> str:
        """The chain with its dot ("left.", or "" on a serial robot): the prefix the other
        per-joint names of this joint carry (``left.tau3``, ``left.approach3``)."""
        return f"{self.chain}." if self.chain else ""


def offset_name(joint_label: str) -> str:
    """The offset parameter of the joint labelled ``q1`` (or ``left.q3``)."""
    return _PREFIX + joint_label


def is_offset(name: str) -> bool:
    """Is this parameter name a joint zero offset (of the ``joint_offsets`` effect)?"""
    return name.startswith(_PREFIX)


def chain_prefix(chain: str) -> str:
    """The start every offset name of one chain of a kinematic tree shares
    (``joint_offsets.left.``), for grouping parameters by chain."""
    return f"{_PREFIX}{chain}."


def label(name: str) -> str:
    """The joint label of an offset name: ``joint_offsets.left.q3`` -> ``left.q3``;
    InputError for a name that is not a joint offset."""
    if not is_offset(name):
        raise InputError(f"{name!r} is not a joint offset parameter (expected "
                         f"{_PREFIX}q<j> or {_PREFIX}<chain>.q<j>)")
    return name[len(_PREFIX):]


def labels(names: Iterable[str]) -> list[str]:
    """The labels of the joint offsets among parameter names, in their order."""
    return [name[len(_PREFIX):] for name in names if is_offset(name)]


def match(name: str) -> JointOffsetName | None:
    """The parsed offset name, or None for any other parameter (or a malformed label)."""
    found = _NAME.match(name)
    if found is None:
        return None
    return JointOffsetName(found.group("chain") or "", int(found.group("joint")))


def parse(name: str) -> JointOffsetName:
    """The parsed offset name; InputError naming the value if it is not one."""
    parsed = match(name)
    if parsed is None:
        raise InputError(f"{name!r} is not a joint offset parameter (expected "
                         f"{_PREFIX}q<j> or {_PREFIX}<chain>.q<j>)")
    return parsed


def unit(prismatic: bool) -> str:
    """The SI unit of one joint's offset: its joint variable's, a length ("m") for a
    prismatic joint, an angle ("rad") for a revolute one."""
    return LENGTH_UNIT if prismatic else ANGLE_UNIT


def units(chain: Chain) -> tuple[str, ...]:
    """(n,) the SI unit of each joint's offset of ``chain``, joint 1 first (a kinematic
    tree's stacked chain: in its joint-vector order, as its offset labels)."""
    return tuple(unit(bool(prismatic)) for prismatic in chain.joint_is_prismatic)


@dataclass(frozen=True)
class PushTable:
    """The controller's n joints in its order, each with its offset parameter's name.

    names[j]: the offset of controller joint j (0-based): ``joint_offsets.q1..qn``, or with
    the model's joint labels of a kinematic tree (when there are n of them)
    ``joint_offsets.head.q1``, ... (docs/dual-loop.md)."""

    names: tuple[str, ...]

    @classmethod
    def for_controller(cls, n_joints: int, joint_labels: Sequence[str] = ()) -> PushTable:
        joints = (list(joint_labels) if len(joint_labels) == n_joints
                  else [f"q{j + 1}" for j in range(n_joints)])
        return cls(tuple(offset_name(joint) for joint in joints))

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def labels(self) -> tuple[str, ...]:
        """The joint labels in controller order (``q1``.., or ``head.q1``..)."""
        return tuple(name[len(_PREFIX):] for name in self.names)

    def index(self, name: str) -> int:
        """The controller joint (0-based) of an offset name; InputError if it has none."""
        try:
            return self.names.index(name)
        except ValueError:
            parse(name)  # a name that is no offset at all says so
            raise InputError(f"{name!r} is not an offset of this controller's joints "
                             f"({', '.join(self.labels)})") from None

    def values(self, parameters: Mapping[str, float]) -> list[float]:
        """(n,) rad (m for a prismatic joint) per controller joint from a fit's values by
        name; 0 (nominal) where the fit has no such parameter."""
        return [float(parameters.get(name, 0.0)) for name in self.names]
