"""Synthetic datasets with a known truth, made with hostpc's own measurement model.

For tests of the fitter, examples and benchmarks: choose poses that look at the target,
evaluate the model with the true parameter values (any registered effect, so hidden effects
can be injected), and add noise drawn from each sample's covariance. End-to-end tests use the
simulated controller instead, which has an independent forward model.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.kinematics import get_robot, invert_transform, pose_to_transform
from hostpc.kinematics.inverse import look_at, solve_ik
from hostpc.model.joint_offsets import offset_name
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

# A pose of each built-in robot with the flange pointing down (-z of base), used as the IK seed
HOME_POSES = {
    "ur5e": (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0),
    "ur10e": (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0),
    "industrial6": (0.0, -0.9, 2.9, 0.0, np.pi - 2.0, 0.0),
}
DEFAULT_TOOL = FramePose(xyz=np.array([0.0, 0.045, 0.06]), rpy=np.array([0.0, 0.0, np.pi / 2]))
LATERAL_SIGMA_AT_HALF_METRE = 5e-5   # m, grows linearly with depth
DEPTH_SIGMA_AT_HALF_METRE = 2.5e-4   # m, grows with the square of depth


@dataclass(frozen=True)
class SyntheticDataset:
    """A dataset and the truth that produced it (parameter name -> value, SI)."""

    dataset: Dataset
    truth: Mapping[str, float]
    effects: tuple[str, ...]


def stereo_covariance(points: np.ndarray, noise_scale: float = 1.0) -> np.ndarray:
    """(N, 3, 3) covariance of stereo-triangulated points (N, 3) in the camera frame:
    lateral sigma proportional to depth, depth sigma to depth squared."""
    depth = np.abs(points[:, 2])
    lateral = noise_scale * LATERAL_SIGMA_AT_HALF_METRE * depth / 0.5
    axial = noise_scale * DEPTH_SIGMA_AT_HALF_METRE * (depth / 0.5) ** 2
    cov = np.zeros((points.shape[0], 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = lateral**2
    cov[:, 2, 2] = axial**2
    return cov


def default_target(robot: str, tool: FramePose = DEFAULT_TOOL, depth: float = 0.45) -> np.ndarray:
    """A target point on the floor in front of the robot's home pose (base frame, m)."""
    from hostpc.kinematics import forward

    chain = get_robot(robot)
    T_base_flange = forward(chain, np.array([HOME_POSES[robot]])).T_base_flange[0]
    T_base_tool = T_base_flange @ pose_to_transform(tool.xyz, tool.rpy)
    return T_base_tool[:3, 3] + depth * T_base_tool[:3, 2]


def look_at_poses(robot: str, tool: FramePose, target: np.ndarray, n_poses: int,
                  rng: np.random.Generator, *, distance: tuple[float, float] = (0.3, 0.6),
                  cone_deg: float = 35.0, aim_spread: float = 0.03,
                  roll_deg: float = 90.0) -> np.ndarray:
    """(n_poses, n) joint angles (nominal model) whose sensor looks at the target from random
    points of a cone above it, with random roll; unreachable candidates are dropped."""
    chain = get_robot(robot)
    home = np.array(HOME_POSES[robot])
    T_flange_tool = pose_to_transform(tool.xyz, tool.rpy)
    T_tool_flange = invert_transform(T_flange_tool)
    accepted: list[np.ndarray] = []
    for _ in range(50):
        if sum(len(a) for a in accepted) >= n_poses:
            break
        m = 2 * n_poses
        polar = np.radians(cone_deg) * np.sqrt(rng.uniform(0, 1, m))
        azimuth = rng.uniform(0, 2 * np.pi, m)
        direction = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                              np.cos(polar)], axis=1)
        camera = target + rng.uniform(*distance, (m, 1)) * direction
        aim = target + rng.uniform(-aim_spread, aim_spread, (m, 3)) * [1, 1, 0]
        roll = np.radians(rng.uniform(-roll_deg, roll_deg, m))
        T_base_tool = look_at(camera, aim, roll)
        goals = T_base_tool @ T_tool_flange
        seeds = home + rng.normal(0.0, 0.15, (m, chain.n))
        q, ok = solve_ik(chain, goals, seeds)
        near_home = np.all(np.abs(q - home) < 1.6, axis=1)
        accepted.append(q[ok & near_home])
    found = np.concatenate(accepted)
    if found.shape[0] < n_poses:
        raise ValueError(f"only {found.shape[0]} of {n_poses} look-at poses are reachable by "
                         f"{robot}; move the target or widen the distance range")
    return found[:n_poses]


def approach_signs(q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, n) sign of the last motion of each joint into each pose when visiting the poses
    in order (the first pose: random)."""
    signs = np.sign(np.diff(q, axis=0, prepend=q[:1] - rng.uniform(-1, 1, (1, q.shape[1]))))
    signs[signs == 0] = 1.0
    return signs


def noisy_measurements(problem: Problem, truth: Mapping[str, float],
                       rng: np.random.Generator, noise_scale: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Stereo points (N, 3) predicted by `problem` with the true parameter values (names
    absent from `truth` are zero), plus Gaussian noise drawn from each point's stereo
    covariance (N, 3, 3), which is returned too (noise_scale 0: exact points, the covariance
    at scale 1)."""
    unknown = set(truth) - set(problem.layout.names)
    if unknown:
        raise KeyError(f"truth names parameters no effect has: {sorted(unknown)}")
    x = np.array([truth.get(name, 0.0) for name in problem.layout.names])
    clean, _ = predict(problem, x, jacobian=False)
    cov = stereo_covariance(clean, noise_scale if noise_scale > 0 else 1.0)
    noise = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal(clean.shape))
    return clean + (noise if noise_scale > 0 else 0.0), cov


def random_truth(rng: np.random.Generator, n_joints: int = 6, *, offsets_deg: float = 0.5,
                 tool_mm: float = 2.0, tool_deg: float = 0.5, target_mm: float = 2.0
                 ) -> dict[str, float]:
    """Uniform random zero offsets and frame errors of the stereo_target method."""
    truth = {offset_name(f"q{i + 1}"): np.radians(rng.uniform(-offsets_deg, offsets_deg))
             for i in range(n_joints)}
    for axis in "xyz":
        truth[f"tool.{axis}"] = rng.uniform(-tool_mm, tool_mm) * 1e-3
        truth[f"tool.r{axis}"] = np.radians(rng.uniform(-tool_deg, tool_deg))
        truth[f"target.{axis}"] = rng.uniform(-target_mm, target_mm) * 1e-3
    return {k: float(v) for k, v in truth.items()}


def synthesize_stereo_target(
    truth: Mapping[str, float],
    *,
    robot: str = "ur5e",
    n_samples: int = 120,
    seed: int = 0,
    noise_scale: float = 1.0,
    known: Iterable[str] = (),
    tool: FramePose = DEFAULT_TOOL,
    target: np.ndarray | None = None,
    seconds_per_pose: float = 4.0,
    q: np.ndarray | None = None,
    approach: np.ndarray | None = None,
    temperature: np.ndarray | None = None,
) -> SyntheticDataset:
    """A stereo_target dataset whose measurements follow `truth` (full parameter names, SI),
    plus Gaussian noise from each sample's covariance (noise_scale 0 for exact data).

    The dataset carries the nominal frames; the truth's frame parameters are the errors of
    the real frames. Records t, approach and temperature context for the diagnostics
    (``approach``: (N, n) signs to record instead of those of visiting the poses in order;
    ``temperature``: (N,) the arm's temperature to record instead of a slow 2 mK/s rise).
    """
    rng = np.random.default_rng(seed)
    target = default_target(robot, tool) if target is None else np.asarray(target, float)
    if q is None:
        q = look_at_poses(robot, tool, target, n_samples, rng)
    n_samples = q.shape[0]
    t = np.asarray(seconds_per_pose * np.arange(1, n_samples + 1), dtype=np.float64)
    approach = approach_signs(q, rng) if approach is None else np.asarray(approach, float)
    temperature = np.asarray(21.0 + 0.002 * t if temperature is None else temperature,
                             dtype=np.float64)
    placeholder = Samples(q=q, p=np.zeros((n_samples, 3)),
                          cov=np.broadcast_to(np.eye(3) * 1e-8, (n_samples, 3, 3)),
                          t=t, approach=approach, temperature=temperature)
    dataset = Dataset(method="stereo_target", robot=RobotDescription(name=robot),
                      frames={"tool": tool, "target": target}, samples=placeholder)
    effects = tuple(dict.fromkeys(name.split(".", 1)[0] for name in truth))
    problem = build_problem(dataset, list(effects))
    measured, cov = noisy_measurements(problem, truth, rng, noise_scale)
    samples = Samples(q=q, p=measured, cov=cov, t=t, approach=approach, temperature=temperature)
    final = replace(dataset, samples=samples, known=tuple(known))
    return SyntheticDataset(dataset=final, truth=dict(truth), effects=effects)


def write_example(path: str | Path, synthetic: SyntheticDataset) -> None:
    """Save a synthetic dataset and its truth (``<name>.truth.json`` beside it)."""
    import json

    from hostpc.dataset import save_dataset

    path = Path(path)
    save_dataset(synthetic.dataset, path)
    truth_path = path.with_suffix(".truth.json")
    truth_path.write_text(json.dumps({"effects": list(synthetic.effects),
                                      "truth": dict(synthetic.truth)}, indent=2) + "\n")
