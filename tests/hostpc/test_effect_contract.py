"""One contract test over every registered effect: output shapes, zero parameters give the
nominal model, analytic Jacobian (where given) against a numeric one."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.model.effect import ModelContext, numeric_jacobian
from hostpc.model.measurements.registry import measurement_models
from hostpc.model.problem import build_problem
from hostpc.model.registry import builtin_effects
from tests.support import sphere_dataset

REGISTERED = sorted(builtin_effects())


def context_for(effect_cls, noisy_stereo):  # type: ignore[no-untyped-def]
    methods = [name for name, model in measurement_models().items()
               if model.accepts(effect_cls)]
    if "stereo_target" in methods:
        dataset = noisy_stereo.dataset
    else:
        dataset = sphere_dataset()
    problem = build_problem(dataset, ["joint_offsets"])
    return problem.context


@pytest.mark.parametrize("name", REGISTERED)
def test_effect_contract(name: str, noisy_stereo) -> None:  # type: ignore[no-untyped-def]
    cls = builtin_effects()[name]
    effect = cls()
    ctx: ModelContext = context_for(cls, noisy_stereo)
    names = list(effect.parameter_names(ctx))
    units = list(effect.parameter_units(ctx))
    assert names and len(names) == len(set(names)) == len(units)
    assert all(isinstance(n, str) and n for n in names)
    P = len(names)
    rng = np.random.default_rng(0)
    p = rng.uniform(-1e-3, 1e-3, P)
    N, n = ctx.q_cmd.shape
    if effect.hook == "joint":
        assert effect.joint_delta(ctx, np.zeros(P)).shape == (N, n)
        assert np.all(effect.joint_delta(ctx, np.zeros(P)) == 0.0)
        analytic = effect.joint_jacobian(ctx, p)
        numeric = numeric_jacobian(lambda v: effect.joint_delta(ctx, v), p)
    elif effect.hook == "geometry":
        assert effect.kinematic_delta(ctx, np.zeros(P)).shape == (N, 5 * n)
        assert np.all(effect.kinematic_delta(ctx, np.zeros(P)) == 0.0)
        analytic = effect.kinematic_jacobian(ctx, p)
        numeric = numeric_jacobian(lambda v: effect.kinematic_delta(ctx, v), p)
    elif effect.hook == "sensor":
        m = 3 if ctx.method == "stereo_target" else 1
        y = rng.uniform(0.1, 0.5, (N, m))
        np.testing.assert_array_equal(effect.sensor_apply(ctx, np.zeros(P), y), y)
        assert effect.sensor_apply(ctx, p, y).shape == (N, m)
        jac = effect.sensor_jacobians(ctx, p, y)
        if jac is None:
            return
        d_out_d_y, analytic = jac
        assert d_out_d_y.shape == (N, m, m)
        for k in range(m):  # d out / d y, column by column
            step = np.zeros(m)
            step[k] = 1e-6
            column = (effect.sensor_apply(ctx, p, y + step)
                      - effect.sensor_apply(ctx, p, y - step)) / 2e-6
            np.testing.assert_allclose(d_out_d_y[:, :, k], column, rtol=1e-6, atol=1e-9)
        numeric = numeric_jacobian(lambda v: effect.sensor_apply(ctx, v, y), p)
    else:  # frame effects: their math is in the measurement models (tested there)
        assert effect.hook == "frame"
        return
    if analytic is None:
        return
    assert analytic.shape == numeric.shape
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-9)
