"""Close the loop without code: turn "parameter P varies with variable V" into an effect.

When the effect-agnostic search finds a significant pattern that no built-in effect models,
the ladder builds the interaction effect itself - P linear in V, ``P(V) = P + k (V - V0)``
with V0 the variable's mean on the diagnosed samples - tests it on held-out samples like
any candidate and adds it when it wins. The effect is generated as plugin *source* and
loaded from that source, so the file ``--write-plugins DIR`` writes is exactly the effect
that was fitted: ``hostpc fit DATA --plugin DIR/NAME.py --effects +NAME`` reproduces it.

Parameters that can vary this way: a joint's zero offset (``joint_offsets.q4``,
``joint_offsets.left.q4``: joint hook) and a DH/MDH table entry (``geometry.a3``: geometry
hook, serial robots), and a frame's translation (``world.z``, ``markers.b.x``,
``target.z``: ``frame_candidates``, which also writes a step in time and per level of a
group label). Where V is not recorded (NaN: the other arm's samples) the effect is 0.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.frame_candidates import frame_source, load
from hostpc.diagnostics.interactions import Interaction
from hostpc.diagnostics.patterns import pattern_effect
from hostpc.fitting import FitResult
from hostpc.model import joint_offsets
from hostpc.model.effect import Effect, ModelContext

_GEOMETRY = re.compile(r"geometry\.(?P<kind>d|a|alpha|beta)(?P<joint>\d+)$")

_JOINT_TEMPLATE = '''"""{title}

Written by `hostpc diagnose --ladder --write-plugins`: the effect-agnostic search found
"{parameter} varies with {variable}" and no built-in effect models it. The zero offset of
joint {label} moves by k * ({variable} - {reference!r}) (k in rad per unit of
{variable}; 0 where {variable} is not recorded). Load it with
    hostpc fit DATASET --plugin THIS_FILE --effects +{name}
"""

import numpy as np

from hostpc.model.effect import Effect


class {class_name}(Effect):
    name = "{name}"
    hook = "joint"
    is_linear = True
    unit = "rad/unit"
    description = "{parameter} linear in {variable} (found by hostpc diagnose)"
    variable = "{variable}"
    reference = {reference!r}
    label = "{label}"

    def parameter_names(self, ctx):
        return ["k"]

    def basis(self, ctx):
        values = np.nan_to_num(ctx.variable(self.variable) - self.reference, nan=0.0)
        basis = np.zeros((ctx.n_samples, ctx.n_joints, 1))
        basis[:, list(ctx.joint_labels).index(self.label), 0] = values
        return basis

    def joint_delta(self, ctx, p):
        return np.einsum("njp,p->nj", self.basis(ctx), p)
'''

_GEOMETRY_TEMPLATE = '''"""{title}

Written by `hostpc diagnose --ladder --write-plugins`: the effect-agnostic search found
"{parameter} varies with {variable}" and no built-in effect models it. The table entry
{kind}{joint} changes by k * ({variable} - {reference!r}) (k in its unit per unit of
{variable}; 0 where {variable} is not recorded). Load it with
    hostpc fit DATASET --plugin THIS_FILE --effects +{name}
"""

import numpy as np

from hostpc.kinematics import kin_index
from hostpc.model.effect import Effect


class {class_name}(Effect):
    name = "{name}"
    hook = "geometry"
    is_linear = True
    unit = "per unit"
    description = "{parameter} linear in {variable} (found by hostpc diagnose)"
    variable = "{variable}"
    reference = {reference!r}

    def parameter_names(self, ctx):
        return ["k"]

    def basis(self, ctx):
        values = np.nan_to_num(ctx.variable(self.variable) - self.reference, nan=0.0)
        basis = np.zeros((ctx.n_samples, 5 * ctx.n_joints, 1))
        basis[:, kin_index("{kind}", {joint}, ctx.n_joints), 0] = values
        return basis

    def kinematic_delta(self, ctx, p):
        return np.einsum("nkp,p->nk", self.basis(ctx), p)
'''


@dataclass(frozen=True)
class GeneratedEffect:
    """An interaction effect built from a search result: its name, the pattern it models,
    its plugin source, and the loaded class."""

    name: str
    parameter: str
    variable: str
    source: str
    effect_class: type[Effect]


def effect_name(parameter: str, variable: str) -> str:
    """A valid effect name for "parameter varies with variable": ``q4_with_left_q3``."""
    local = parameter.split(".", 1)[1]
    return re.sub(r"\W", "_", f"{local}_with_{variable}").lower()


def generate(interaction: Interaction, values: np.ndarray,
             fit: FitResult | None = None) -> GeneratedEffect | None:
    """The effect "parameter linear in variable" (values: the variable on the diagnosed
    samples, for its reference), or None when the parameter is not one it can vary.
    With the current fit, frame translations are written too (``frame_candidates``):
    linear in a numeric variable, a step in time, or per level of a group label."""
    parameter, variable = interaction.parameter, interaction.variable
    defined = values[np.isfinite(values)]
    if defined.size == 0:
        return None
    if fit is not None:
        frame = frame_source(parameter, variable, fit, values)
        if frame is not None:
            return GeneratedEffect(frame[0], parameter, variable, frame[1],
                                   load(frame[0], frame[1]))
        if variable in fit.problem.context.categorical:
            return None
    name = effect_name(parameter, variable)
    fields = {"parameter": parameter, "variable": variable, "name": name,
              "reference": float(defined.mean()),
              "class_name": "".join(p.capitalize() for p in name.split("_")),
              "title": f"{parameter} varies with {variable}: a generated zerocal effect."}
    offset, geometry = joint_offsets.match(parameter), _GEOMETRY.match(parameter)
    if offset:
        source = _JOINT_TEMPLATE.format(label=offset.label, **fields)
    elif geometry:
        source = _GEOMETRY_TEMPLATE.format(kind=geometry.group("kind"),
                                           joint=int(geometry.group("joint")), **fields)
    else:
        return None
    return GeneratedEffect(name, parameter, variable, source, load(name, source))


def generated_sources(effects: list[Effect]) -> dict[str, str]:
    """The plugin source of every generated effect among ``effects``, by effect name."""
    return {e.name: e.plugin_source for e in effects  # type: ignore[attr-defined]
            if hasattr(type(e), "plugin_source")}


def unexplained(interactions: tuple[Interaction, ...], tried: set[str],
                context: ModelContext | None = None) -> list[Interaction]:
    """The significant patterns, best first, stronger than any pattern that a built-in
    effect among the candidates ``tried`` (not yet in the model) models: when the search's
    strongest finding is what a built-in effect models, that effect is the answer (the
    weaker patterns are often its echoes) and nothing is generated."""
    found = []
    for interaction in interactions:
        if not interaction.significant:
            break
        built_in = pattern_effect(interaction.parameter, interaction.variable, context)
        if built_in is not None and any(e in tried for e in built_in.split(" or ")):
            break
        found.append(interaction)
    return found
