"""Generated effects on frames: "the instrument's frame drifts with t", "marker b was knocked
at t = 1234 s", "it moved per group".

The effect-agnostic search tests every model parameter, frame parameters included, against
every logged variable; ``auto_effects`` writes joint and table parameters as effects. This
module writes frame translations, as sensor effects ``y += d(sample) * k * f(v)``:

- the frame the measurement is expressed in (world_point's ``world``: the laser tracker's
  registration; ``world.z`` drifting as its stand settles): d is the axis itself, exact;
- a point carried by the flange (world_point's ``markers.b``: a reflector nest) or fixed
  in the base frame (stereo_target's ``target``, seen by the camera on the flange): d is
  the axis turned into the measurement frame, ``R_world_base R_base_flange(q) e`` or
  ``R_flange_tool^T R_base_flange(q)^T e``,
  with the instrument or camera rotation taken at the fit (a constant in the plugin) and
  the flange rotation at the commanded joints (first order: the fitted zero offsets turn
  it by a fraction of a degree). A marker's effect acts on that marker's samples only.

f is the centred variable (linear: ``k`` in m per unit of v); a step ``1[t > t0]`` when the
variable is time and a step explains more of the residual than a line (a knocked marker,
a bumped stand: t0 the best cut between two samples); or for a group label one indicator
per level after the first ("per level": the frame's offset on that level's samples
against the first level's). 0 where v is not recorded.

Rotations of the frame the measurement is expressed in (``world.rz``: the tracker's stand
twisting as it settles) are written too, as a small turn ``y += k f(v) a x (y - o)``: a the
frame's own axis in the measurement frame (``R a_local``, with R at the fit: the model's
rotation delta is ``R exp(r)``, so this is the parameter's own column) and o the frame's
origin at the fit (k in rad per unit of v). Rotations of a point carried by the flange
or fixed in the base (a marker, the target) do not move the point: not written.
"""

from __future__ import annotations

import re
import types
from dataclasses import dataclass

import numpy as np

from hostpc.fitting import FitResult
from hostpc.fitting.solver import evaluate
from hostpc.model.effect import Effect
from hostpc.model.measurements.terms import frame_pose

_AXES = ("x", "y", "z")
_TURNS = ("rx", "ry", "rz")
#: fewest samples on either side of a step
MIN_STEP_SIDE = 3


@dataclass(frozen=True)
class FrameKind:
    """How a frame's translation reaches one method's measurement: ``rotation_frame``
    (None: additive, the measurement's own frame) is the pose frame whose rotation at the
    fit turns the flange-rotated axis into the measurement frame; ``inverse``: the point
    is fixed in the base frame (seen through the flange: R_flange_tool^T R_base_flange^T)
    rather than carried by the flange (R_world_base R_base_flange); ``grouped``: one point
    per level of ``marker``."""

    rotation_frame: str | None
    inverse: bool = False
    grouped: bool = False


#: (method, frame) -> how its translation enters the measurement
FRAMES: dict[tuple[str, str], FrameKind] = {
    ("world_point", "world"): FrameKind(None),
    ("world_point", "markers"): FrameKind("world", grouped=True),
    ("stereo_target", "target"): FrameKind("tool", inverse=True),
}

_TEMPLATE = """\"\"\"{title}

Written by `hostpc diagnose --ladder --write-plugins`: the effect-agnostic search found
"{parameter} varies with {variable}" and no built-in effect models it. The frame's
{motion} changes by {law}; every measured point{whose} {moves}{seen} (0 where {variable}
is not recorded). Load it with
    hostpc fit DATASET --plugin THIS_FILE --effects +{name}
\"\"\"

import numpy as np

from hostpc.kinematics import forward
from hostpc.model.effect import Effect


class {class_name}(Effect):
    name = "{name}"
    hook = "sensor"
    methods = ({method!r},)
    is_linear = True
    unit = "{unit}"
    description = "{parameter} {basis} {variable} (found by hostpc diagnose)"
    variable = "{variable}"
    axis = {axis_index}
    reference = {reference!r}
    step = {step!r}
    levels = {levels!r}
    #: the samples it acts on: (group variable, level index), or None for all
    group = {group!r}
    #: None: the axis adds to the measurement; else (rotation at the fit, inverse)
    rotation = {rotation!r}
    #: None: a translation; else (the turn's axis in the measurement frame, its origin)
    pivot = {pivot!r}

    def parameter_names(self, ctx):
        return [{names}]

    def modulators(self, ctx):
        values = ctx.variable(self.variable)
        if self.levels:
            columns = [np.where(values == level, 1.0, 0.0) for level in self.levels]
            F = np.stack(columns, axis=1)
        elif self.step is not None:
            F = np.where(values > self.step, 1.0, 0.0)[:, None]
        else:
            F = np.nan_to_num(values - self.reference, nan=0.0)[:, None]
        if self.group is not None:
            F = F * (ctx.variable(self.group[0]) == self.group[1])[:, None]
        return F

    def direction(self, ctx, y):
        m = y.shape[1]
        if self.pivot is not None:
            return np.cross(np.array(self.pivot[0]), y - np.array(self.pivot[1]))
        axis = np.eye(3)[self.axis]
        if self.rotation is None:
            return np.broadcast_to(np.eye(m)[self.axis], (ctx.n_samples, m))
        R, inverse = np.array(self.rotation[0]), self.rotation[1]
        R_base_flange = forward(ctx.chain, ctx.q_cmd).T_base_flange[:, :3, :3]
        if inverse:
            return np.einsum("ij,nkj,k->ni", R, R_base_flange, axis)
        return np.einsum("ij,njk,k->ni", R, R_base_flange, axis)

    def sensor_apply(self, ctx, p, y):
        return y + self.direction(ctx, y) * (self.modulators(ctx) @ p)[:, None]

    def sensor_jacobians(self, ctx, p, y):
        n, m = y.shape
        d_y = np.broadcast_to(np.eye(m), (n, m, m)).copy()
        if self.pivot is not None:  # d(a x (y - o))/dy = [a]x
            a = np.array(self.pivot[0])
            turn = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
            d_y = d_y + (self.modulators(ctx) @ p)[:, None, None] * turn
        d_p = np.einsum("ni,np->nip", self.direction(ctx, y), self.modulators(ctx))
        return d_y, d_p
"""


def frame_effect_name(parameter: str, variable: str, step: bool = False) -> str:
    """``world_z_with_t``, ``markers_b_x_step_in_t``: the frame is kept in the name."""
    link = "step_in" if step else "with"
    return re.sub(r"\W", "_", f"{parameter}_{link}_{variable}").lower()


def best_step(fit: FitResult, parameter: str, values: np.ndarray) -> float | None:
    """The cut t0 between two samples at which "parameter steps at t0" explains more of the
    residual (first-order chi-square drop) than "parameter linear in the variable", or None
    when the line explains more (or too few samples lie on a side)."""
    if parameter not in fit.names:
        return None
    evaluation = evaluate(fit.problem, fit.x)
    J = evaluation.jacobian
    assert J is not None
    n, m = evaluation.whitened.shape
    r = evaluation.whitened.ravel()
    fitted = J[:, ~fit.fixed]
    basis = np.linalg.qr(fitted)[0] if fitted.shape[1] else np.zeros((r.size, 0))
    column = J[:, fit.names.index(parameter)]
    defined = np.isfinite(values)
    times = np.unique(values[defined])
    if times.size < 2 * MIN_STEP_SIDE:
        return None
    cuts = 0.5 * (times[MIN_STEP_SIDE - 1:-MIN_STEP_SIDE] + times[MIN_STEP_SIDE:1 - MIN_STEP_SIDE])
    per_row = np.repeat(np.where(defined, values, np.nan), m)

    def drop(columns: np.ndarray) -> np.ndarray:
        columns = columns - basis @ (basis.T @ columns)
        norms = np.einsum("ij,ij->j", columns, columns)
        return np.where(norms > 1e-12, (columns.T @ r) ** 2 / np.maximum(norms, 1e-300), 0.0)

    steps = column[:, None] * (np.nan_to_num(per_row, nan=-np.inf)[:, None] > cuts[None, :])
    linear = column * np.nan_to_num(per_row - np.nanmean(values), nan=0.0)
    drops = drop(steps)
    best = int(np.argmax(drops))
    return float(cuts[best]) if drops[best] > float(drop(linear[:, None])[0]) else None


def frame_source(parameter: str, variable: str, fit: FitResult, values: np.ndarray
                 ) -> tuple[str, str] | None:
    """(effect name, plugin source) of "parameter varies with variable" for a frame
    translation of the fit's method (``FRAMES``), else None. values: the variable on the
    diagnosed samples (level indices for a group label)."""
    problem = fit.problem
    context = problem.context
    head, _, local = parameter.partition(".")
    kind = FRAMES.get((context.method, head))
    point, _, axis = local.rpartition(".")
    turn = axis in _TURNS and kind is not None and kind.rotation_frame is None \
        and not kind.grouped
    if kind is None or (axis not in _AXES and not turn) or bool(point) != kind.grouped:
        return None
    group: tuple[str, float] | None = None
    if kind.grouped:
        levels = list(context.categorical.get("marker", ()))
        if point not in levels or variable == "marker":
            return None
        group = ("marker", float(levels.index(point)))
    defined = values[np.isfinite(values)]
    if defined.size == 0:
        return None
    rotation = None
    pivot = None
    if turn:  # a small turn of the measurement frame about its own axis, at the fit
        R, origin, _ = frame_pose(problem, head, fit.x)
        pivot = (R[:, _TURNS.index(axis)].round(12).tolist(), origin.round(12).tolist())
    if kind.rotation_frame is not None:
        R = frame_pose(problem, kind.rotation_frame, fit.x)[0]
        rotation = ((R.T if kind.inverse else R).round(12).tolist(), kind.inverse)
    unit = "rad" if turn else "m"
    level_names = context.categorical.get(variable)
    step = None
    if level_names is not None:
        present = sorted({int(v) for v in defined})
        if len(present) < 2:
            return None
        indices = present[1:]
        fields = {"levels": tuple(float(i) for i in indices), "reference": 0.0,
                  "basis": "per level of", "names": ", ".join(repr(level_names[i])
                                                             for i in indices),
                  "law": f"k_LEVEL on the samples of each {variable} level after "
                         f"{level_names[present[0]]!r} (k in {unit})"}
    else:
        step = best_step(fit, parameter, values) if variable == "t" else None
        reference = float(defined.mean())
        fields = {"levels": (), "reference": reference, "names": "'k'"}
        if step is not None:
            fields |= {"basis": "steps in",
                       "law": f"k from {variable} > {step!r} on (k in {unit})"}
        else:
            fields |= {"basis": "linear in", "law": f"k * ({variable} - {reference!r}) "
                                                     f"(k in {unit} per unit of {variable})"}
    name = frame_effect_name(parameter, variable, step is not None)
    seen = ("" if rotation is None else
            " (the camera's or instrument's rotation at the fit, the flange's at the "
            "commanded joints)")
    whose = "" if group is None else f" of marker {point!r}"
    if turn:
        motion = f"rotation about its {axis[1]} axis"
        moves = "turns by that angle about the axis through the frame's origin"
    else:
        motion = f"{axis} translation"
        moves = (f"moves by that much along the frame's {axis} axis as seen in the "
                 "measurement frame")
    source = _TEMPLATE.format(
        title=f"{parameter} varies with {variable}: a generated zerocal effect.",
        parameter=parameter, variable=variable, name=name, method=context.method,
        axis=axis, axis_index=(_TURNS if turn else _AXES).index(axis), step=step,
        group=group, rotation=rotation, pivot=pivot, seen=seen, whose=whose, unit=unit,
        motion=motion, moves=moves,
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
