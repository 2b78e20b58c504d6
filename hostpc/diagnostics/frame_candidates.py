"""Generated effects on frames: "the instrument's frame drifts with t", "it moved per group".

The effect-agnostic search tests every model parameter, frame parameters included, against
every logged variable; ``auto_effects`` writes joint and table parameters as effects. This
module writes the frame parameters whose change enters the measurement additively: the
translation of the frame the measurement is expressed in (world_point's ``world``: the
laser tracker's registration; ``world.z`` drifting as its stand settles). Such a change
is exact as a sensor effect, ``y[:, axis] += k * f(v)``, so the written plugin is the
fitted effect on any dataset of that method.

f is the centred variable (linear: ``k`` in m per unit of v), or for a group label one
indicator per level after the first ("per level": the frame's offset on that level's
samples against the first level's, in m). 0 where v is not recorded.

Frames whose change depends on the pose (a marker on the flange, a target seen by a camera
on the flange, rotations) are not written here: the search still names them.
"""

from __future__ import annotations

import re
import types
from collections.abc import Sequence

import numpy as np

from hostpc.model.effect import Effect

#: (method, frame): the frame each method's measurement is expressed in, whose translation
#: adds to the measurement unchanged
ADDITIVE_FRAMES: dict[str, str] = {"world_point": "world"}

_AXES = ("x", "y", "z")

_TEMPLATE = '''"""{title}

Written by `hostpc diagnose --ladder --write-plugins`: the effect-agnostic search found
"{parameter} varies with {variable}" and no built-in effect models it. The measurement is
expressed in frame {frame!r}; its {axis} translation changes by {law}, which moves every
measured point by the same amount along {axis} (0 where {variable} is not recorded).
Load it with
    hostpc fit DATASET --plugin THIS_FILE --effects +{name}
"""

import numpy as np

from hostpc.model.effect import Effect


class {class_name}(Effect):
    name = "{name}"
    hook = "sensor"
    methods = ({method!r},)
    is_linear = True
    unit = "m"
    description = "{parameter} {basis} in {variable} (found by hostpc diagnose)"
    variable = "{variable}"
    axis = {axis_index}
    reference = {reference!r}
    levels = {levels!r}

    def parameter_names(self, ctx):
        return [{names}]

    def modulators(self, ctx):
        values = ctx.variable(self.variable)
        if self.levels:
            columns = [np.where(values == level, 1.0, 0.0) for level in self.levels]
            return np.stack(columns, axis=1)
        return np.nan_to_num(values - self.reference, nan=0.0)[:, None]

    def sensor_apply(self, ctx, p, y):
        out = np.array(y, dtype=float)
        out[:, self.axis] += self.modulators(ctx) @ p
        return out

    def sensor_jacobians(self, ctx, p, y):
        n, m = y.shape
        d_y = np.broadcast_to(np.eye(m), (n, m, m)).copy()
        d_p = np.zeros((n, m, len(p)))
        d_p[:, self.axis, :] = self.modulators(ctx)
        return d_y, d_p
'''


def frame_effect_name(parameter: str, variable: str) -> str:
    """``world_z_with_t``: the frame is kept in the name (``z_with_t`` would not say whose)."""
    return re.sub(r"\W", "_", f"{parameter}_with_{variable}").lower()


def frame_source(parameter: str, variable: str, method: str, values: np.ndarray,
                 levels: Sequence[str] | None = None) -> tuple[str, str] | None:
    """(effect name, plugin source) of "parameter varies with variable" for a frame
    translation that is additive in ``method``'s measurement, else None. values: the
    variable on the diagnosed samples (level indices for a group label); levels: the
    group label's level names (None: a numeric variable)."""
    frame = ADDITIVE_FRAMES.get(method)
    head, _, axis = parameter.partition(".")
    if frame is None or head != frame or axis not in _AXES:
        return None
    defined = values[np.isfinite(values)]
    if defined.size == 0:
        return None
    name = frame_effect_name(parameter, variable)
    if levels is not None:
        present = sorted({int(v) for v in defined})
        if len(present) < 2:
            return None
        indices = present[1:]
        names = ", ".join(repr(f"{levels[i]}") for i in indices)
        fields = {"levels": tuple(float(i) for i in indices), "reference": 0.0,
                  "basis": "per level of", "names": names,
                  "law": f"k_LEVEL on the samples of each {variable} level after "
                         f"{levels[present[0]]!r} (k in m)"}
    else:
        reference = float(defined.mean())
        fields = {"levels": (), "reference": reference, "basis": "linear",
                  "names": "'k'",
                  "law": f"k * ({variable} - {reference!r}) (k in m per unit of {variable})"}
    source = _TEMPLATE.format(
        title=f"{parameter} varies with {variable}: a generated zerocal effect.",
        parameter=parameter, variable=variable, name=name, frame=frame, method=method,
        axis=axis, axis_index=_AXES.index(axis),
        class_name="".join(p.capitalize() for p in name.split("_")), **fields)
    return name, source


def load(name: str, source: str) -> type[Effect]:
    """The effect class defined by a generated plugin source (marked with its source)."""
    module = types.ModuleType(f"zerocal_generated_{name}")
    exec(compile(source, f"<generated {name}>", "exec"), module.__dict__)  # noqa: S102
    cls: type[Effect] = next(v for v in vars(module).values()
                             if isinstance(v, type) and issubclass(v, Effect)
                             and v is not Effect)
    cls.plugin_source = source  # type: ignore[attr-defined]
    return cls
