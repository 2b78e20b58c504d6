"""Building a calibration problem: a dataset, its measurement model, the robot chain and a
list of effects, laid out as one parameter vector. Building validates everything a fit needs,
once; folds (``Problem.subset``) and candidate effects (``extend_problem``) reuse it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset
from hostpc.errors import EffectError
from hostpc.kinematics import Chain
from hostpc.model.context import chain_version
from hostpc.model.contract import check_effect
from hostpc.model.effect import Effect, EffectTerm, ModelContext
from hostpc.model.effects.frames import frame_effect
from hostpc.model.layout import MeasurementPredictor, ParameterLayout, Problem
from hostpc.model.measurements.base import MeasurementModel
from hostpc.model.measurements.registry import measurement_model, measurement_models
from hostpc.model.memo import SharedValues
from hostpc.model.registry import (
    available_effects,
    builtin_effects,
    instantiate,
    parse_effect_list,
)

__all__ = ["build_problem", "default_effects", "extend_problem", "robot_chain"]


def robot_chain(dataset: Dataset, plugins: Iterable[str | Path] = (), *,
                shared: SharedValues | None = None) -> Chain:
    """The nominal chain the fit of this dataset works on (its measurement model's); kept
    in ``shared`` (if given) per robot description and URDF file version."""
    return _chain(measurement_model(dataset.method, plugins), dataset, shared)


def _chain(model: MeasurementModel, dataset: Dataset, shared: SharedValues | None) -> Chain:
    version = chain_version(dataset)
    if shared is None or version is None:
        return model.chain(dataset)
    return shared.value(dataset.robot, ("chain", type(model), version),
                        lambda: model.chain(dataset))


def default_effects(dataset: Dataset, plugins: Iterable[str | Path] = ()) -> list[str]:
    """joint_offsets plus every default frame of the method that the dataset does not mark
    known."""
    model = measurement_model(dataset.method, plugins)
    return ["joint_offsets"] + [f for f in model.default_frames if f not in dataset.known]


def _registry_with_frames(model: MeasurementModel, dataset: Dataset,
                          plugins: tuple[str, ...]) -> dict[str, type[Effect]]:
    """The effect registry plus a frame effect for each frame of the model that has none."""
    registry = available_effects(plugins)
    for name, parameters in model.frame_parameters(dataset).items():
        if name not in registry:
            registry[name] = frame_effect(name, tuple(parameters))
    return registry


def _kinds_accepting(effect: type[Effect]) -> list[str]:
    """The kinds ``effect`` names and the registered kinds whose models take it (for the
    error message)."""
    accepting = [name for name, model in measurement_models().items() if model.accepts(effect)]
    return list(dict.fromkeys([*(effect.methods or ()), *accepting]))


def _terms(model: MeasurementPredictor, dataset: Dataset, context: ModelContext,
           instances: Sequence[Effect]) -> tuple[tuple[EffectTerm, ...], ParameterLayout]:
    """Check each effect against the model and the dataset and lay out the vector."""
    allowed_frames = tuple(model.frame_parameters(dataset))
    terms = []
    all_names: list[str] = []
    all_units: list[str] = []
    slices: dict[str, slice] = {}
    start = 0
    builtin = set(builtin_effects().values())  # asked once: it reads every kind's descriptor
    for effect in instances:
        if effect.hook == "frame" and effect.name not in allowed_frames:
            raise EffectError(
                f"effect {effect.name!r} does not apply to method {dataset.method!r} "
                f"(its frames are: {', '.join(allowed_frames)})"
            )
        if effect.name in slices:
            raise EffectError(f"effect {effect.name!r} listed twice")
        local = tuple(str(n) for n in effect.parameter_names(context))
        units = tuple(str(u) for u in effect.parameter_units(context))
        if len(units) != len(local):
            raise EffectError(f"effect {effect.name!r}: {len(local)} names but {len(units)} units")
        if effect.hook == "frame" and effect.name in dataset.known:
            raise EffectError(
                f"effect {effect.name!r} is a frame the dataset marks as known; "
                "remove it from `known` to estimate it"
            )
        if not model.accepts(type(effect)):
            raise EffectError(
                f"effect {effect.name!r} does not apply to method {dataset.method!r} "
                f"(only to {', '.join(_kinds_accepting(type(effect)))})"
            )
        if type(effect) not in builtin:
            check_effect(effect, context, model.measurement_size)
        span = slice(start, start + len(local))
        terms.append(EffectTerm(effect=effect, names=local, slice=span))
        slices[effect.name] = span
        all_names += [f"{effect.name}.{n}" for n in local]
        all_units += list(units)
        start += len(local)
    return tuple(terms), ParameterLayout(tuple(all_names), tuple(all_units), slices)


def _linear_bases(terms: Iterable[EffectTerm], context: ModelContext
                  ) -> tuple[np.ndarray | None, ...]:
    """Per term: the constant basis of a linear joint/geometry effect, else None. A basis
    the same for every sample (a broadcast view, as the geometry effect's) stays one: a
    (k, P) matrix seen N times, not an (N, k, P) copy (456 MB at 100k poses)."""
    return tuple(
        _compact(term.effect.basis(context))
        if term.effect.is_linear and term.effect.hook in ("joint", "geometry") else None
        for term in terms
    )


def _compact(basis: np.ndarray) -> np.ndarray:
    basis = np.asarray(basis)
    if basis.ndim == 3 and basis.shape[0] > 1 and basis.strides[0] == 0:
        return np.broadcast_to(np.ascontiguousarray(basis[0]), basis.shape)
    return np.ascontiguousarray(basis)


def build_problem(
    dataset: Dataset,
    effects: str | Iterable[str] | None = None,
    *,
    plugins: Iterable[str | Path] = (),
    effect_instances: Iterable[Effect] | None = None,
    shared: SharedValues | None = None,
) -> Problem:
    """Validate effects against the dataset and lay out the parameter vector.

    effects: None for the default (joint_offsets + unknown frames), a list of names, or a
    spec string such as ``"joint_offsets,tool"`` or ``"+backlash"`` (added to the default).
    plugins: Python files defining effects and measurement models. shared: what another
    problem of this dataset computed (``problem.shared``, hostpc.model.memo), reused and
    carried on; None starts anew.
    """
    plugin_paths = tuple(str(p) for p in plugins)
    model = measurement_model(dataset.method, plugin_paths)
    shared = SharedValues() if shared is None else shared
    chain = _chain(model, dataset, shared)
    model.check(dataset, chain)
    names = parse_effect_list(effects, default_effects(dataset, plugin_paths))
    if effect_instances is None:
        instances = instantiate(names, _registry_with_frames(model, dataset, plugin_paths))
    else:
        instances = list(effect_instances)
    context = model.context(dataset, chain)
    terms, layout = _terms(model, dataset, context, instances)
    bases = _linear_bases(terms, context)
    measured, W = model.measurements(dataset)
    # read-only: shared by the problem's views and extensions, and the memos cache what is
    # derived from them (a held-out residual of changed measurements would be stale); a
    # copy, so the dataset's own arrays stay as they were
    measured = np.array(measured, dtype=float)
    for array in (measured, W):
        array.setflags(write=False)
    return Problem(
        dataset=dataset,
        chain=chain,
        context=context,
        terms=terms,
        layout=layout,
        measured=measured,
        sqrt_information=W,
        plugins=plugin_paths,
        linear_bases=bases,
        model=model,
        shared=shared,
    )


def extend_problem(problem: Problem, effects: Sequence[Effect]) -> Problem:
    """The problem with ``effects`` appended (a candidate effect): the built context,
    chain, measurements and the existing terms' bases are reused, not rebuilt.

    Raises EffectError/InputError if an effect cannot apply."""
    instances = [t.effect for t in problem.terms] + list(effects)
    terms, layout = _terms(problem.measurement, problem.dataset, problem.context, instances)
    new_bases = _linear_bases(terms[len(problem.terms):], problem.context)
    return replace(problem, terms=terms, layout=layout,
                   linear_bases=tuple(problem.linear_bases) + new_bases)
