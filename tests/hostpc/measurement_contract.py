"""The measurement-model contract, as checks any test can run on any model class.

Run over every registered model by test_measurement_contract.py; a plugin's tests call
``check_model(cls, plugins=[file])`` on theirs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, load_dataset, save_dataset
from hostpc.errors import EffectError, InputError
from hostpc.fitting import solve
from hostpc.model.effect import Effect
from hostpc.model.layout import Problem
from hostpc.model.measurements import MeasurementModel
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem, extend_problem
from hostpc.model.registry import available_effects

PARAMETER_SCALE = {"rad": 2e-3, "m": 1e-3, "1": 1e-4, "rad/(N m)": 1e-5, "s": 1e-3}


def richest_problem(dataset: Dataset, plugins: Sequence[str] = ()) -> Problem:
    """The default model plus every non-frame effect (and every frame) that applies."""
    problem = build_problem(dataset, plugins=plugins)
    model = problem.measurement
    frames = [f for f in model.frame_parameters(dataset)
              if f not in problem.effect_names and f not in dataset.known]
    registry = available_effects(plugins)
    for name in frames:
        try:
            problem = build_problem(dataset, [*problem.effect_names, name], plugins=plugins)
        except (InputError, EffectError):
            continue
    for name, cls in registry.items():
        if cls.hook == "frame" or name in problem.effect_names:
            continue
        effect: Effect = cls()
        try:
            extended = extend_problem(problem, [effect])
            predict(extended, np.zeros(extended.layout.size))
        except (InputError, EffectError, KeyError):
            continue
        problem = extended
    return problem


def random_parameters(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-1, 1) * PARAMETER_SCALE.get(unit, 1e-4)
                     for unit in problem.layout.units])


def check_shapes(problem: Problem) -> None:
    n = problem.dataset.n_samples
    m = problem.measurement.measurement_size
    x = np.zeros(problem.layout.size)
    prediction, jacobian = predict(problem, x)
    assert prediction.shape == (n, m)
    assert jacobian is not None and jacobian.shape == (n, m, problem.layout.size)
    assert problem.measured.shape == (n, m)
    assert problem.sqrt_information.shape == (n, m, m)
    values, none = predict(problem, x, jacobian=False)
    assert none is None and np.array_equal(values, prediction)


def check_jacobian(problem: Problem, rng: np.random.Generator, step: float = 1e-7) -> None:
    """Analytic Jacobian against central differences, relative to each column's size."""
    x = random_parameters(problem, rng)
    _, analytic = predict(problem, x)
    assert analytic is not None
    columns = []
    for k in range(x.size):
        dx = np.zeros_like(x)
        dx[k] = step
        plus, _ = predict(problem, x + dx, jacobian=False)
        minus, _ = predict(problem, x - dx, jacobian=False)
        columns.append((plus - minus) / (2 * step))
    numeric = np.stack(columns, axis=-1)
    scale = np.max(np.abs(numeric), axis=(0, 1), keepdims=True)
    error = np.abs(analytic - numeric) / (scale + 1e-4)
    worst = int(np.unravel_index(np.argmax(error), error.shape)[2])
    assert error.max() < 1e-5, f"{problem.method}: column {problem.layout.names[worst]}"


def check_round_trip(dataset: Dataset, directory: Path, plugins: Sequence[str] = ()) -> None:
    path = directory / f"{dataset.method}.json"
    save_dataset(dataset, path, plugins=plugins)
    assert load_dataset(path, plugins=plugins) == dataset


def check_recovery(problem: Problem, rng: np.random.Generator) -> None:
    """A noise-free fit recovers an injected truth on the parameters the data identify."""
    gauge = solve(problem, cv_folds=0)
    truth = np.where(gauge.fixed, 0.0, random_parameters(problem, rng))
    clean, _ = predict(problem, truth, jacobian=False)
    result = solve(replace(problem, measured=clean), cv_folds=0)
    assert result.converged, result.message
    # the exact gauge is the data's; the weak-parameter rule judges sigmas at the measured
    # noise (docs/fitting.md), which noise-free data makes tiny: it holds no more than the
    # gauge fit did, and what it frees is recovered too (its truth is 0)
    assert not np.any(result.fixed & ~gauge.fixed)
    scale = np.array([PARAMETER_SCALE.get(u, 1e-4) for u in problem.layout.units])
    assert np.max(np.abs(result.x - truth) / scale) < 1e-6, problem.layout.names


def check_model(cls: type[MeasurementModel], directory: Path, plugins: Sequence[str] = (),
                seed: int = 0) -> None:
    """Every rule of the contract on the model's example dataset."""
    rng = np.random.default_rng(seed)
    dataset = cls.example(rng)
    assert dataset.method == cls.name
    default = build_problem(dataset, plugins=plugins)
    check_shapes(default)
    check_recovery(default, rng)
    rich = richest_problem(dataset, plugins)
    check_shapes(rich)
    check_jacobian(rich, rng)
    check_round_trip(dataset, directory, plugins)
