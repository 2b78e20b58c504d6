"""Helpers shared by tests (import as tests.support)."""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Dataset, RobotDescription, Samples, SphereFrame
from hostpc.kinds.sphere_probe.file_face import probe_blocks


def sphere_dataset(robot: str = "ur5e", n: int = 40, seed: int = 0) -> Dataset:
    """A sphere_probe dataset with plausible (not exact-contact) poses, for derivative tests."""
    from hostpc.synthesize import DEFAULT_TOOL, default_target, look_at_poses

    rng = np.random.default_rng(seed)
    q = look_at_poses(robot, DEFAULT_TOOL, default_target(robot), n, rng)
    samples = Samples(q=q, sigma=np.full(n, 5e-6), group=np.arange(n) // 5,
                      speed=rng.uniform(0.005, 0.02, n))
    return Dataset(
        method="sphere_probe", robot=RobotDescription(name=robot),
        frames={"tool": DEFAULT_TOOL, "sphere": SphereFrame(default_target(robot), 0.0125)},
        samples=samples, blocks=probe_blocks(0.0015),
    )
