"""Every analytic derivative of the measurement models against central differences."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.support import sphere_dataset

ALL_STEREO = ["joint_offsets", "tool", "target", "base", "geometry", "joint_compliance",
              "encoder_scale", "transmission_harmonic", "backlash", "depth_scale"]
ALL_SPHERE = ["joint_offsets", "tool", "sphere", "base", "geometry", "joint_compliance",
              "encoder_scale", "transmission_harmonic", "backlash", "trigger_latency"]


def central_difference(problem, x: np.ndarray, step: float = 1e-6) -> np.ndarray:  # type: ignore[no-untyped-def]
    columns = []
    for k in range(x.size):
        dx = np.zeros_like(x)
        dx[k] = step
        plus, _ = predict(problem, x + dx, jacobian=False)
        minus, _ = predict(problem, x - dx, jacobian=False)
        columns.append((plus - minus) / (2 * step))
    return np.stack(columns, axis=-1)


def assert_jacobian_close(problem, analytic: np.ndarray, numeric: np.ndarray) -> None:  # type: ignore[no-untyped-def]
    """Relative to each column's size, with an absolute floor for columns that are zero by
    physics (e.g. tau6 = 0 on a UR, whose last link's centre of mass is on its axis): there the
    central difference is pure rounding noise (~1e-10). A wrong derivative is off by O(1);
    1e-5 leaves room for the central difference's own rounding at extreme random poses."""
    scale = np.max(np.abs(numeric), axis=(0, 1), keepdims=True)
    error = np.abs(analytic - numeric) / (scale + 1e-4)
    worst = np.unravel_index(np.argmax(error), error.shape)
    assert error.max() < 1e-5, f"worst column {problem.layout.names[worst[2]]}: {error.max()}"


def random_parameters(problem, rng: np.random.Generator) -> np.ndarray:  # type: ignore[no-untyped-def]
    x = np.empty(problem.layout.size)
    for k, unit in enumerate(problem.layout.units):
        scale = {"rad": 0.01, "m": 0.003, "1": 1e-3, "rad/(N m)": 1e-4, "s": 1e-3}[unit]
        x[k] = rng.uniform(-scale, scale)
    return x


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stereo_target_jacobian_matches_central_differences(noisy_stereo, seed: int) -> None:
    problem = build_problem(noisy_stereo.dataset, ALL_STEREO)
    x = random_parameters(problem, np.random.default_rng(seed))
    _, analytic = predict(problem, x)
    numeric = central_difference(problem, x)
    assert_jacobian_close(problem, analytic, numeric)


@pytest.mark.parametrize("robot", ["ur5e", "industrial6"])
def test_sphere_probe_jacobian_matches_central_differences(robot: str) -> None:
    problem = build_problem(sphere_dataset(robot), ALL_SPHERE)
    x = random_parameters(problem, np.random.default_rng(3))
    _, analytic = predict(problem, x)
    numeric = central_difference(problem, x)
    assert_jacobian_close(problem, analytic, numeric)


def test_zero_parameters_give_the_nominal_prediction(noisy_stereo) -> None:
    nominal = build_problem(noisy_stereo.dataset, ["joint_offsets"])
    everything = build_problem(noisy_stereo.dataset, ALL_STEREO)
    p_nominal, _ = predict(nominal, np.zeros(nominal.layout.size), jacobian=False)
    p_all, _ = predict(everything, np.zeros(everything.layout.size), jacobian=False)
    np.testing.assert_allclose(p_all, p_nominal, atol=1e-15)


# hypothesis-generated joint vectors: the analytic derivatives hold anywhere, not only at
# the fixture's look-at poses
from dataclasses import replace  # noqa: E402

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra.numpy import arrays  # noqa: E402

joint_vectors = arrays(np.float64, (4, 6), elements=st.floats(-3.0, 3.0))


@settings(max_examples=15, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # fixture is read-only
@given(q=joint_vectors, seed=st.integers(0, 1000))
def test_stereo_jacobian_at_random_joint_vectors(noisy_stereo, q: np.ndarray, seed: int) -> None:
    dataset = noisy_stereo.dataset
    samples = dataset.samples.subset(np.arange(4))
    dataset = dataset.with_samples(replace(samples, q=q, approach=np.sign(q + 0.1)))
    problem = build_problem(dataset, ALL_STEREO)
    x = random_parameters(problem, np.random.default_rng(seed))
    _, analytic = predict(problem, x)
    assert_jacobian_close(problem, analytic, central_difference(problem, x))


@settings(max_examples=6, deadline=None)
@given(q=joint_vectors, seed=st.integers(0, 1000))
def test_sphere_jacobian_at_random_joint_vectors(q: np.ndarray, seed: int) -> None:
    dataset = sphere_dataset("ur5e", n=4)
    dataset = dataset.with_samples(replace(dataset.samples, q=q))
    problem = build_problem(dataset, ALL_SPHERE)
    x = random_parameters(problem, np.random.default_rng(seed))
    _, analytic = predict(problem, x)
    assert_jacobian_close(problem, analytic, central_difference(problem, x))
