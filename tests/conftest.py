"""Shared test helpers: small synthetic datasets with a known truth."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.synthesize import random_truth, synthesize_stereo_target


@pytest.fixture(scope="session")
def stereo_poses() -> np.ndarray:
    """60 reachable look-at poses of a UR5e (computed once per session)."""
    from hostpc.synthesize import DEFAULT_TOOL, default_target, look_at_poses

    return look_at_poses("ur5e", DEFAULT_TOOL, default_target("ur5e"), 60,
                         np.random.default_rng(123))


@pytest.fixture()
def noisy_stereo(stereo_poses: np.ndarray):  # type: ignore[no-untyped-def]
    truth = random_truth(np.random.default_rng(5))
    return synthesize_stereo_target(truth, q=stereo_poses, seed=5)
