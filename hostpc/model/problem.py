"""A calibration problem: a dataset, the robot chain and a list of effects, laid out as one
parameter vector. Building it validates everything a fit needs, once."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, Samples
from hostpc.errors import EffectError, InputError
from hostpc.kinematics import Chain, gravity_torque
from hostpc.kinematics.robots import chain_from_table, get_robot
from hostpc.model.contract import check_effect
from hostpc.model.effect import Effect, EffectTerm, ModelContext
from hostpc.model.registry import (
    available_effects,
    builtin_effects,
    instantiate,
    parse_effect_list,
)

FRAME_EFFECTS_BY_METHOD = {
    "stereo_target": ("tool", "target", "base"),
    "sphere_probe": ("tool", "sphere", "base"),
    "dual_loop": ("camera", "left_base", "right_base", "left_target", "right_target"),
}
DEFAULT_FRAMES_BY_METHOD = {
    "stereo_target": ("tool", "target"),
    "sphere_probe": ("tool", "sphere"),
    "dual_loop": ("camera", "left_base", "right_base", "left_target", "right_target"),
}


@dataclass(frozen=True)
class ParameterLayout:
    """Which slice of the parameter vector is which parameter.

    names: full names ``<effect>.<name>`` in vector order; units: SI unit of each;
    effect_slices: effect name -> slice.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    effect_slices: Mapping[str, slice]

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no parameter {name!r} in this model") from None

    def effect_of(self, index: int) -> str:
        return self.names[index].split(".", 1)[0]


@dataclass(frozen=True)
class Problem:
    """Everything a fit needs; constant during the fit.

    measured: (N, m) measurements; sqrt_information: (N, m, m) whitening matrices W with
    W^T W = cov^-1, so whitened residuals are W @ (measured - predicted).
    """

    dataset: Dataset
    chain: Chain
    context: ModelContext
    terms: tuple[EffectTerm, ...]
    layout: ParameterLayout
    measured: np.ndarray
    sqrt_information: np.ndarray
    plugins: tuple[str, ...] = field(default=())
    #: per term: the constant basis of a linear joint/geometry effect (delta = basis @ p),
    #: computed once here, or None
    linear_bases: tuple[np.ndarray | None, ...] = field(default=())

    @property
    def method(self) -> str:
        return self.dataset.method

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(term.effect.name for term in self.terms)

    def term(self, name: str) -> EffectTerm | None:
        for term in self.terms:
            if term.effect.name == name:
                return term
        return None

    def subset(self, indices: np.ndarray) -> Problem:
        """The same model on a subset of the samples (for cross-validation)."""
        return build_problem(
            self.dataset.with_samples(self.dataset.samples.subset(indices)),
            [t.effect.name for t in self.terms],
            plugins=self.plugins,
            effect_instances=[t.effect for t in self.terms],
        )


def robot_chain(dataset: Dataset) -> Chain:
    """The nominal chain of the dataset's robot (built-in by name, or explicit table)."""
    robot = dataset.robot
    if dataset.method == "dual_loop":  # a kinematic tree: its stacked bookkeeping chain
        from hostpc.model.dual_loop import tree_of

        return tree_of(dataset).stacked_chain()
    if robot.name is not None and robot.a is None:
        return get_robot(robot.name)
    if robot.urdf is not None:  # extension A: a URDF chain (hostpc.kinematics.urdf)
        from hostpc.kinematics.urdf import load_urdf_chain

        assert robot.base_link is not None and robot.tip_link is not None
        return load_urdf_chain(robot.urdf, robot.base_link, robot.tip_link)
    # the dataset layer guarantees a complete explicit table when there is no name
    assert robot.convention is not None and robot.a is not None and robot.alpha is not None
    assert robot.d is not None and robot.theta is not None
    return chain_from_table(
        robot.name or "explicit",
        robot.convention,
        robot.a,
        robot.alpha,
        robot.d,
        robot.theta,
        mass=robot.mass,
        com=robot.com,
        joint_types=robot.joint_types,
    )


def default_effects(dataset: Dataset) -> list[str]:
    """joint_offsets plus every frame of the method that the dataset does not mark known."""
    frames = DEFAULT_FRAMES_BY_METHOD.get(dataset.method, ())
    return ["joint_offsets"] + [f for f in frames if f not in dataset.known]


def sample_variables(samples: Samples, scalars: tuple[str, ...] = ("t", "temperature", "speed")
                     ) -> dict[str, np.ndarray]:
    """The per-sample variables every method shares, by contract name, each (N,): the
    recorded scalars that any sample has, `depth` (the measured point's z in the sensor
    frame, m) and `extra.NAME`."""
    variables: dict[str, np.ndarray] = {}
    for name in scalars:
        values = getattr(samples, name)
        if values is not None and np.any(np.isfinite(values)):
            variables[name] = np.asarray(values, dtype=float)
    if samples.p is not None:
        variables["depth"] = np.asarray(samples.p, dtype=float)[:, 2]
    for name, values in samples.extra.items():
        if np.any(np.isfinite(values)):
            variables[f"extra.{name}"] = np.asarray(values, dtype=float)
    return variables


def _context(dataset: Dataset, chain: Chain) -> ModelContext:
    if dataset.method == "dual_loop":
        from hostpc.model.dual_loop import dual_loop_context

        return dual_loop_context(dataset, chain)
    samples = dataset.samples
    q_cmd = np.asarray(samples.q, dtype=float)
    if chain.mass is not None and chain.com is not None:
        tau = gravity_torque(chain, q_cmd)
    else:
        tau = np.full_like(q_cmd, np.nan)
    approach = np.nan_to_num(np.asarray(samples.approach, dtype=float), nan=0.0)
    variables: dict[str, np.ndarray] = {}
    for j in range(chain.n):
        variables[f"q{j + 1}"] = q_cmd[:, j]
    if np.all(np.isfinite(tau)):
        for j in range(chain.n):
            variables[f"tau{j + 1}"] = tau[:, j]
    if np.any(np.isfinite(samples.approach)):
        for j in range(chain.n):
            variables[f"approach{j + 1}"] = approach[:, j]
    variables.update(sample_variables(samples))
    return ModelContext(
        chain=chain, method=dataset.method, q_cmd=q_cmd, tau=tau, approach=approach,
        variables=variables,
    )


def _measurements(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    samples = dataset.samples
    if dataset.method in ("stereo_target", "dual_loop"):
        cov = np.asarray(samples.cov, dtype=float)
        # W = L^-1 with cov = L L^T gives W^T W = cov^-1
        L = np.linalg.cholesky(cov)
        eye = np.broadcast_to(np.eye(3), cov.shape)
        W = np.linalg.solve(L, eye)
        return np.asarray(samples.p, dtype=float), W
    if dataset.method == "sphere_probe":
        sphere = dataset.sphere()
        stylus = dataset.probe_stylus_radius or 0.0
        n = samples.n
        measured = np.full((n, 1), float(sphere.radius) + float(stylus))
        W = (1.0 / np.asarray(samples.sigma, dtype=float)).reshape(n, 1, 1)
        return measured, W
    raise InputError(f"method {dataset.method!r} is not supported by the fit yet")


def build_problem(
    dataset: Dataset,
    effects: str | Iterable[str] | None = None,
    *,
    plugins: Iterable[str | Path] = (),
    effect_instances: Iterable[Effect] | None = None,
) -> Problem:
    """Validate effects against the dataset and lay out the parameter vector.

    effects: None for the default (joint_offsets + unknown frames), a list of names, or a
    spec string such as ``"joint_offsets,tool"`` or ``"+backlash"`` (added to the default).
    """
    plugin_paths = tuple(str(p) for p in plugins)
    chain = robot_chain(dataset)
    if dataset.method not in FRAME_EFFECTS_BY_METHOD:
        raise InputError(f"method {dataset.method!r} is not supported by the fit yet")
    if dataset.method == "dual_loop":
        from hostpc.model.dual_loop import check_dual_loop, tree_of

        check_dual_loop(dataset, tree_of(dataset))
    elif dataset.n_joints != chain.n:
        raise InputError(
            f"samples have {dataset.n_joints} joint angles but robot {chain.name!r} has {chain.n}"
        )
    names = parse_effect_list(effects, default_effects(dataset))
    if effect_instances is None:
        instances = instantiate(names, available_effects(plugin_paths))
    else:
        instances = list(effect_instances)
    context = _context(dataset, chain)
    allowed_frames = FRAME_EFFECTS_BY_METHOD[dataset.method]
    terms = []
    all_names: list[str] = []
    all_units: list[str] = []
    slices: dict[str, slice] = {}
    start = 0
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
        if effect.methods is not None and dataset.method not in effect.methods:
            raise EffectError(
                f"effect {effect.name!r} does not apply to method {dataset.method!r} "
                f"(only to {', '.join(effect.methods)})"
            )
        if type(effect) not in builtin_effects().values():
            check_effect(effect, context, 1 if dataset.method == "sphere_probe" else 3)
        span = slice(start, start + len(local))
        terms.append(EffectTerm(effect=effect, names=local, slice=span))
        slices[effect.name] = span
        all_names += [f"{effect.name}.{n}" for n in local]
        all_units += list(units)
        start += len(local)
    measured, W = _measurements(dataset)
    bases = tuple(
        np.ascontiguousarray(term.effect.basis(context))
        if term.effect.is_linear and term.effect.hook in ("joint", "geometry") else None
        for term in terms
    )
    return Problem(
        dataset=dataset,
        chain=chain,
        context=context,
        terms=tuple(terms),
        layout=ParameterLayout(tuple(all_names), tuple(all_units), slices),
        measured=measured,
        sqrt_information=W,
        plugins=plugin_paths,
        linear_bases=bases,
    )
