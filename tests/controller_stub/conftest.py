"""Shared helpers for the simulator tests (no hostpc imports: the stub is tested on its own)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.optimize import least_squares

from controller_stub.scenario.spec import Scenario, scenario_from_dict
from controller_stub.world.simulation import Simulation


def _make_sim(**overrides: object) -> Simulation:
    """A Simulation from the built-in defaults with top-level blocks overridden."""
    return Simulation(scenario_from_dict(dict(overrides)))


def _pose_looking_at(
    sim: Simulation, point: np.ndarray, normal: np.ndarray, dist: float
) -> np.ndarray:
    """Reported joint angles (n,) that put the TRUE left camera `dist` m from `point` along
    `normal`, looking back along -normal (solved on the simulator's own truth)."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    eye = np.asarray(point, float) + dist * normal

    def residual(q: np.ndarray) -> np.ndarray:
        T = sim.physics.flange_pose(sim.physical_angles(q)[None], sim.time)[0]
        T_cam = T @ sim.stereo.T_flange_camera
        return np.concatenate([T_cam[:3, 3] - eye, T_cam[:3, 2] + normal])

    q0 = sim.joint_positions()
    best = None
    for q1 in np.linspace(-np.pi, np.pi, 9):
        start = q0.copy()
        start[0] = q1
        sol = least_squares(residual, start, xtol=1e-14, ftol=1e-14, gtol=1e-14)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None and best.cost < 1e-16
    return np.asarray(best.x)


@pytest.fixture
def default_sim() -> Simulation:
    return Simulation(Scenario())


@pytest.fixture
def make_sim() -> Callable[..., Simulation]:
    """Factory: make_sim(seed=..., truth={...}, ...) -> Simulation (top-level blocks)."""
    return _make_sim


@pytest.fixture
def pose_looking_at() -> Callable[..., np.ndarray]:
    """Factory: pose_looking_at(sim, point, normal, dist) -> reported q (n,)."""
    return _pose_looking_at
