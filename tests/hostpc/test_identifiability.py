"""The gauge: one held parameter per null direction, chosen so the rest is well conditioned."""

from __future__ import annotations

import numpy as np

from hostpc.fitting.identifiability import analyse


def jacobian_with_null(direction: np.ndarray, rows: int = 40, seed: int = 0) -> np.ndarray:
    """A random full-rank Jacobian projected so that `direction` is its only null vector."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(rows, direction.size))
    d = direction / np.linalg.norm(direction)
    return J - np.outer(J @ d, d)


def test_weakly_participating_geometry_is_not_held() -> None:
    # the null direction is almost entirely target.x + tool.x; geometry.d1 barely takes part
    names = ["geometry.d1", "target.x", "tool.x", "joint_offsets.q2"]
    units = ["m", "m", "m", "rad"]
    J = jacobian_with_null(np.array([0.002, 1.0, -1.0, 0.0]))
    ident = analyse(J, names, units)
    assert ident.rank == 3
    held = [d.fixed for d in ident.null_directions]
    assert held[0] in ("target.x", "tool.x")
    assert ident.condition_number < 20


def test_priority_among_strong_participants() -> None:
    # joint offset and frame share the direction equally: the joint offset is held (never
    # pushed), the frame absorbs it
    names = ["joint_offsets.q1", "target.y", "tool.z"]
    J = jacobian_with_null(np.array([1.0, -0.8, 0.0]))
    ident = analyse(J, names, ["rad", "m", "m"])
    assert [d.fixed for d in ident.null_directions] == ["joint_offsets.q1"]
    assert ident.null_directions[0].parameters == ("joint_offsets.q1", "target.y")


def test_parameter_without_effect_is_named() -> None:
    J = np.random.default_rng(1).normal(size=(10, 3))
    J[:, 2] = 0.0
    ident = analyse(J, ["a.x", "b.y", "c.z"], ["m", "m", "m"])
    assert [d.fixed for d in ident.null_directions] == ["c.z"]
    assert "has no effect" in ident.null_directions[0].description
