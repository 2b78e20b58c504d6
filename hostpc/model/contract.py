"""The effect contract, checked when a user's effect enters a model: output shapes, zero
parameters give the nominal model, and an analytic Jacobian agrees with a numeric one.
A plugin that breaks it is refused with one line before it can mislead a fit."""

from __future__ import annotations

import numpy as np

from hostpc.errors import EffectError
from hostpc.model.effect import Effect, ModelContext, numeric_jacobian

JACOBIAN_TOLERANCE = 1e-4


def _check_shape(effect: Effect, what: str, value: np.ndarray,
                 shape: tuple[int, ...]) -> None:
    """EffectError naming the effect unless ``value`` is an array of ``shape``."""
    got = tuple(np.shape(value))
    if got != shape:
        raise EffectError(f"effect {effect.name!r}: {what} has shape {got}, expected {shape}")


def check_effect(effect: Effect, ctx: ModelContext, measurement_dim: int) -> None:
    """Raise EffectError naming the effect and the broken rule. Frame effects have no code."""
    if effect.hook == "frame":
        return
    names = list(effect.parameter_names(ctx))
    n_params = len(names)
    rng = np.random.default_rng(0)
    p = rng.uniform(-1e-3, 1e-3, n_params)
    zero = np.zeros(n_params)
    n_samples, n_joints = ctx.q_cmd.shape
    try:
        if effect.is_linear and effect.hook in ("joint", "geometry"):
            rows = n_joints if effect.hook == "joint" else 5 * n_joints
            _check_shape(effect, "basis", effect.basis(ctx), (n_samples, rows, n_params))
        if effect.hook == "joint":
            value, shape = effect.joint_delta(ctx, zero), (n_samples, n_joints)
            analytic = effect.joint_jacobian(ctx, p)
            fun = lambda v: effect.joint_delta(ctx, v)  # noqa: E731
        elif effect.hook == "geometry":
            value, shape = effect.kinematic_delta(ctx, zero), (n_samples, 5 * n_joints)
            analytic = effect.kinematic_jacobian(ctx, p)
            fun = lambda v: effect.kinematic_delta(ctx, v)  # noqa: E731
        else:
            y = rng.uniform(0.1, 0.5, (n_samples, measurement_dim))
            value, shape = effect.sensor_apply(ctx, zero, y) - y, (n_samples, measurement_dim)
            jacobians = effect.sensor_jacobians(ctx, p, y)
            analytic = None if jacobians is None else jacobians[1]
            fun = lambda v: effect.sensor_apply(ctx, v, y)  # noqa: E731
        value = np.asarray(value, dtype=float)
        if value.shape != shape:
            raise EffectError(f"effect {effect.name!r}: returns shape {value.shape}, "
                              f"expected {shape}")
        if np.any(np.abs(value) > 1e-12):
            raise EffectError(f"effect {effect.name!r}: all-zero parameters must give the "
                              "nominal model (zero delta)")
        if analytic is None:
            return
        numeric = numeric_jacobian(fun, p)
        analytic = np.asarray(analytic, dtype=float)
    except EffectError:
        raise
    except Exception as exc:  # a user's code may fail in any way: one line
        raise EffectError(f"effect {effect.name!r} failed: {type(exc).__name__}: {exc}") from exc
    if analytic.shape != numeric.shape:
        raise EffectError(f"effect {effect.name!r}: Jacobian has shape {analytic.shape}, "
                          f"expected {numeric.shape}")
    error = float(np.max(np.abs(analytic - numeric)) / (np.max(np.abs(numeric)) + 1e-12))
    if error > JACOBIAN_TOLERANCE:
        raise EffectError(
            f"effect {effect.name!r}: its analytic Jacobian disagrees with a numeric derivative "
            f"(relative error {error:.1e}); fix it, or return None to use numeric derivatives"
        )
