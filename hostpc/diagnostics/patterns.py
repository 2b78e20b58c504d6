"""Which built-in effect a residual pattern ("parameter P varies with variable V") is: the
table the advice names effects by and the generated effects (auto_effects.py) defer to."""

from __future__ import annotations

import re

from hostpc.model import joint_offsets
from hostpc.model.effect import ModelContext
from hostpc.model.effects.coupling import JointCoupling

# which built-in effect a "joint offset varies with variable" pattern is; {b}: the branch
# prefix of a kinematic tree ("left."), {j}: the joint (checked first)
OFFSET_PATTERN_EFFECTS = (
    ("{b}tau{j}", "joint_compliance"),
    ("{b}approach{j}", "backlash"),
    ("{b}q{j}", "encoder_scale or transmission_harmonic"),
)
# the same for other parameters
PATTERN_EFFECTS = (
    (re.compile(r"tool\.z$"), "depth", "depth_scale"),
    (re.compile(r".*$"), "speed", "trigger_latency"),
    (re.compile(r"geometry\.[ad]\d+$"), "temperature", "thermal_expansion"),
    (re.compile(r"geometry\.[ad]\d+$"), "t", "thermal_expansion"),
)


def pattern_effect(parameter: str, variable: str, context: ModelContext | None = None
                   ) -> str | None:
    """The built-in effect(s) a "parameter varies with variable" pattern is, or None (a
    neighbour's angle is joint_coupling only for the pairs it has on ``context``'s robot)."""
    offset = joint_offsets.match(parameter)
    if offset is not None:
        for template, effect in OFFSET_PATTERN_EFFECTS:
            if variable == template.format(b=offset.branch, j=offset.joint):
                return effect
    for pattern, template, effect in PATTERN_EFFECTS:
        match = pattern.match(parameter)
        if match and variable == template.format(**match.groupdict()):
            return effect
    # any parameter moving with a gravity torque or an approach direction: what the
    # compliance and the backlash of some joint do (they show in many parameters at once)
    if re.fullmatch(r"(\w+\.)?tau\d+", variable):
        return "joint_compliance"
    if re.fullmatch(r"(\w+\.)?approach\d+", variable):
        return "backlash"
    if offset is not None:  # a joint's zero moving with a neighbouring joint's angle
        b, j = offset.branch, offset.joint
        for i in (j - 1, j + 1):
            if variable == f"{b}q{i}" and (context is None or f"{b}k{j}_{i}" in
                                           JointCoupling().parameter_names(context)):
                return "joint_coupling"
    return None
