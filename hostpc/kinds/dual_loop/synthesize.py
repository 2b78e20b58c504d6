"""dual_loop poses and datasets: plan where to look, assemble samples, synthesize a truth.

- :func:`plan_poses`: arm poses around :data:`~hostpc.kinematics.humanoid.HUMANOID_HOME`
  whose target is in front of the robot, each with head angles that aim the camera near the
  target (nominal model), alternating left and right.
- :func:`make_dataset`: a dual_loop :class:`Dataset` from the recorded angles and the
  measured points (any source: the simulated controller, a real robot, a synthesis).
- :func:`synthesize_dual_loop`: measurements from hostpc's own model with a known truth
  (for derivative tests and quick checks; end-to-end studies use ``controller_stub``'s
  independent humanoid model instead).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.kinds.dual_loop.planning import PlannedPoses, nominal_frames
from hostpc.model.problem import build_problem
from hostpc.synthesize import noisy_measurements


def make_dataset(poses: PlannedPoses, p: np.ndarray, cov: np.ndarray, *,
                 robot: str = "humanoid_upper",
                 frames: Mapping[str, FramePose | np.ndarray] | None = None,
                 known: tuple[str, ...] = ()) -> Dataset:
    """A dual_loop dataset: measured points ``p`` (N, 3) m in the camera frame with
    covariances ``cov`` (N, 3, 3) m^2, at ``poses``; nominal frames by default."""
    samples = Samples(q=poses.q_arm, p=p, cov=cov, chain=poses.chain, q_head=poses.q_head,
                      t=np.arange(1, poses.n + 1, dtype=float))
    return Dataset(method="dual_loop", robot=RobotDescription(name=robot),
                   frames=dict(nominal_frames(robot) if frames is None else frames),
                   samples=samples, known=known)


def synthesize_dual_loop(truth: Mapping[str, float], poses: PlannedPoses, *, seed: int = 0,
                         noise_scale: float = 1.0) -> Dataset:
    """Measurements from hostpc's own dual_loop model at the parameter values ``truth``
    (full names, SI; missing ones 0), with stereo noise (``synthesize.stereo_covariance``;
    ``noise_scale`` 0 for exact data). The effects are those named in ``truth`` (plus the
    default frames)."""
    rng = np.random.default_rng(seed)
    placeholder = make_dataset(poses, np.zeros((poses.n, 3)),
                               np.broadcast_to(np.eye(3) * 1e-8, (poses.n, 3, 3)))
    effects = list(dict.fromkeys(["joint_offsets", *placeholder.frames,
                                  *(n.split(".", 1)[0] for n in truth)]))
    problem = build_problem(placeholder, effects)
    measured, cov = noisy_measurements(problem, truth, rng, noise_scale)
    return make_dataset(poses, measured, cov)
